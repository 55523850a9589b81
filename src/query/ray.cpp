// Points by position and ray shooting pruned by the V-map (include/vmap/query.h).
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "vmap/error.h"
#include "vmap/query.h"

namespace vmap {
namespace {

struct Ray {
    Vec3 o, d, inv;   // origin, unit direction, 1 / direction per axis
    float scale = 1;  // disc radius = splat radius x scale
};

void check(const VisibilityMap& vm, uint32_t from, Vec3 dir, float scale) {
    vm.require_links("ray");
    if (!(scale > 0 && scale <= 100))
        throw Error(fmt::format("ray: splat scale {} out of range (0, 100]", scale));
    const size_t n = vm.points().size();
    if (from >= n)
        throw Error(
            fmt::format("ray: point id {} out of range (the V-map has {} points)", from, n));
    if (!is_finite(dir) || (dir.x == 0 && dir.y == 0 && dir.z == 0))
        throw Error("ray: the direction must be finite and non-zero");
    if (!vm.points().has_normals() || !vm.points().has_radii())
        throw Error("ray: the V-map's points have no normals or splat radii");
}

Ray make_ray(const VisibilityMap& vm, uint32_t from, Vec3 dir, float scale) {
    Ray r;
    r.scale = scale;
    r.o = vm.points().positions[vm.inverse()[from]];
    // Normalised in double: the length of a very long or very short float vector over- or
    // underflows in float.
    const double dx = dir.x, dy = dir.y, dz = dir.z, l = std::sqrt(dx * dx + dy * dy + dz * dz);
    r.d = {float(dx / l), float(dy / l), float(dz / l)};
    r.inv = {1.f / r.d.x, 1.f / r.d.y, 1.f / r.d.z};  // +-inf for a zero component: slabs work
    return r;
}

// Two-sided disc test for the point at octree position k; updates best (t, k).
inline void hit_disc(const VisibilityMap& vm, const Ray& r, uint32_t k, float& best_t,
                     int64_t& best_k) {
    const Vec3 c = vm.points().positions[k], n = vm.points().normals[k];
    const float den = dot(r.d, n);
    if (std::fabs(den) < 1e-8f) return;
    const float t = dot(c - r.o, n) / den;
    if (!(t > 0) || t >= best_t) return;
    const Vec3 off = r.o + r.d * t - c;
    const float rad = vm.points().radii[k] * r.scale;
    if (length2(off) > rad * rad) return;
    best_t = t;
    best_k = k;
}

// Entry distance of the ray into box b grown by g, or +inf when it misses (or enters beyond
// t_max).
inline float box_entry(const Ray& r, const Box& b, float g, float t_max) {
    float t0 = 0, t1 = t_max;
    const float lo[3] = {b.lo.x - g, b.lo.y - g, b.lo.z - g};
    const float hi[3] = {b.hi.x + g, b.hi.y + g, b.hi.z + g};
    const float o[3] = {r.o.x, r.o.y, r.o.z}, inv[3] = {r.inv.x, r.inv.y, r.inv.z};
    for (int a = 0; a < 3; ++a) {
        float ta = (lo[a] - o[a]) * inv[a], tb = (hi[a] - o[a]) * inv[a];
        if (std::isnan(ta) || std::isnan(tb)) {  // zero direction and origin on a slab plane
            if (o[a] < lo[a] || o[a] > hi[a]) return INFINITY;
            continue;
        }
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
        if (t0 > t1) return INFINITY;
    }
    return t0;
}

double distance2(Vec3 a, Vec3 b) {
    const double x = double(a.x) - b.x, y = double(a.y) - b.y, z = double(a.z) - b.z;
    return x * x + y * y + z * z;
}

RayHit result(const VisibilityMap& vm, float t, int64_t k) {
    RayHit h;
    if (k < 0) return h;
    h.hit = true;
    h.id = vm.order()[size_t(k)];
    h.distance = float(t * vm.octree().scale());  // the octree's frame -> input units
    return h;
}

}  // namespace

uint32_t nearest_point(const PointSet& points, Vec3 pos) {
    if (points.size() == 0) throw Error("nearest point: the point set is empty");
    if (!is_finite(pos)) throw Error("nearest point: the position must be finite");
    uint32_t best = 0;
    double best_d = INFINITY;  // in double: squared distances of large coordinates overflow floats
    for (size_t i = 0; i < points.size(); ++i) {
        const double d = distance2(points.positions[i], pos);
        if (d < best_d) best_d = d, best = uint32_t(i);
    }
    return best;
}

uint32_t nearest_point(const VisibilityMap& vm, Vec3 pos) {
    if (vm.points().size() == 0) throw Error("nearest point: the V-map has no points");
    if (!is_finite(pos)) throw Error("nearest point: the position must be finite");
    pos = vm.octree().to_local(pos);
    uint32_t best = 0;
    double best_d = INFINITY;
    for (size_t k = 0; k < vm.points().size(); ++k) {
        const double d = distance2(vm.points().positions[k], pos);
        const uint32_t id = vm.order()[k];
        if (d < best_d || (d == best_d && id < best)) best_d = d, best = id;
    }
    return best;
}

uint64_t visible_count(const VisibilityMap& vm, uint32_t i) {
    if (i >= vm.points().size())
        throw Error(fmt::format("query: point id {} out of range (the V-map has {} points)", i,
                                vm.points().size()));
    const Octree& t = vm.octree();
    uint64_t count = 0;
    for (int32_t A = t.leaf_node()[t.leaf_of_point(vm.inverse()[i])]; A >= 0; A = t.parent()[A])
        for (int32_t B : vm.links(A)) count += t.point_end()[B] - t.point_begin()[B];
    return count;
}

RayHit shoot_ray(const VisibilityMap& vm, uint32_t from, Vec3 dir, RayStats* stats,
                 float splat_scale) {
    check(vm, from, dir, splat_scale);
    const Ray r = make_ray(vm, from, dir, splat_scale);
    const Octree& t = vm.octree();
    // Node boxes bound points and leaf discs, not every point's splat: grow them by the largest
    // splat radius so that no disc pokes out of its node's box.
    const float grow =
        *std::max_element(vm.points().radii.begin(), vm.points().radii.end()) * splat_scale;
    float best_t = INFINITY;
    int64_t best_k = -1;
    RayStats st;
    for (int32_t A = t.leaf_node()[t.leaf_of_point(vm.inverse()[from])]; A >= 0; A = t.parent()[A]) {
        for (int32_t B : vm.links(A)) {
            // Stackless preorder walk of B's subtree: skip a subtree whose box the ray misses or
            // enters beyond the best hit so far.
            for (int32_t m = B; m < t.skip()[B];) {
                ++st.node_tests;
                if (box_entry(r, t.boxes()[m], grow, best_t) == INFINITY) {
                    m = t.skip()[m];
                    continue;
                }
                if (t.is_leaf(m)) {
                    for (uint32_t k = t.point_begin()[m]; k < t.point_end()[m]; ++k) {
                        ++st.disc_tests;
                        hit_disc(vm, r, k, best_t, best_k);
                    }
                }
                ++m;
            }
        }
    }
    if (stats) {
        stats->node_tests += st.node_tests;
        stats->disc_tests += st.disc_tests;
    }
    return result(vm, best_t, best_k);
}

RayHit shoot_ray_brute(const VisibilityMap& vm, uint32_t from, Vec3 dir, bool visible_only,
                       float splat_scale) {
    check(vm, from, dir, splat_scale);
    const Ray r = make_ray(vm, from, dir, splat_scale);
    float best_t = INFINITY;
    int64_t best_k = -1;
    if (visible_only) {
        for (uint32_t id : vm.visible_set(from)) hit_disc(vm, r, vm.inverse()[id], best_t, best_k);
    } else {
        const int32_t node = vm.octree().leaf_node()[vm.octree().leaf_of_point(vm.inverse()[from])];
        for (uint32_t k = 0; k < vm.points().size(); ++k)
            if (k < vm.octree().point_begin()[node] || k >= vm.octree().point_end()[node])
                hit_disc(vm, r, k, best_t, best_k);
    }
    return result(vm, best_t, best_k);
}

}  // namespace vmap
