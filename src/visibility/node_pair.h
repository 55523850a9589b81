// Node-pair decisions for V-map construction: for a node pair (A, B) (A before B in preorder, so
// every leaf pair under it is oriented from a leaf of A to a leaf of B, as the builder walks it),
// decide without walking a leaf pair that
//   - every leaf pair under A x B passes leaf_pair_visible (all visible: one link), or
//   - none does (none visible: nothing), or
//   - neither can be shown (undecided: the builder splits the pair or walks its leaf pairs).
// Both decisions are proofs about the float predicate of leaf_pair.h AS EVALUATED (rounding
// included), so the V-map is the one the leaf-pair path builds, byte for byte. The bounds are
// computed in double from the float inputs; the float predicate's own rounding is covered by an
// absolute margin E (NodePairContext::margin), derived below. Shared by the CPU and CUDA drivers.
//
// Why E = 1e-5 M suffices, M >= |any coordinate of a centroid, disc or box| (u = 2^-24, vectors
// as floats, "exact" = real arithmetic on those floats):
//  (e1) d = fl(q - p) differs from q - p by <= u|q - p| <= 2uM a component. A float dot product
//       n . v of a unit-length float normal with such a vector differs from the exact n . (q - p)
//       by <= 14uM (component errors of v, three products and two sums).
//  (e2) Facing, dot(n, d) > facing_tol * len with len = sqrtf(length2(d)): the float sides differ
//       from n . (q - p) and tol |q - p| by <= 14uM and <= 10uM. So exact n.(q-p) - tol|q-p| > E
//       makes the float test true, and < -E makes it false.
//  (e3) Occluder x (centroid c, normal n, Delta) with t = fl(num / nd), num = fl(n . fl(c - p)),
//       nd = fl(n . d): if the float test accepts x, the exact point y = p + t (q - p) (t the
//       float value, eps < t < fl(1 - eps)) satisfies |n . (y - c)| <= |t||n.(q-p) - nd| +
//       |t nd - num| + |num - n.(c-p)| <= 14uM + 4uM + 14uM (it lies within 32uM of x's plane),
//       and fl(p + d t) lies within 9uM of y, so |y - c| <= Delta (1 + 3u) + 10uM. Such a y lies
//       in x's content box (its disc's box) grown by 45uM + 3u Delta < E (Delta < 3M), plus the
//       box's own shortfall: octree.cpp reaches Delta sqrt(1 - n_i^2) along axis i with the
//       float normal, whose length is 1 +- 2u, where the unit normal needs sqrt(1 - n_i^2/|n|^2);
//       the two differ by at most Delta sqrt(1e-6) (NodeBounds::pad). For a flagged x (no
//       plane) the same holds with the sphere of radius Delta, which the box holds.
//  (e4) So x is no actual occluder when (i) no exact segment point with t in [eps, fl(1-eps)]
//       comes within E of x's box (the shaft test), or (ii) every such point is farther than E
//       from x's plane (plane-side test), or (iii) the float t cannot lie in (eps, 1 - eps): with
//       |n.(c-p)| <= h and |n.(q-p)| >= D > E, |t| <= (h + E)/(D - E)(1 + u); for x on B's side,
//       n.(c-p) = n.(q-p) - n.(q-c) and |1 - t| <= h/D + 2.5 E/(D - E) + 2u with |n.(q-c)| <= h.
//       Both are below eps when (h + 3E)/(D - E) + 1e-6 < eps (the flat test below); or (iv)
//       every shaft point is farther than E from x's disc (within 32uM of the plane and within
//       Delta + 3u Delta + 10uM of c means within E of the disc).
//  (e5) What counts is narrower than what (e3)/(e4) bound: counts_as_occluder also asks that x
//       stand in front of both ends (in_front_of_ends) and not be crossed from behind within
//       half an end's disc radius of that end (exits_at_an_end), nor cut within the end windows
//       (beyond_the_end_windows). All three only drop occluders that pass the eps window and the
//       disc test; none makes a leaf count that (e3) would reject.
//       So every bound here, an upper bound on the leaves with eps < t < 1 - eps whose disc the
//       segment meets, bounds the leaves that count, and "fewer than K may occlude" stays a
//       proof. (A rule that let a leaf count at t <= eps, or t >= 1 - eps, would need flat_end
//       and the shaft's t range redone; none does.) A leaf crossed in its core counts K
//       (occluder_weight): count_possible_occluders bounds that with the core's own disc.
// Doubles carry relative errors near 1e-16, far inside E.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "octree/records.h"
#include "visibility/leaf_pair.h"

namespace vmap::detail {

// Per node, over the leaves below it (computed by node_bounds()).
struct NodeBounds {
    Vec3 clo, chi;     // box of the leaf centroids (each centroid exactly inside)
    Vec3 axis;         // normal cone axis; the two bounds below hold for this float vector
    float chord = 0;   // >= |n_x - axis| for every leaf x below with a normal
    float s_lo = 0;    // <= axis . c_x for every leaf centroid c_x below (exact real product)
    float s_hi = 0;    // >= axis . c_x
    float pad = 0;     // >= 1e-3 Delta_x for every leaf x below (the box shortfall, e3)
    int32_t flat = 0;  // leaves below with a normal
    int32_t ndeg = 0;  // leaves below flagged kLeafNormalDegenerate
    // The same leaves binned by the direction of their normal (cone_of: 26 bins, the faces,
    // edges and corners of a cube), each bin a cone with the box of its leaves' centroids, in
    // NodeBoundsSet::cones[cone_begin, cone_begin + cone_count) (see num_cones for a node with
    // one leaf below, which may store none): a node holding two walls of a
    // room and the leaves along their edge has three tight cones where one would span 90
    // degrees, each over its own part. For the facing tests.
    uint32_t cone_begin = 0, cone_count = 0;
};

struct NormalCone {
    Vec3 axis;
    float chord = 0;  // >= |n_x - axis| for the cone's leaves
    Vec3 clo, chi;    // box of the cone's leaf centroids
};

struct NodeBoundsSet {
    std::vector<NodeBounds> nodes;
    std::vector<NormalCone> cones;
};

// The bin of a normal: each component below -0.38, between, or above 0.38 (sin 22.5 degrees).
VMAP_HD int cone_of(Vec3 n) {
    auto t = [](float v) { return v < -0.38f ? 0 : (v > 0.38f ? 2 : 1); };
    return t(n.x) + 3 * t(n.y) + 9 * t(n.z);
}

// The bounds of every node of `t` (parallel over nodes).
NodeBoundsSet node_bounds(const Octree& t);

enum class PairDecision : uint8_t { kUndecided = 0, kAllVisible = 1, kNoneVisible = 2 };

// What the node tests read: the walk array, the bounds, the predicate's parameters.
struct NodePairContext {
    OctreeView tree;
    // The bounds of the internal nodes, at node index n, or at bounds_index[n] when that is
    // given (the device keeps only the internal nodes'); a leaf's are leaf_bounds of its disc.
    const NodeBounds* nb = nullptr;
    const NormalCone* cones = nullptr;
    const int32_t* skip = nullptr;  // per node: end of its subtree (preorder)
    VisibilityParams vp;
    double margin = 0;  // E above; 0 disables every decision (all undecided)
    const int32_t* bounds_index = nullptr;
    // True when nb holds every node's bounds, the leaves' too (the host's node_bounds() does:
    // bounds_of stores leaf_bounds for a leaf), so bounds_at reads a leaf's instead of computing
    // them again at every node a shaft walk tests. The same values either way.
    bool leaves_stored = false;
};

// Float rounding of a double bound, outward: never below (down) or above (up) the double value,
// after first widening by `slack` to absorb the double arithmetic's own rounding.
VMAP_HD float round_up(double v, double slack) {
    const float f = float(v + slack);
    return double(f) >= v + slack ? f : nextafterf(f, INFINITY);
}
VMAP_HD float round_down(double v, double slack) {
    const float f = float(v - slack);
    return double(f) <= v - slack ? f : nextafterf(f, -INFINITY);
}

// E for a tree whose root content box is `root`, or 0 where the analysis does not hold (float
// products that could overflow or lose precision to underflow).
inline double node_pair_margin(const Box& root) {
    double m = 0;
    for (float v : {root.lo.x, root.lo.y, root.lo.z, root.hi.x, root.hi.y, root.hi.z})
        m = fabs(double(v)) > m ? fabs(double(v)) : m;
    if (!(m > 1e-10 && m < 1e15)) return 0;
    return 1e-5 * m;
}

struct D3 {
    double x = 0, y = 0, z = 0;
};
VMAP_HD D3 d3(Vec3 v) { return {double(v.x), double(v.y), double(v.z)}; }
VMAP_HD double dot3(D3 a, D3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
VMAP_HD double norm3(D3 a) { return sqrt(dot3(a, a)); }
VMAP_HD double min_d(double a, double b) { return a < b ? a : b; }
VMAP_HD double max_d(double a, double b) { return a > b ? a : b; }

// The bounds of one leaf (node_bounds.cpp's sums over a single leaf, written out): its centroid
// as the box, its normal (normalised in double) as the axis with the chord to the float normal,
// no stored cone (num_cones stands in for it). Computed where they are needed, on the host and
// the device alike, so neither stores a leaf's bounds.
VMAP_HD NodeBounds leaf_bounds(const LeafDisc& d) {
    NodeBounds b;
    b.clo = b.chi = d.centroid;
    b.pad = round_up(1e-3 * double(d.delta), 0);
    b.axis = Vec3{0, 0, 1};
    const D3 nv = d3(d.normal);
    if (d.flags & kLeafNormalDegenerate) {
        b.ndeg = 1;
    } else {
        b.flat = 1;
        const double len = sqrt(nv.x * nv.x + nv.y * nv.y + nv.z * nv.z);
        b.axis = len > 1e-3 ? Vec3{float(nv.x / len), float(nv.y / len), float(nv.z / len)}
                            : d.normal;
    }
    const D3 ax = d3(b.axis), c = d3(d.centroid);
    const double s = dot3(ax, c);
    const double scale = fabs(ax.x * c.x) + fabs(ax.y * c.y) + fabs(ax.z * c.z);
    const double chord = b.flat ? norm3({nv.x - ax.x, nv.y - ax.y, nv.z - ax.z}) : 0.0;
    b.chord = round_up(chord, 1e-12);
    b.s_lo = round_down(s, 1e-12 * scale);
    b.s_hi = round_up(s, 1e-12 * scale);
    return b;
}

// The bounds of node n.
VMAP_HD NodeBounds bounds_at(const NodePairContext& c, int32_t n) {
    const int32_t leaf = c.tree.walk[n].leaf;
    if (leaf >= 0 && !c.leaves_stored) return leaf_bounds(c.tree.leaves[leaf]);
    return c.nb[c.bounds_index ? c.bounds_index[n] : n];
}

// Box of differences q - p, q in [blo, bhi], p in [alo, ahi].
struct DiffBox {
    D3 lo, hi;
};
VMAP_HD DiffBox diff_box(const NodeBounds& A, const NodeBounds& B) {
    return {{double(B.clo.x) - A.chi.x, double(B.clo.y) - A.chi.y, double(B.clo.z) - A.chi.z},
            {double(B.chi.x) - A.clo.x, double(B.chi.y) - A.clo.y, double(B.chi.z) - A.clo.z}};
}
VMAP_HD D3 corner(const DiffBox& b, int k) {
    return {(k & 1) ? b.hi.x : b.lo.x, (k & 2) ? b.hi.y : b.lo.y, (k & 4) ? b.hi.z : b.lo.z};
}
// min over y in the box of n . y - k |y|, k >= 0: a concave function, so the minimum is at a
// corner.
VMAP_HD double min_lin_minus_norm(const DiffBox& b, D3 n, double k) {
    double m = 1e300;
    for (int c = 0; c < 8; ++c) {
        const D3 y = corner(b, c);
        m = min_d(m, dot3(n, y) - k * norm3(y));
    }
    return m;
}
// The same over the box's corners with their lengths computed once.
struct Corners {
    D3 y[8];
    double len[8];
};
VMAP_HD Corners corners_of(const DiffBox& b) {
    Corners c;
    for (int k = 0; k < 8; ++k) {
        c.y[k] = corner(b, k);
        c.len[k] = norm3(c.y[k]);
    }
    return c;
}
VMAP_HD double min_lin_minus_norm(const Corners& c, D3 n, double k) {
    double m = 1e300;
    for (int i = 0; i < 8; ++i) m = min_d(m, dot3(n, c.y[i]) - k * c.len[i]);
    return m;
}
// Smallest |y| over the box.
VMAP_HD double min_norm(const DiffBox& b) {
    auto gap = [](double lo, double hi) { return lo > 0 ? lo : (hi < 0 ? -hi : 0.0); };
    const D3 g{gap(b.lo.x, b.hi.x), gap(b.lo.y, b.hi.y), gap(b.lo.z, b.hi.z)};
    return norm3(g);
}
// max over y in the box of n . y + k |y| for any real k (an upper bound when k < 0).
VMAP_HD double max_lin_plus_norm(const DiffBox& b, D3 n, double k) {
    double m = -1e300;
    for (int c = 0; c < 8; ++c) {
        const D3 y = corner(b, c);
        m = max_d(m, dot3(n, y) + (k > 0 ? k * norm3(y) : 0.0));
    }
    return k > 0 ? m : m + k * min_norm(b);
}

// The differences q - p from a cone of A (s = 1: p in the cone's box, q in B's box) or to a
// cone of B (s = -1: p in A's box, q in the cone's box).
VMAP_HD DiffBox cone_diff_box(const NodeBounds& A, const NodeBounds& B, double s,
                              const NormalCone& k) {
    Vec3 alo = A.clo, ahi = A.chi, blo = B.clo, bhi = B.chi;
    if (s > 0)
        alo = k.clo, ahi = k.chi;
    else
        blo = k.clo, bhi = k.chi;
    return {{double(blo.x) - ahi.x, double(blo.y) - ahi.y, double(blo.z) - ahi.z},
            {double(bhi.x) - alo.x, double(bhi.y) - alo.y, double(bhi.z) - alo.z}};
}
// X's cones: those stored, or, when none is stored for a node with one leaf below (a leaf, or a
// chain of single children down to one), that leaf's own cone, which is X's own axis, chord and
// centroid box (node_bounds.cpp stores it only where the two differ: a cone per leaf less, in
// host and device memory).
VMAP_HD uint32_t num_cones(const NodeBounds& X) {
    return X.cone_count > 0 ? X.cone_count : (X.flat + X.ndeg == 1 ? uint32_t(X.flat) : 0u);
}
VMAP_HD NormalCone cone_at(const NormalCone* cones, const NodeBounds& X, uint32_t i) {
    return X.cone_count > 0 ? cones[X.cone_begin + i] : NormalCone{X.axis, X.chord, X.clo, X.chi};
}

// Does every leaf with a normal under X (X = A with s = 1, X = B with s = -1; direction s n_x)
// face every leaf at the other end, n_x . y - tol |y| > E (e2)? Cone by cone. Leaves without a
// normal face everything.
VMAP_HD bool all_face(const NormalCone* cones, const NodeBounds& A, const NodeBounds& B, double s,
                      double tol, double E) {
    const NodeBounds& X = s > 0 ? A : B;
    for (uint32_t i = 0; i < num_cones(X); ++i) {
        const NormalCone k = cone_at(cones, X, i);
        const Corners c = corners_of(cone_diff_box(A, B, s, k));
        const D3 n{s * k.axis.x, s * k.axis.y, s * k.axis.z};
        if (!(min_lin_minus_norm(c, n, k.chord + tol) > E)) return false;
    }
    return true;
}
// Does no leaf under X face any leaf at the other end (n_x . y - tol |y| < -E, cone by cone;
// X has no flagged leaf)?
VMAP_HD bool none_face(const NormalCone* cones, const NodeBounds& A, const NodeBounds& B, double s,
                       double tol, double E) {
    const NodeBounds& X = s > 0 ? A : B;
    if (X.ndeg > 0 || X.flat == 0) return false;
    for (uint32_t i = 0; i < num_cones(X); ++i) {
        const NormalCone k = cone_at(cones, X, i);
        const D3 n{s * k.axis.x, s * k.axis.y, s * k.axis.z};
        if (!(max_lin_plus_norm(cone_diff_box(A, B, s, k), n, k.chord - tol) < -E)) return false;
    }
    return true;
}

// (e4 iii) for the leaves with a normal under X, X = A (s = 1) or X = B (s = -1): their planes
// are crossed only at t < eps (A) or t > 1 - eps (B) by every segment from A's centroids to B's.
VMAP_HD bool flat_end(const NodeBounds& X, double s, const DiffBox& b, double eps, double E) {
    if (X.flat == 0) return false;
    const D3 n{s * X.axis.x, s * X.axis.y, s * X.axis.z};
    const D3 diag{double(X.chi.x) - X.clo.x, double(X.chi.y) - X.clo.y, double(X.chi.z) - X.clo.z};
    const double h = (double(X.s_hi) - X.s_lo) + double(X.chord) * norm3(diag);
    const double D = min_lin_minus_norm(b, n, double(X.chord));
    return D > 2 * E && (h + 3 * E) / (D - E) + 1e-6 < eps;
}

// The swept set of the segments from A's centroid box to B's at t in [t0, t1]: the union over t
// of the boxes (1 - t) [alo, ahi] + t [blo, bhi]. Per axis and face, the face moves linearly in
// t: lower face al + t (bl - al), upper face ah + t (bh - ah); their slopes' reciprocals are kept
// (0 for a face that does not move).
struct Shaft {
    D3 alo, ahi, blo, bhi;
    double t0, t1;
    double inv_lo[3], inv_hi[3];
};
VMAP_HD Shaft make_shaft(Vec3 alo, Vec3 ahi, Vec3 blo, Vec3 bhi, double t0, double t1) {
    Shaft s{d3(alo), d3(ahi), d3(blo), d3(bhi), t0, t1, {0, 0, 0}, {0, 0, 0}};
    const double al[3] = {s.alo.x, s.alo.y, s.alo.z}, ah[3] = {s.ahi.x, s.ahi.y, s.ahi.z};
    const double bl[3] = {s.blo.x, s.blo.y, s.blo.z}, bh[3] = {s.bhi.x, s.bhi.y, s.bhi.z};
    for (int i = 0; i < 3; ++i) {
        s.inv_lo[i] = bl[i] != al[i] ? 1.0 / (bl[i] - al[i]) : 0.0;
        s.inv_hi[i] = bh[i] != ah[i] ? 1.0 / (ah[i] - bh[i]) : 0.0;
    }
    return s;
}
// Does the shaft meet box [lo - g, hi + g]? Per axis the moving box overlaps it for t in an
// interval bounded by two linear inequalities v0 + sl t <= 0 (lower face al + t (bl - al) <= xh,
// upper face ah + t (bh - ah) >= xl); the test is exact up to double rounding (far inside g).
VMAP_HD bool shaft_meets_box(const Shaft& s, Vec3 lo, Vec3 hi, double g) {
    double tmin = s.t0, tmax = s.t1;
    const double al[3] = {s.alo.x, s.alo.y, s.alo.z}, ah[3] = {s.ahi.x, s.ahi.y, s.ahi.z};
    const double xl[3] = {lo.x - g, lo.y - g, lo.z - g}, xh[3] = {hi.x + g, hi.y + g, hi.z + g};
    for (int i = 0; i < 3; ++i) {
        const double v0[2] = {al[i] - xh[i], xl[i] - ah[i]};
        const double inv[2] = {s.inv_lo[i], s.inv_hi[i]};
        for (int k = 0; k < 2; ++k) {
            if (inv[k] > 0)
                tmax = min_d(tmax, -v0[k] * inv[k]);
            else if (inv[k] < 0)
                tmin = max_d(tmin, -v0[k] * inv[k]);
            else if (v0[k] > 0)
                return false;
        }
        if (tmin > tmax) return false;
    }
    return true;
}

// (e4 ii) Is every shaft point farther than E from the plane of every leaf under X (X has no
// flagged leaf)? n_x . (y - c_x) = axis . y - axis . c_x + (n_x - axis) . (y - c_x).
VMAP_HD bool shaft_clear_of_planes(const Shaft& s, const NodeBounds& X, double E) {
    if (X.ndeg > 0 || X.flat == 0) return false;
    const D3 n = d3(X.axis);
    auto support = [&](D3 lo, D3 hi, double sign) {  // max of sign * n . y over the box
        const double v[3] = {n.x * sign, n.y * sign, n.z * sign};
        const double l[3] = {lo.x, lo.y, lo.z}, h[3] = {hi.x, hi.y, hi.z};
        double r = 0;
        for (int i = 0; i < 3; ++i) r += max_d(v[i] * l[i], v[i] * h[i]);
        return r;
    };
    // n . y over the shaft is linear in t on each box's support: extreme at t0 or t1.
    double lo = 1e300, hi = -1e300;
    for (double t : {s.t0, s.t1}) {
        const double mn = (1 - t) * -support(s.alo, s.ahi, -1) + t * -support(s.blo, s.bhi, -1);
        const double mx = (1 - t) * support(s.alo, s.ahi, 1) + t * support(s.blo, s.bhi, 1);
        lo = min_d(lo, mn);
        hi = max_d(hi, mx);
    }
    // Farthest distance between the shaft's bounding box and X's centroid box.
    const D3 a{min_d(s.alo.x, s.blo.x), min_d(s.alo.y, s.blo.y), min_d(s.alo.z, s.blo.z)};
    const D3 b{max_d(s.ahi.x, s.bhi.x), max_d(s.ahi.y, s.bhi.y), max_d(s.ahi.z, s.bhi.z)};
    const D3 far{max_d(b.x - X.clo.x, X.chi.x - a.x), max_d(b.y - X.clo.y, X.chi.y - a.y),
                 max_d(b.z - X.clo.z, X.chi.z - a.z)};
    const double wobble = double(X.chord) * norm3(far);
    return lo - X.s_hi - wobble > E || hi - X.s_lo + wobble < -E;
}

// (e4 iv) Is every shaft point farther than E from leaf x's disc (its ball when flagged)? The
// shaft lies within w = max(rA, rB) of its central segment y(t) = p0 + t d0 (at the same t), and
// for a point of that segment: plane distance = alpha |t - t*| (t* where it crosses the plane),
// in-plane distance from c >= Q0 - beta |t - t*| (Q0 at t*), so its distance to the disc is at
// least max(alpha s, Q - beta s), s = |t - t*|, Q = Q0 - Delta; minimised over s >= the distance
// from t* to [t0, t1].
VMAP_HD bool shaft_clear_of_disc(const Shaft& s, const LeafDisc& x, double E) {
    const D3 p0{(s.alo.x + s.ahi.x) / 2, (s.alo.y + s.ahi.y) / 2, (s.alo.z + s.ahi.z) / 2};
    const D3 q0{(s.blo.x + s.bhi.x) / 2, (s.blo.y + s.bhi.y) / 2, (s.blo.z + s.bhi.z) / 2};
    const D3 d0{q0.x - p0.x, q0.y - p0.y, q0.z - p0.z};
    const D3 ra{s.ahi.x - p0.x, s.ahi.y - p0.y, s.ahi.z - p0.z};
    const D3 rb{s.bhi.x - q0.x, s.bhi.y - q0.y, s.bhi.z - q0.z};
    const double w = max_d(norm3(ra), norm3(rb)) * (1 + 1e-12);
    const D3 c = d3(x.centroid), v{p0.x - c.x, p0.y - c.y, p0.z - c.z};
    const double delta = double(x.delta);
    if (x.flags & kLeafNormalDegenerate) {  // distance from c to the segment, minus Delta
        const double dd = dot3(d0, d0);
        double t = dd > 0 ? -dot3(v, d0) / dd : s.t0;
        t = min_d(max_d(t, s.t0), s.t1);
        const D3 y{v.x + d0.x * t, v.y + d0.y * t, v.z + d0.z * t};
        return norm3(y) * (1 - 1e-12) - delta - w > E;
    }
    const double nl = norm3(d3(x.normal));
    if (!(nl > 0)) return false;
    const D3 n{x.normal.x / nl, x.normal.y / nl, x.normal.z / nl};
    const double nd = dot3(n, d0), nv = dot3(n, v);
    const double alpha = fabs(nd);
    const double beta = sqrt(max_d(0.0, dot3(d0, d0) - nd * nd));
    if (!(alpha > 1e-9 * norm3(d0))) return fabs(nv) * (1 - 1e-12) - w > E;
    const double ts = -nv / nd;
    const D3 ys{v.x + d0.x * ts, v.y + d0.y * ts, v.z + d0.z * ts};  // y(t*) - c, in the plane
    const double q = norm3(ys) - delta;
    const double smin = ts < s.t0 ? s.t0 - ts : (ts > s.t1 ? ts - s.t1 : 0.0);
    double lb = alpha * smin;
    if (q - beta * smin > lb) {  // the minimum of the max lies beyond smin, where both meet
        lb = alpha * q / (alpha + beta);
    }
    return lb * (1 - 1e-9) - w > E;
}

// The shaft of node pair (A, B): the segments between their centroid boxes at t in
// [eps, 1 - eps].
VMAP_HD Shaft pair_shaft(const NodePairContext& c, int32_t A, int32_t B) {
    const NodeBounds na = bounds_at(c, A);
    const NodeBounds nbb = bounds_at(c, B);
    return make_shaft(na.clo, na.chi, nbb.clo, nbb.chi, double(c.vp.eps), double(1.f - c.vp.eps));
}

// Walks the tree nodes that may hold an actual occluder of some segment from A's centroids to
// B's (e4), like leaf_pair_visible walks the preorder array, pruning a subtree when the shaft
// misses its box, when it lies under A or B with that end flat, or when the shaft clears all its
// planes, and a leaf when the shaft clears its disc. A or B itself, when a leaf, is the pair's
// own end and never entered. Calls enter(n) for each node entered, in preorder; a false return
// stops the walk. Counts the nodes tested into wc->shaft_node_tests.
// `s` is pair_shaft(c, A, B).
template <class Counters, class Enter>
VMAP_HD void walk_shaft(const NodePairContext& c, const Shaft& s, int32_t A, int32_t B,
                        bool flat_a, bool flat_b, Counters* wc, Enter&& enter) {
    const double E = c.margin;
    const bool a_leaf = c.tree.walk[A].leaf >= 0, b_leaf = c.tree.walk[B].leaf >= 0;
    int32_t n = 0;
    while (n < c.tree.num_nodes) {
        wc->shaft_node_tests++;
        const WalkNode w = c.tree.walk[n];
        const bool in_a = n >= A && n < c.skip[A], in_b = n >= B && n < c.skip[B];
        const NodeBounds x = bounds_at(c, n);
        if (!shaft_meets_box(s, w.lo, w.hi, E + x.pad) ||
            (in_a && (a_leaf || (flat_a && x.ndeg == 0))) ||
            (in_b && (b_leaf || (flat_b && x.ndeg == 0))) || shaft_clear_of_planes(s, x, E) ||
            (w.leaf >= 0 && shaft_clear_of_disc(s, c.tree.leaves[w.leaf], E))) {
            n = w.skip;
            continue;
        }
        if (!enter(n)) return;
        ++n;
    }
}

// Whether each end is flat for the other (flat_end), for walk_shaft.
VMAP_HD void flat_ends(const NodePairContext& c, int32_t A, int32_t B, bool* fa, bool* fb) {
    const NodeBounds na = bounds_at(c, A), nbb = bounds_at(c, B);
    const DiffBox db = diff_box(na, nbb);
    *fa = flat_end(na, 1, db, c.vp.eps, c.margin);
    *fb = flat_end(nbb, -1, db, c.vp.eps, c.margin);
}

// Leaf x's core (VisibilityParams::core) as a disc of its own: x with Delta = core_radius, the
// float the walks square.
VMAP_HD LeafDisc core_disc(const LeafDisc& x, const VisibilityParams& vp) {
    LeafDisc k = x;
    k.delta = core_radius(x, vp);
    return k;
}

// The occluders some segment from A's centroids to B's may count, up to `limit`: each leaf that
// may be an actual occluder of one counts one, or `limit` when a segment may also cross its core
// (a crossing there counts K: occluder_weight). The core is a disc like x's own with radius
// rc = core_radius(x), the float the walks compare with: (e3) with rc for Delta puts a crossing
// the float test finds in the core within E of the core disc, so shaft_clear_of_disc with rc
// (e4 iv) proves that no segment crosses it. Without cores (cores_on) every crossing counts one,
// or, with K 1, already K.
template <class Counters>
VMAP_HD int count_possible_occluders(const NodePairContext& c, int32_t A, int32_t B, int limit,
                                     Counters* wc) {
    bool flat_a, flat_b;
    flat_ends(c, A, B, &flat_a, &flat_b);
    const bool cores = cores_on(c.vp);
    const Shaft s = pair_shaft(c, A, B);
    int count = 0;
    walk_shaft(c, s, A, B, flat_a, flat_b, wc, [&](int32_t n) {
        const int32_t leaf = c.tree.walk[n].leaf;
        if (leaf < 0) return true;
        count += cores && !shaft_clear_of_disc(s, core_disc(c.tree.leaves[leaf], c.vp), c.margin)
                     ? limit
                     : 1;
        return count < limit;
    });
    return count;
}

// The part of the walk array the leaf pairs under (A, B) can need: the nodes walk_shaft enters,
// in preorder with skips remapped to this list (an ancestor-closed top of the tree: a node is
// entered only when its parent was). Walking it instead of the whole array counts the same
// actual occluders: every actual occluder of a segment under (A, B), and each of its ancestors,
// is entered (walk_shaft prunes only what holds none, e4), and a node of the list is reached
// exactly when the full walk reaches it (the same float box tests on the same ancestors). So
// the answers are those of the full walk, byte for byte; the work counted is less. `orig` is
// scratch.
// The skips of a list of tree nodes (out[k] the record of preorder node orig[k]) remapped to
// the list: a node's skip becomes the first entry past its subtree. Entries come in preorder
// and the list is ancestor-closed, so the open nodes form a stack (the innermost on top) and an
// entry closes every open node whose subtree ends at or before it. `orig` is used up (reused
// as the stack: orig[k] is needed only for entries after k).
inline void list_skips(std::vector<WalkNode>& out, std::vector<int32_t>& orig) {
    std::vector<int32_t>& open = orig;
    size_t top = 0;
    for (size_t k = 0; k < out.size(); ++k) {
        const int32_t o = orig[k];
        while (top > 0 && out[size_t(open[top - 1])].skip <= o)
            out[size_t(open[--top])].skip = int32_t(k);
        open[top++] = int32_t(k);
    }
    while (top > 0) out[size_t(open[--top])].skip = int32_t(out.size());
}

inline void shaft_walk_nodes(const NodePairContext& c, int32_t A, int32_t B,
                             std::vector<WalkNode>& out, std::vector<int32_t>& orig) {
    out.clear();
    orig.clear();
    bool flat_a, flat_b;
    flat_ends(c, A, B, &flat_a, &flat_b);
    struct {
        uint64_t shaft_node_tests = 0;
    } wc;
    walk_shaft(c, pair_shaft(c, A, B), A, B, flat_a, flat_b, &wc, [&](int32_t n) {
        out.push_back(c.tree.walk[n]);
        orig.push_back(n);
        return true;
    });
    list_skips(out, orig);
}

// Whether the construction tests (A, B) at all: a pair of two leaves is one leaf pair, walked
// untested (a node-pair test costs a few walks).
VMAP_HD bool worth_deciding(const NodePairContext& c, int32_t A, int32_t B) {
    return c.margin > 0 && (c.tree.walk[A].leaf < 0 || c.tree.walk[B].leaf < 0);
}

// The decision for node pair (A, B), A before B in preorder (see the top of this file).
template <class Counters>
VMAP_HD PairDecision decide_node_pair(const NodePairContext& c, int32_t A, int32_t B,
                                      Counters* wc) {
    if (!(c.margin > 0)) return PairDecision::kUndecided;
    const NodeBounds na = bounds_at(c, A);
    const NodeBounds nbb = bounds_at(c, B);
    const DiffBox db = diff_box(na, nbb);
    const double E = c.margin, tol = c.vp.facing_tol;
    // Facing fails for every pair when it fails for every leaf of one end.
    if (none_face(c.cones, na, nbb, 1, tol, E) || none_face(c.cones, na, nbb, -1, tol, E))
        return PairDecision::kNoneVisible;
    // All visible: a direction to see along (len > 0 in float: |q - p| > E), every leaf of A
    // faces every leaf of B and back, and fewer than K leaves may occlude any segment.
    if (!(min_norm(db) > E)) return PairDecision::kUndecided;
    if (!all_face(c.cones, na, nbb, 1, tol, E) || !all_face(c.cones, na, nbb, -1, tol, E))
        return PairDecision::kUndecided;
    if (count_possible_occluders(c, A, B, c.vp.K, wc) < c.vp.K) return PairDecision::kAllVisible;
    return PairDecision::kUndecided;
}

}  // namespace vmap::detail
