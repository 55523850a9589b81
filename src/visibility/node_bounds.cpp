// Per-node bounds for the node-pair decisions (node_pair.h): centroid box, normal cone, the
// spread of the centroids along the cone axis. Each node reads its own leaf range (contiguous in
// preorder), so the pass is O(leaves x height), in parallel over nodes.
#include <tbb/parallel_for.h>

#include <array>
#include <cmath>

#include "octree/records.h"
#include "visibility/node_pair.h"

namespace vmap::detail {
namespace {

// What one pass over a node's leaves gathers: the node's bounds so far, its normal sums, and
// per normal bin (cone_of) the cone and its normal sums.
struct Gather {
    NodeBounds b;
    double sx = 0, sy = 0, sz = 0;
    Vec3 first{0, 0, 1};
    std::array<double, 27 * 3> bin_sum{};
    std::array<int32_t, 27> bin_at;
    std::array<NormalCone, 27> bin{};
};

// First pass: centroid boxes (node and bins), pad, counts, normal sums.
void gather_leaves(const Octree& t, int32_t l0, int32_t l1, Gather& g) {
    NodeBounds& b = g.b;
    b.clo = b.chi = leaf_discs(t)[l0].centroid;
    g.bin_at.fill(-1);
    for (int32_t l = l0; l < l1; ++l) {
        const LeafDisc& d = leaf_discs(t)[l];
        const Vec3 c = d.centroid;
        b.clo = {std::fmin(b.clo.x, c.x), std::fmin(b.clo.y, c.y), std::fmin(b.clo.z, c.z)};
        b.chi = {std::fmax(b.chi.x, c.x), std::fmax(b.chi.y, c.y), std::fmax(b.chi.z, c.z)};
        b.pad = std::fmax(b.pad, round_up(1e-3 * double(d.delta), 0));
        if (d.flags & kLeafNormalDegenerate) {
            b.ndeg++;
            continue;
        }
        if (b.flat++ == 0) g.first = d.normal;
        g.sx += d.normal.x, g.sy += d.normal.y, g.sz += d.normal.z;
        const int k = cone_of(d.normal);
        NormalCone& cn = g.bin[k];
        if (g.bin_at[k] < 0) g.bin_at[k] = 0, cn.axis = d.normal, cn.clo = cn.chi = c;
        cn.clo = {std::fmin(cn.clo.x, c.x), std::fmin(cn.clo.y, c.y), std::fmin(cn.clo.z, c.z)};
        cn.chi = {std::fmax(cn.chi.x, c.x), std::fmax(cn.chi.y, c.y), std::fmax(cn.chi.z, c.z)};
        g.bin_sum[3 * k] += d.normal.x, g.bin_sum[3 * k + 1] += d.normal.y;
        g.bin_sum[3 * k + 2] += d.normal.z;
    }
}

// Any float vector serves as an axis (the bounds hold for it as stored); the mean normal makes
// them tight, the first normal stands in when the normals cancel.
Vec3 mean_axis(double x, double y, double z, double cnt, Vec3 fallback) {
    const double len = std::sqrt(x * x + y * y + z * z);
    return len > 1e-3 * cnt ? Vec3{float(x / len), float(y / len), float(z / len)} : fallback;
}

void set_axes(Gather& g) {
    g.b.axis = mean_axis(g.sx, g.sy, g.sz, g.b.flat, g.first);
    for (int k = 0; k < 27; ++k)
        if (g.bin_at[k] >= 0)
            g.bin[k].axis = mean_axis(g.bin_sum[3 * k], g.bin_sum[3 * k + 1],
                                      g.bin_sum[3 * k + 2], 1, g.bin[k].axis);
}

// Second pass, about the axes: the chords of the node's and the bins' cones, the spread of the
// centroids along the node's axis; the node's cones go to `cones`.
void spread_and_chords(const Octree& t, int32_t l0, int32_t l1, Gather& g,
                       std::vector<NormalCone>& cones) {
    NodeBounds& b = g.b;
    const D3 ax = d3(b.axis);
    double chord = 0, lo = INFINITY, hi = -INFINITY, scale = 0;
    std::array<double, 27> bin_chord{};
    for (int32_t l = l0; l < l1; ++l) {
        const LeafDisc& d = leaf_discs(t)[l];
        const D3 c = d3(d.centroid);
        const double s = dot3(ax, c);
        lo = std::fmin(lo, s);
        hi = std::fmax(hi, s);
        scale =
            std::fmax(scale, std::fabs(ax.x * c.x) + std::fabs(ax.y * c.y) + std::fabs(ax.z * c.z));
        if (d.flags & kLeafNormalDegenerate) continue;
        const D3 nv = d3(d.normal);
        chord = std::fmax(chord, norm3({nv.x - ax.x, nv.y - ax.y, nv.z - ax.z}));
        const int k = cone_of(d.normal);
        const D3 ck = d3(g.bin[k].axis);
        bin_chord[k] = std::fmax(bin_chord[k], norm3({nv.x - ck.x, nv.y - ck.y, nv.z - ck.z}));
    }
    // Doubles err by a few 1e-16 relative: widen by 1e-12 of the magnitudes before rounding.
    b.chord = round_up(chord, 1e-12);
    b.s_lo = round_down(lo, 1e-12 * scale);
    b.s_hi = round_up(hi, 1e-12 * scale);
    for (int k = 0; k < 27; ++k) {
        if (g.bin_at[k] < 0) continue;
        g.bin[k].chord = round_up(bin_chord[k], 1e-12);
        cones.push_back(g.bin[k]);
        b.cone_count++;
    }
}

// One leaf below: its cone is the node's own bounds (the same sums and roundings), which
// num_cones and cone_at (node_pair.h) stand in for; kept only if a bit differed.
void drop_own_cone(NodeBounds& b, std::vector<NormalCone>& cones) {
    if (b.flat != 1 || b.ndeg != 0 || cones.size() != 1) return;
    const NormalCone& k = cones[0];
    auto same = [](Vec3 u, Vec3 v) { return u.x == v.x && u.y == v.y && u.z == v.z; };
    if (same(k.axis, b.axis) && k.chord == b.chord && same(k.clo, b.clo) && same(k.chi, b.chi)) {
        cones.clear();
        b.cone_count = 0;
    }
}

// Node n's bounds; its cones (one per normal bin present, in bin order) go to `cones`.
NodeBounds bounds_of(const Octree& t, int32_t n, std::vector<NormalCone>& cones) {
    if (t.is_leaf(n)) return leaf_bounds(leaf_discs(t)[t.node_leaf()[n]]);
    const int32_t l0 = t.leaf_begin()[n], l1 = t.leaf_end()[n];
    Gather g;
    gather_leaves(t, l0, l1, g);
    set_axes(g);
    spread_and_chords(t, l0, l1, g, cones);
    drop_own_cone(g.b, cones);
    return g.b;
}

}  // namespace

NodeBoundsSet node_bounds(const Octree& t) {
    NodeBoundsSet out;
    out.nodes.resize(t.num_nodes());
    std::vector<std::vector<NormalCone>> cones(t.num_nodes());
    tbb::parallel_for(int32_t(0), t.num_nodes(),
                      [&](int32_t n) { out.nodes[n] = bounds_of(t, n, cones[n]); });
    for (int32_t n = 0; n < t.num_nodes(); ++n) {
        out.nodes[n].cone_begin = uint32_t(out.cones.size());
        out.cones.insert(out.cones.end(), cones[n].begin(), cones[n].end());
    }
    return out;
}

}  // namespace vmap::detail
