// The hierarchical parts of the radiosity solver, written once for the CPU (oneTBB loops) and
// the GPU (one thread per link or point): the block refinement of one V-map link and the final
// gather of one point. Plain arrays in, no allocation, no recursion (explicit stacks, depth-first
// in one fixed order), no exceptions. With contraction into FMAs forbidden on both sides
// (-ffp-contract=off, --fmad=false) and IEEE sqrt and division (nvcc's defaults), each call
// gives the same bits on both.
#pragma once

#include <cstdint>

#include "vmap/vec.h"

namespace vmap::detail {

constexpr float kGiPi = 3.14159265358979323846f;  // == std::numbers::pi_v<float>
// Internal nodes count as flat when |mean normal| >= 1 - kGiFlatness / theta.
constexpr float kGiFlatness = 0.05f;
// Explicit stacks: a pop pushes at most 8 children (7 beyond the one it replaces), once per
// level on each side, so 7 * 2 * 22 + 1 entries cover max_height 21 (the octree's limit).
constexpr int kGiStack = 320;

// K(r, s) = cos_r cos_s / (pi d^2 + max(A_r, A_s)), cosines clamped at 0 (docs/gi.md). K(r, s)
// and K(s, r) are the same float: dot(ns, -d) is exactly -dot(ns, d).
VMAP_HD float gi_kernel_hd(Vec3 pr, Vec3 nr, float ar, Vec3 ps, Vec3 ns, float as) {
    const Vec3 d = ps - pr;
    const float d2 = dot(d, d);
    if (!(d2 > 0)) return 0;
    const float len = sqrtf(d2);
    const float cr = dot(nr, d) / len;
    const float cs = -dot(ns, d) / len;
    if (!(cr > 0) || !(cs > 0)) return 0;
    return (cr * cs) / (kGiPi * d2 + (ar > as ? ar : as));
}

// What refinement and gather need of a node: total area, area-weighted mean position and normal
// (not renormalised), the half-diagonal of its content box, the mean area of its points.
struct NodeGeom {
    Vec3 center, normal;
    float area = 0, size = 0;
    float point_area = 0;
};

// The octree (depth-first preorder: a node's first child is the next node, skip[n] is just past
// its subtree), its node geometry, the points and the V-map's links, as plain arrays.
struct GiTree {
    int32_t num_nodes = 0;
    uint32_t num_points = 0;
    const int32_t* skip = nullptr;       // per node
    const int32_t* node_leaf = nullptr;  // per node: >= 0 for a leaf
    const int32_t* parent = nullptr;     // per node, -1 for the root
    const uint32_t* point_begin = nullptr;
    const uint32_t* point_end = nullptr;
    const NodeGeom* geom = nullptr;          // per node
    const Vec3* position = nullptr;          // per point
    const Vec3* normal = nullptr;            // per point
    const float* area = nullptr;             // per point: pi r^2
    const int32_t* point_leaf = nullptr;     // per point: its leaf's node
    const uint64_t* link_offsets = nullptr;  // per node + 1
    const int32_t* links = nullptr;          // both ends of every link
};

VMAP_HD bool gi_within(const GiTree& t, int32_t a, int32_t x) { return x <= a && a < t.skip[x]; }
VMAP_HD bool gi_leaf(const GiTree& t, int32_t n) { return t.node_leaf[n] >= 0; }
VMAP_HD bool gi_flat_normal(const NodeGeom& g, float theta) {
    return length(g.normal) >= 1.0f - kGiFlatness / theta;
}
// Leaves are taken as they are (opening them would pair single points with everything).
VMAP_HD bool gi_flat(const GiTree& t, int32_t n, float theta) {
    return gi_leaf(t, n) || gi_flat_normal(t.geom[n], theta);
}
VMAP_HD uint64_t gi_pair_key(uint32_t e1, uint32_t e2) {
    return e1 < e2 ? (uint64_t(e1) << 32) | e2 : (uint64_t(e2) << 32) | e1;
}

// Pushes n's children (with `other`) so that they pop in child order; `first` says on which side
// of the pair n stands.
VMAP_HD void gi_push_children(const GiTree& t, int32_t n, int32_t other, bool first, int32_t* sa,
                              int32_t* sb, int& top) {
    int32_t c[8];
    int m = 0;
    for (int32_t k = n + 1; k < t.skip[n] && m < 8; k = t.skip[k]) c[m++] = k;
    for (int k = m - 1; k >= 0; --k, ++top) {
        sa[top] = first ? c[k] : other;
        sb[top] = first ? other : c[k];
    }
}
VMAP_HD int32_t gi_child_toward(const GiTree& t, int32_t a, int32_t x) {
    for (int32_t c = a + 1; c < t.skip[a]; c = t.skip[c])
        if (gi_within(t, x, c)) return c;
    return -1;
}

// What the walk of link (x, y) does with the pair (a, b) on its stack (gi_link_blocks).
enum class GiStep : uint8_t {
    kBlock,       // disjoint, flat and far enough apart: one part (if its kernel is positive)
    kPoints,      // two leaves that are not a block: their point pairs
    kOpenAll,     // open the node that lies within its link end: all its children
    kOpenToward,  // open an ancestor of its link end: its child toward that end only
};
struct GiDecision {
    GiStep step;
    bool open_a;  // for the opening steps: a is opened (else b)
};
VMAP_HD GiDecision gi_decide(const GiTree& t, float theta, int32_t x, int32_t y, int32_t a,
                             int32_t b) {
    const NodeGeom &ga = t.geom[a], &gb = t.geom[b];
    const bool fa = gi_flat(t, a, theta), fb = gi_flat(t, b, theta);
    if (!gi_within(t, a, b) && !gi_within(t, b, a) && fa && fb &&
        length(gb.center - ga.center) > theta * (ga.size + gb.size))
        return {GiStep::kBlock, false};
    const bool la = gi_leaf(t, a), lb = gi_leaf(t, b);
    if (la && lb) return {GiStep::kPoints, false};  // both inside their link ends
    const bool open_a = lb || (!la && (fa == fb ? ga.size >= gb.size : !fa));
    const bool within = open_a ? gi_within(t, a, x) : gi_within(t, b, y);
    return {within ? GiStep::kOpenAll : GiStep::kOpenToward, open_a};
}

// The block refinement of the V-map link (x, y): the link descends from (root, root) along the
// partition of the leaf-pair matrix (a pair of disjoint flat nodes farther apart than theta
// times their sizes is a block; otherwise the node not flat enough, else the larger, is opened)
// and every part (x', y') it holds in block (A, B) gives out(key(A, B), A_x' A_y' K(x', y')),
// x', y' the finer of block node and link end on each side (docs/gi.md). Two leaves that are not
// a block give their point pairs (elements num_nodes + point). Returns the number of parts.
//
// The walk starts with the single pair (a0, b0) on its stack: (0, 0), or a pair that the walk
// from (0, 0) reaches through kOpenToward steps alone (GiLinkPath), which give no part and
// leave one pair on the stack, so the parts and their order are the same.
template <class Out>
VMAP_HD uint32_t gi_link_blocks(const GiTree& t, float theta, int32_t x, int32_t y, Out&& out,
                                int32_t a0 = 0, int32_t b0 = 0) {
    int32_t sa[kGiStack], sb[kGiStack];
    int top = 1;
    sa[0] = a0, sb[0] = b0;
    uint32_t parts = 0;
    const uint32_t base = uint32_t(t.num_nodes);
    while (top > 0) {
        --top;
        const int32_t a = sa[top], b = sb[top];
        const GiDecision d = gi_decide(t, theta, x, y, a, b);
        if (d.step == GiStep::kBlock) {
            const NodeGeom& pa = t.geom[gi_within(t, a, x) ? a : x];
            const NodeGeom& pb = t.geom[gi_within(t, b, y) ? b : y];
            const float k = gi_kernel_hd(pa.center, pa.normal, pa.point_area, pb.center, pb.normal,
                                         pb.point_area);
            if (k > 0) out(gi_pair_key(uint32_t(a), uint32_t(b)), double(pa.area) * pb.area * k);
            parts += k > 0;
        } else if (d.step == GiStep::kPoints) {  // every point pair is visible
            for (uint32_t i = t.point_begin[a]; i < t.point_end[a]; ++i)
                for (uint32_t j = t.point_begin[b]; j < t.point_end[b]; ++j) {
                    const float ai = t.area[i], aj = t.area[j];
                    const float k = gi_kernel_hd(t.position[i], t.normal[i], ai, t.position[j],
                                                 t.normal[j], aj);
                    if (k > 0) out(gi_pair_key(base + i, base + j), double(ai) * aj * k);
                    parts += k > 0;
                }
        } else {
            const int32_t n = d.open_a ? a : b, other = d.open_a ? b : a;
            if (d.step == GiStep::kOpenAll) {
                gi_push_children(t, n, other, d.open_a, sa, sb, top);
            } else {
                const int32_t c = gi_child_toward(t, n, d.open_a ? x : y);
                sa[top] = d.open_a ? c : other, sb[top] = d.open_a ? other : c;
                ++top;
            }
        }
    }
    return parts;
}

// The start of the walks of x's links, kept from one link to the next (the CPU walks a node's
// links in order, and links to nearby nodes share most of the descent from the root). pa/pb
// hold the pairs the last walk passed through by kOpenToward steps, from (0, 0) to the pair
// where those steps ended. For the next link (x, y), every pair up to the deepest one whose b
// holds y is also on y's walk: the steps before it opened a toward x or b toward that pair's b,
// which holds y, and they are decided the same (a step's decision depends on y only through
// whether the opened b lies within y, and no strict ancestor of y does).
struct GiLinkPath {
    static constexpr int kMax = 2 * 22 + 1;  // one step a level on each side, max_height 21
    int32_t pa[kMax], pb[kMax];
    int m = -1;  // pa[m], pb[m]: where the last walk's kOpenToward steps ended

    // Moves to link (x, y) of the same x: a(), b() are then the pair its walk starts from.
    VMAP_HD void seek(const GiTree& t, float theta, int32_t x, int32_t y) {
        int i = 0;
        if (m < 0) {
            pa[0] = 0, pb[0] = 0;
        } else {
            i = m;
            while (i > 0 && !gi_within(t, y, pb[i])) --i;
        }
        for (;;) {
            const GiDecision d = gi_decide(t, theta, x, y, pa[i], pb[i]);
            if (d.step != GiStep::kOpenToward || i + 1 >= kMax) break;
            pa[i + 1] = d.open_a ? gi_child_toward(t, pa[i], x) : pa[i];
            pb[i + 1] = d.open_a ? pb[i] : gi_child_toward(t, pb[i], y);
            ++i;
        }
        m = i;
    }
    VMAP_HD int32_t a() const { return pa[m]; }
    VMAP_HD int32_t b() const { return pb[m]; }
};

// What the final gather reads besides the tree: the hierarchical solution B (per element: nodes,
// then points), which nodes hold an emitter, and the points' emission and albedo.
struct GiGatherView {
    GiTree tree;
    const Vec3* B = nullptr;
    const uint8_t* emits = nullptr;  // per node
    const Vec3* emission = nullptr;  // per point
    const Vec3* albedo = nullptr;    // per point
    float theta = 2;
};

// What point i (position x, normal n, area a) gathers from node L (linked to its leaf or an
// ancestor: all of L sees i): at node level when L holds several points, no emitter, is flat
// and farther than theta times its size from x; else its children, down to points.
VMAP_HD Vec3 gi_gather_node(const GiGatherView& v, Vec3 x, Vec3 n, float a, int32_t L) {
    const GiTree& t = v.tree;
    int32_t st[kGiStack];
    int top = 1;
    st[0] = L;
    Vec3 h{0, 0, 0};
    while (top > 0) {
        const int32_t m = st[--top];
        const NodeGeom& g = t.geom[m];
        if (t.point_end[m] - t.point_begin[m] > 1 && !v.emits[m] && gi_flat_normal(g, v.theta) &&
            length(g.center - x) > v.theta * g.size) {
            const float k = gi_kernel_hd(x, n, a, g.center, g.normal, g.point_area);
            if (k > 0) h = h + v.B[m] * (k * g.area);
        } else if (gi_leaf(t, m)) {
            for (uint32_t j = t.point_begin[m]; j < t.point_end[m]; ++j) {
                const float aj = t.area[j];
                const float k = gi_kernel_hd(x, n, a, t.position[j], t.normal[j], aj);
                if (k > 0) h = h + v.B[uint64_t(t.num_nodes) + j] * (k * aj);
            }
        } else {
            int32_t c[8];
            int cnt = 0;
            for (int32_t k = m + 1; k < t.skip[m] && cnt < 8; k = t.skip[k]) c[cnt++] = k;
            for (int k = cnt - 1; k >= 0; --k) st[top++] = c[k];
        }
    }
    return h;
}

// The final gather of point i: E_i + rho_i times what it gathers over the links of its leaf and
// of every ancestor (leaf first, each node's links in order).
VMAP_HD Vec3 gi_final_gather_point(const GiGatherView& v, uint32_t i) {
    const GiTree& t = v.tree;
    const Vec3 x = t.position[i], n = t.normal[i];
    const float a = t.area[i];
    Vec3 h{0, 0, 0};
    for (int32_t A = t.point_leaf[i]; A >= 0; A = t.parent[A])
        for (uint64_t k = t.link_offsets[A]; k < t.link_offsets[A + 1]; ++k)
            h = h + gi_gather_node(v, x, n, a, t.links[k]);
    const Vec3 E = v.emission[i], rho = v.albedo[i];
    return Vec3{E.x + rho.x * h.x, E.y + rho.y * h.y, E.z + rho.z * h.z};
}

}  // namespace vmap::detail
