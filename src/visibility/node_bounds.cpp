// Per-node bounds for the node-pair decisions (node_pair.h): centroid box, normal cone, the
// spread of the centroids along the cone axis. Each node reads its own leaf range (contiguous in
// preorder), so the pass is O(leaves x height), in parallel over nodes.
#include <tbb/parallel_for.h>

#include <cmath>

#include "visibility/node_pair.h"

namespace vmap::detail {
namespace {

// Float rounding of a double bound, outward: never below (down) or above (up) the double value,
// after first widening by `slack` to absorb the double arithmetic's own rounding.
float round_up(double v, double slack) {
    const float f = float(v + slack);
    return double(f) >= v + slack ? f : std::nextafter(f, INFINITY);
}
float round_down(double v, double slack) {
    const float f = float(v - slack);
    return double(f) <= v - slack ? f : std::nextafter(f, -INFINITY);
}

NodeBounds bounds_of(const Octree& t, int32_t n) {
    NodeBounds b;
    const int32_t l0 = t.leaf_begin[n], l1 = t.leaf_end[n];
    double sx = 0, sy = 0, sz = 0;
    double cs[6][3] = {};
    Vec3 first{0, 0, 1};
    b.clo = b.chi = t.leaves[l0].centroid;
    for (int32_t l = l0; l < l1; ++l) {
        const LeafDisc& d = t.leaves[l];
        const Vec3 c = d.centroid;
        b.clo = {std::fmin(b.clo.x, c.x), std::fmin(b.clo.y, c.y), std::fmin(b.clo.z, c.z)};
        b.chi = {std::fmax(b.chi.x, c.x), std::fmax(b.chi.y, c.y), std::fmax(b.chi.z, c.z)};
        b.pad = std::fmax(b.pad, round_up(1e-3 * double(d.delta), 0));
        if (d.flags & kLeafNormalDegenerate) {
            b.ndeg++;
            continue;
        }
        if (b.flat++ == 0) first = d.normal;
        sx += d.normal.x, sy += d.normal.y, sz += d.normal.z;
        const int k = cone_of(d.normal);
        NodeBounds::Cone& cn = b.cone[k];
        if (!(b.cones >> k & 1)) cn.axis = d.normal, cn.clo = cn.chi = c;  // axis if they cancel
        b.cones |= 1u << k;
        cn.clo = {std::fmin(cn.clo.x, c.x), std::fmin(cn.clo.y, c.y), std::fmin(cn.clo.z, c.z)};
        cn.chi = {std::fmax(cn.chi.x, c.x), std::fmax(cn.chi.y, c.y), std::fmax(cn.chi.z, c.z)};
        cs[k][0] += d.normal.x, cs[k][1] += d.normal.y, cs[k][2] += d.normal.z;
    }
    double cone_chord[6] = {};
    for (int k = 0; k < 6; ++k) {
        const double l = std::sqrt(cs[k][0] * cs[k][0] + cs[k][1] * cs[k][1] + cs[k][2] * cs[k][2]);
        if (l > 1e-3) b.cone[k].axis = {float(cs[k][0] / l), float(cs[k][1] / l), float(cs[k][2] / l)};
    }
    const double len = std::sqrt(sx * sx + sy * sy + sz * sz);
    // Any float vector serves as the axis (the bounds hold for it as stored); the mean normal
    // makes them tight, the first normal stands in when the normals cancel.
    b.axis = len > 1e-3 * b.flat ? Vec3{float(sx / len), float(sy / len), float(sz / len)} : first;
    const D3 ax = d3(b.axis);
    double chord = 0, lo = INFINITY, hi = -INFINITY, scale = 0;
    for (int32_t l = l0; l < l1; ++l) {
        const LeafDisc& d = t.leaves[l];
        const D3 c = d3(d.centroid);
        const double s = dot3(ax, c);
        lo = std::fmin(lo, s);
        hi = std::fmax(hi, s);
        scale = std::fmax(scale, std::fabs(ax.x * c.x) + std::fabs(ax.y * c.y) +
                                     std::fabs(ax.z * c.z));
        if (d.flags & kLeafNormalDegenerate) continue;
        const D3 nv = d3(d.normal);
        chord = std::fmax(chord, norm3({nv.x - ax.x, nv.y - ax.y, nv.z - ax.z}));
        const int k = cone_of(d.normal);
        const D3 ck = d3(b.cone[k].axis);
        cone_chord[k] = std::fmax(cone_chord[k], norm3({nv.x - ck.x, nv.y - ck.y, nv.z - ck.z}));
    }
    for (int k = 0; k < 6; ++k) b.cone[k].chord = round_up(cone_chord[k], 1e-12);
    // Doubles err by a few 1e-16 relative: widen by 1e-12 of the magnitudes before rounding.
    b.chord = round_up(chord, 1e-12);
    b.s_lo = round_down(lo, 1e-12 * scale);
    b.s_hi = round_up(hi, 1e-12 * scale);
    return b;
}

}  // namespace

std::vector<NodeBounds> node_bounds(const Octree& t) {
    std::vector<NodeBounds> out(t.num_nodes());
    tbb::parallel_for(int32_t(0), t.num_nodes(), [&](int32_t n) { out[n] = bounds_of(t, n); });
    return out;
}

}  // namespace vmap::detail
