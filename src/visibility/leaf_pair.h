// The leaf-pair visibility predicate (paper §5; docs/design.md "Leaf-pair visibility"), written once
// for the CPU and the CUDA backends. Plain inline functions on plain structs: no allocation, no
// exceptions, no virtual calls. The build turns off FMA contraction on both sides, so the same
// inputs give the same bits on the host and on the device.
#pragma once

#include "octree/records.h"
#include "vmap/octree.h"
#include "vmap/vec.h"
#include "vmap/visibility.h"

namespace vmap::detail {

// Does segment p + t d, t in [0, 1], come within r of c? (paper §5.2: only the Boolean.)
// Closest point of the segment to c is at t* = clamp((c - p) . d / |d|^2, 0, 1). Spheres carry a
// conservative slack for rounding (octree.cpp), so a float evaluation never drops a true hit.
VMAP_HD bool segment_meets_sphere(Vec3 p, Vec3 d, float dd, Sphere s) {
    const Vec3 v = s.center - p;
    float t = dot(v, d);
    if (t <= 0.f) return length2(v) <= s.radius * s.radius;
    if (t >= dd) return length2(v - d) <= s.radius * s.radius;
    t = t / dd;
    const Vec3 w = v - d * t;
    return length2(w) <= s.radius * s.radius;
}

// Plain min/max: the libm fminf/fmaxf are calls on the host (NaN rules); no NaN reaches these.
VMAP_HD float min_f(float a, float b) { return a < b ? a : b; }
VMAP_HD float max_f(float a, float b) { return a > b ? a : b; }

// A segment p + t d, t in [t0, t1], prepared for slab tests against boxes.
struct SlabRay {
    Vec3 p, inv;  // inv = 1 / d per axis (infinite for a zero component)
    Vec3 d;
    float t0, t1;
};
VMAP_HD SlabRay slab_ray(Vec3 p, Vec3 d, float t0, float t1) {
    return SlabRay{p, Vec3{1.f / d.x, 1.f / d.y, 1.f / d.z}, d, t0, t1};
}
// Does the segment meet the box grown by g? Boxes carry a rounding slack (octree.cpp). A
// direction component too small to invert is handled apart, so every product is finite.
VMAP_HD bool slab_meets_box(const SlabRay& r, const Box& b, float g) {
    float tmin = r.t0, tmax = r.t1;
    const float lo[3] = {b.lo.x - g, b.lo.y - g, b.lo.z - g};
    const float hi[3] = {b.hi.x + g, b.hi.y + g, b.hi.z + g};
    const float p[3] = {r.p.x, r.p.y, r.p.z}, inv[3] = {r.inv.x, r.inv.y, r.inv.z};
    const float d[3] = {r.d.x, r.d.y, r.d.z};
#if defined(__CUDACC__)
#pragma unroll
#endif
    for (int i = 0; i < 3; ++i) {
        if (fabsf(d[i]) < 1e-30f) {
            if (p[i] < lo[i] || p[i] > hi[i]) return false;
            continue;
        }
        const float ta = (lo[i] - p[i]) * inv[i], tb = (hi[i] - p[i]) * inv[i];
        tmin = max_f(tmin, min_f(ta, tb));
        tmax = min_f(tmax, max_f(ta, tb));
    }
    return tmin <= tmax;
}

// slab_meets_box for a segment whose direction has no component under 1e-30 in magnitude, with
// g = 0: the same float operations in the same order without the per-axis test for such a
// component, so the same answer (visibility_test's Slab checks it on each backend). The GPU's
// packet walk uses it where no lane of a warp needs the test (cuda_backend.cu, walk_packet).
VMAP_HD bool slab_meets_box_regular(const SlabRay& r, const Box& b) {
    float tmin = r.t0, tmax = r.t1;
    float ta = (b.lo.x - r.p.x) * r.inv.x, tb = (b.hi.x - r.p.x) * r.inv.x;
    tmin = max_f(tmin, min_f(ta, tb));
    tmax = min_f(tmax, max_f(ta, tb));
    ta = (b.lo.y - r.p.y) * r.inv.y, tb = (b.hi.y - r.p.y) * r.inv.y;
    tmin = max_f(tmin, min_f(ta, tb));
    tmax = min_f(tmax, max_f(ta, tb));
    ta = (b.lo.z - r.p.z) * r.inv.z, tb = (b.hi.z - r.p.z) * r.inv.z;
    tmin = max_f(tmin, min_f(ta, tb));
    tmax = min_f(tmax, max_f(ta, tb));
    return tmin <= tmax;
}
// Does any component of d lie under 1e-30 in magnitude (slab_meets_box's special case)?
VMAP_HD bool has_tiny_component(Vec3 d) {
    return fabsf(d.x) < 1e-30f || fabsf(d.y) < 1e-30f || fabsf(d.z) < 1e-30f;
}

// Whether crossings in the discs' cores count K (VisibilityParams::core): not on a rough sheet
// (roughness > 0, a scan's noise), where a sample lies off its surface and its disc's centre
// is no surer than its rim (docs/validation.md "Sure hits: the discs' cores"), and not with K 1,
// where every crossing already does.
VMAP_HD bool cores_on(const VisibilityParams& vp) {
    return vp.core > 0.f && vp.roughness == 0.f && vp.K > 1;
}
// The radius of leaf x's core: a crossing nearer its centre than this counts as K occluders
// (0 where cores_on is false: none is nearer). The walks on every backend square this float (no
// contraction) and compare with <, so they agree.
VMAP_HD float core_radius(const LeafDisc& x, const VisibilityParams& vp) {
    return cores_on(vp) ? vp.core * x.delta : 0.f;
}

// Is leaf x an actual occluder of segment p + t d (paper §5.1, Fig. 7)?
// The crossing's t goes to *t_out when given; *core_out says whether it lies in x's core
// (core_radius), when given and x is an actual occluder.
VMAP_HD bool is_actual_occluder(Vec3 p, Vec3 d, float len, const LeafDisc& x,
                                const VisibilityParams& vp, float* t_out = nullptr,
                                bool* core_out = nullptr) {
    const float rc = core_radius(x, vp);
    if (x.flags & kLeafNormalDegenerate) {
        // No tangent plane: the disc degenerates to its sphere; occludes if the segment's
        // interior passes within Delta of the centroid.
        const float dd = len * len;
        const Vec3 v = x.centroid - p;
        const float t = dot(v, d) / dd;
        if (t_out) *t_out = t;
        if (!(t > vp.eps && t < 1.f - vp.eps)) return false;
        const float r2 = length2(v - d * t);
        if (core_out) *core_out = r2 < rc * rc;
        return r2 <= x.delta * x.delta;
    }
    const float nd = dot(x.normal, d);
    // Tangent plane (nearly) parallel to pq: no proper crossing (x5 in Fig. 7).
    if (fabsf(nd) <= vp.parallel_tol * len) return false;
    const float t = dot(x.normal, x.centroid - p) / nd;
    if (t_out) *t_out = t;
    // The plane is cut outside the segment's interior (x1 in Fig. 7).
    if (!(t > vp.eps && t < 1.f - vp.eps)) return false;
    // The crossing lies farther than Delta from the centroid (x4 in Fig. 7).
    const Vec3 hit = p + d * t;
    const float r2 = length2(hit - x.centroid);
    if (core_out) *core_out = r2 < rc * rc;
    return r2 <= x.delta * x.delta;
}

// Facing test: n_a . d > tol |d| and n_b . (-d) > tol |d|. A leaf whose normals cancel out has
// no side, so it faces everything.
VMAP_HD bool leaves_face(const LeafDisc& a, const LeafDisc& b, Vec3 d, float len,
                         const VisibilityParams& vp) {
    const float lim = vp.facing_tol * len;
    const bool fa = (a.flags & kLeafNormalDegenerate) || dot(a.normal, d) > lim;
    const bool fb = (b.flags & kLeafNormalDegenerate) || -dot(b.normal, d) > lim;
    return fa && fb;
}

// Read-only loads of the walk array: through the non-coherent cache, 16 bytes at a time, on
// the device; a plain copy on the host.
VMAP_HD WalkNode load_walk(const WalkNode* w) {
#if defined(__CUDA_ARCH__)
    const float4 a = __ldg(reinterpret_cast<const float4*>(w));
    const float4 b = __ldg(reinterpret_cast<const float4*>(w) + 1);
    WalkNode r;
    r.lo = {a.x, a.y, a.z};
    r.skip = __float_as_int(a.w);
    r.hi = {b.x, b.y, b.z};
    r.leaf = __float_as_int(b.w);
    return r;
#else
    return *w;
#endif
}

// The part of a leaf pair's walk that does not depend on the tree: the segment pq (p the
// centroid of the first leaf), the facing test, and the sub-segment the walk tests boxes with.
// An actual occluder's crossing p + t d has eps < t < 1 - eps and lies on its disc, inside the
// node's content box; so only the part of pq with t in [t0, t1] (a little wider than
// (eps, 1 - eps), for rounding, and narrowed by the end windows) needs to meet the boxes. This
// skips the dense surface around both ends. DEVIATION from paper §5.2: the walk prunes with
// each node's tight box of its points and discs, not its sphere. Both bound every occluder disc, so the same occluders are found
// (tests/visibility_test.cpp checks against no pruning at all); the box of a planar wall patch
// is flat, its sphere is not, and after the box test the sphere test rejected almost nothing
// (docs/gpu-notes.md).
struct PairSegment {
    Vec3 p, d;
    float len;
    bool faces;  // a direction to see along (len > 0) and the two leaves face each other
    SlabRay ray;
    // The ends' tangent planes (in_front_of_ends): b's centroid q, the normals, and whether
    // each end has a plane at all (a flagged leaf has none); the ends' disc radii
    // (exits_at_an_end) and their end windows, end_window x Delta (beyond_the_end_windows).
    Vec3 q, na, nb;
    bool plane_a, plane_b;
    float delta_a, delta_b;
    float window_a, window_b;
    float roughness;  // VisibilityParams::roughness, in the octree's frame (exits_at_an_end)
};
// The facing part alone (the CPU's packet walk sets up only the pairs that face).
VMAP_HD bool pair_faces(const LeafDisc& la, const LeafDisc& lb, const VisibilityParams& vp) {
    const Vec3 d = lb.centroid - la.centroid;
    const float len = sqrtf(length2(d));
    // Coincident centroids: no direction to see along.
    return len > 0.f && leaves_face(la, lb, d, len, vp);
}
// `faces`: pair_faces(la, lb, vp), where the caller has it already.
VMAP_HD PairSegment pair_segment(const LeafDisc& la, const LeafDisc& lb,
                                 const VisibilityParams& vp, bool faces) {
    PairSegment s;
    s.p = la.centroid;
    s.d = lb.centroid - s.p;
    s.len = sqrtf(length2(s.d));
    s.faces = faces;
    s.window_a = vp.end_window * la.delta;
    s.window_b = vp.end_window * lb.delta;
    // The walk's sub-segment: past eps, and past the end windows (beyond_the_end_windows),
    // each of which applies on its own half of the segment only, so neither reaches past 0.5.
    // With no windows (or no length) this is (eps, 1 - eps), the same floats as ever.
    float ta = vp.eps, tb = vp.eps;
    if (s.len > 0.f) {
        ta = min_f(max_f(ta, s.window_a / s.len), 0.5f);
        tb = min_f(max_f(tb, s.window_b / s.len), 0.5f);
    }
    s.ray = slab_ray(s.p, s.d, ta * 0.999f, 1.f - tb * 0.999f);
    s.q = lb.centroid;
    s.na = la.normal;
    s.nb = lb.normal;
    s.plane_a = !(la.flags & kLeafNormalDegenerate);
    s.plane_b = !(lb.flags & kLeafNormalDegenerate);
    s.delta_a = la.delta;
    s.delta_b = lb.delta;
    s.roughness = vp.roughness;
    return s;
}
VMAP_HD PairSegment pair_segment(const LeafDisc& la, const LeafDisc& lb,
                                 const VisibilityParams& vp) {
    return pair_segment(la, lb, vp, pair_faces(la, lb, vp));
}

// Can leaf x stand between the ends at all? The segment lies in front of the tangent plane of
// each end leaf (the facing test), so a surface wholly behind one of those planes cannot cut
// it. A leaf whose centroid lies behind an end's plane is, in practice, a neighbour on a
// surface curving away from that end: on a convex patch the tangent disc of radius Delta pokes
// out past the surface it stands for, into the segment's first or last stretch, and it used to
// hide half the pairs that leave a curved object at a shallow angle (docs/validation.md,
// "Where people look"). The rule needs no scale: it compares centroids with planes. An end
// without a usable normal (flagged) has no plane and culls nothing.
VMAP_HD bool in_front_of_ends(const PairSegment& s, const LeafDisc& x) {
    const bool fa = !s.plane_a || dot(s.na, x.centroid - s.p) > 0.f;
    const bool fb = !s.plane_b || dot(s.nb, x.centroid - s.q) > 0.f;
    return fa && fb;
}

// How far along the segment the crossing at t lies from the nearer end (t < 0.5: a).
VMAP_HD float from_nearer_end(const PairSegment& s, float t) {
    return (t < 0.5f ? t : 1.f - t) * s.len;
}

// Near an end, the mirror of in_front_of_ends (docs/validation.md "The predicate near the
// ends"). A leaf x whose plane is cut within half the end's own disc radius of that end
// (t |d| < Delta_end / 2, t measured from the nearer end), with that end's centroid behind x's
// plane, is crossed from its back to its front: the segment comes out of a surface it never
// went into, right where it leaves the end. The end lies on the outside of its own surface and
// the segment leaves into the open (the facing test), so such an x is the end's own surface:
// a neighbour on a crease or a curve whose centroid is not quite behind the end's plane, its
// disc of 2.5 splat radii standing for more surface than it has. Farther out an exit is a real
// one (the far wall of a closed object, which K 2 counts with the near one), so the rule stays
// within half a disc. A surface that faces the end (an object a few millimetres in front of a
// wall, seen from the wall) has the end in front of its plane and still counts. The rule only
// drops occluders the eps window lets count, never adds one: every node-level proof of
// node_pair.h (an upper bound on the occluders) still holds, and the walk's sub-segment is
// unchanged. A flagged x or end has no plane to be behind and is not dropped.
// A rough sheet (a scan's noise, VisibilityParams::roughness): an end lying behind x's plane by
// less than the roughness, with x's normal within 37 degrees of the end's, is the same kind of
// exit at any distance along the segment: x is a neighbour on the end's own sheet that the noise
// raised a little above the end, and a segment leaving at a shallow angle passes under its disc
// far beyond half a disc (at a step h and an angle a to the sheet, h / sin a from the end). Off
// the sheet's direction (the far wall of an object, a crease's other face) the rule leaves x
// counting; a part thinner than the roughness lying flat on the end's sheet (a plate on a floor)
// is taken for the sheet's noise. With roughness 0 this is the rule above, bit for bit.
inline constexpr float kSameSheetCos = 0.8f;  // 37 degrees, as the normals' same-sheet tests
VMAP_HD bool exits_at_an_end(const PairSegment& s, const LeafDisc& x, float t) {
    if (x.flags & kLeafNormalDegenerate) return false;
    const bool near_a = t < 0.5f;
    if (!(near_a ? s.plane_a : s.plane_b)) return false;
    const float from_end = from_nearer_end(s, t);
    const float back = dot(x.normal, (near_a ? s.p : s.q) - x.centroid);
    if (!(back < 0.f)) return false;
    return from_end < 0.5f * (near_a ? s.delta_a : s.delta_b) ||
           (-back < s.roughness && dot(x.normal, near_a ? s.na : s.nb) > kSameSheetCos);
}

// The end windows (VisibilityParams::end_window, docs/gi.md "The end window"): a crossing at t
// counts only when it lies at least end_window x Delta_end from the nearer end. The eps window
// is a share of the segment's length, so it is wide at the far end of a long segment (on a
// segment from a model to a ceiling light, eps 0.05 is centimetres: the model's own overhangs
// within it cast no shadow) and a hair wide on a short one, where the discs of the end's
// neighbours, on a curve, cut the segment leaving it (the near pairs the GI weighs most). The
// neighbours that do that lie within a disc or two of the end, so a window in units of the end's
// own disc takes them out at any length and at any density, and no more. Like the rules above it
// only drops occluders that the eps window and the disc test let count (node_pair.h (e5)).
VMAP_HD bool beyond_the_end_windows(const PairSegment& s, float t) {
    return !(from_nearer_end(s, t) < (t < 0.5f ? s.window_a : s.window_b));
}

// How many of the K occluders of the pair's segment leaf x makes: none unless it is an actual
// occluder (Fig. 7) that stands in front of both ends, is not crossed from behind right at an
// end, and is cut outside the end windows; K when it is crossed in its core (core_radius);
// else one.
// The core (docs/validation.md "Sure hits: the discs' cores"): Delta reaches past the sample's
// own share of the surface (the disc floor widens it to close the gaps between samples, and a
// disc stands out past a curved or thin part's silhouette), which is why one crossing is not
// enough (K 2). The inner part of the disc, about the sample's own splat, is surface: a segment
// through it is hidden, whatever else it crosses.
VMAP_HD int occluder_weight(const PairSegment& s, const LeafDisc& x, const VisibilityParams& vp) {
    float t = 0.f;
    bool core = false;
    if (!(in_front_of_ends(s, x) && is_actual_occluder(s.p, s.d, s.len, x, vp, &t, &core) &&
          !exits_at_an_end(s, x, t) && beyond_the_end_windows(s, t)))
        return 0;
    return core ? vp.K : 1;
}
VMAP_HD bool counts_as_occluder(const PairSegment& s, const LeafDisc& x,
                                const VisibilityParams& vp) {
    return occluder_weight(s, x, vp) > 0;
}

// A node reached by the walk (its box meets the segment): when it is a leaf other than a and b,
// tests it as an occluder. True when that makes the K-th actual occluder (the pair is hidden).
template <bool kCount, class Counters>
VMAP_HD bool occluder_reached(const OctreeView& t, const PairSegment& s, int32_t leaf, int32_t a,
                              int32_t b, const VisibilityParams& vp, int& occluders, Counters* wc) {
    if (leaf < 0 || leaf == a || leaf == b) return false;
    if (kCount) wc->occluder_tests++;
    occluders += occluder_weight(s, t.leaves[leaf], vp);
    return occluders >= vp.K;
}

// Visibility of leaves a != b. Potential occluders are the leaves reached by descending from
// the root into every node whose bounds meet segment pq (stackless walk over the preorder
// skip links), other than a and b; K actual occluders make the pair invisible (any-hit: stop at
// the K-th). kCount selects whether work is counted into `wc`. Counters is WorkCounters, or any
// struct with the same fields (the GPU keeps 32-bit ones in registers). The GPU's packet walk
// (cuda_backend.cu) is this walk for 32 pairs at once, from the same pieces.
template <bool kCount, class Counters = WorkCounters>
VMAP_HD bool leaf_pair_visible(const OctreeView& t, int32_t a, int32_t b,
                               const VisibilityParams& vp, Counters* wc) {
    const PairSegment s = pair_segment(t.leaves[a], t.leaves[b], vp);
    if (!s.faces) return false;
    if (kCount) wc->facing_pairs++;
    int occluders = 0;
    int32_t n = 0;
    while (n < t.num_nodes) {
        if (kCount) wc->node_tests++;
        const WalkNode w = load_walk(t.walk + n);
        if (!slab_meets_box(s.ray, Box{w.lo, w.hi}, 0.f)) {
            n = w.skip;
            continue;
        }
        if (occluder_reached<kCount>(t, s, w.leaf, a, b, vp, occluders, wc)) return false;
        ++n;  // first child, or (for a leaf, whose skip is n + 1) the next subtree
    }
    return true;
}

}  // namespace vmap::detail
