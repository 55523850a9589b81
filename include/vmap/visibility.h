// Parameters of the leaf-pair visibility predicate (paper §5; docs/design.md "Leaf-pair visibility").
#pragma once

#include <cstdint>
#include <string>

namespace vmap {

struct VisibilityParams {
    static constexpr int kKLimit = 1000;       // K in 1..kKLimit
    static constexpr float kEpsLimit = 0.5f;   // eps in [0, kEpsLimit)
    static constexpr float kTolLimit = 1.0f;   // facing_tol, parallel_tol in [0, kTolLimit)
    static constexpr float kEndWindowLimit = 100.0f;  // end_window in [0, kEndWindowLimit]
    static constexpr float kCoreLimit = 1.0f;         // core in [0, kCoreLimit]
    int K = 2;                   // actual occluders that make a pair invisible (>= 1)
    float eps = 0.01f;           // an occluder's plane must cut the segment at t in (eps, 1-eps)
    float facing_tol = 0.001f;   // facing: n_a . d > facing_tol |d| (a rounding guard)
    float parallel_tol = 1e-3f;  // a plane with |n . d| <= parallel_tol |d| is parallel to pq
    // An occluder counts only when its plane is cut farther than end_window x Delta_end from the
    // nearer end, Delta_end that end's disc radius: a window at each end in the ends' own
    // scale, beside eps's share of the length (docs/gi.md "The end window"). 0: none.
    float end_window = 0.f;
    // A scan's surface noise: a leaf whose plane an end lies behind by less than this (in the
    // input's units), with its normal within 37 degrees of that end's, is a bump of the end's
    // own rough sheet, not an occluder (exits_at_an_end in src/visibility/leaf_pair.h; docs/
    // design.md "Noisy scans"). `vmap build` sets it from the cloud's measured noise
    // (estimate_surface_noise in vmap/normals.h); samples of a scene lie on their surfaces: 0.
    float roughness = 0.f;
    // A crossing within core x Delta of an occluder leaf's centroid (the inner part of its disc,
    // about the sample's own share of the surface) counts as K occluders: one sure hit hides
    // (occluder_weight in src/visibility/leaf_pair.h; docs/validation.md "Sure hits: the discs'
    // cores"). 0: every crossing counts one. Not on a rough sheet (roughness > 0: a sample off
    // its surface is no surer at its centre) nor with K 1. Maps before file version 8 have 0.
    float core = kDefaultCore;
    static constexpr float kDefaultCore = 0.5f;

    // Throws vmap::Error naming `source` and the field for a value out of range: K 1..1000,
    // eps [0, 0.5), facing_tol and parallel_tol [0, 1), end_window [0, 100], roughness finite
    // and >= 0, core [0, 1].
    void check(const std::string& source) const;
};

// The parameters as the predicate reads them in an octree's frame (world = local x scale,
// Octree::scale()): the roughness is a length, the rest are ratios and counts. The scale is a
// power of two, so the division is exact.
inline VisibilityParams in_octree_frame(VisibilityParams vp, double scale) {
    vp.roughness = float(double(vp.roughness) / scale);
    return vp;
}

// Work counted while resolving leaf pairs.
struct WorkCounters {
    uint64_t pairs = 0;         // unordered leaf pairs resolved
    uint64_t facing_pairs = 0;  // pairs that passed the facing test (needed a traversal)
    uint64_t visible_pairs = 0;
    uint64_t node_tests = 0;      // segment-sphere tests
    uint64_t occluder_tests = 0;  // tangent-plane tests on potential occluders
    uint64_t cells_stepped = 0;   // grid cells visited (the grid walk only)

    WorkCounters& operator+=(const WorkCounters& o) {
        pairs += o.pairs;
        facing_pairs += o.facing_pairs;
        visible_pairs += o.visible_pairs;
        node_tests += o.node_tests;
        occluder_tests += o.occluder_tests;
        cells_stepped += o.cells_stepped;
        return *this;
    }
};

}  // namespace vmap
