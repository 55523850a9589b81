// Queries beyond point pairs and visible sets: points by position and ray shooting.
//
// Ray shooting (paper §6) from a surface point i: the first point splat (a disc: centre =
// position, normal, radius = splat radius x splat_scale) hit by the ray i + t dir, t > 0. The
// scale defaults to 2: randomly placed discs of the plain splat radius cover only about 1 - 1/e
// of a surface, so a third of all rays would slip through a wall; at 2 about 98% are caught. The
// V-map prunes it: only points in the subtrees linked to i's leaf or one of its ancestors (the
// visible set) can be hit, so just those subtrees are walked, with a ray-box test on each node's
// tight box grown by the largest splat radius. Points in i's own leaf are never reported (the V-map
// says nothing about them), and discs are two-sided.
//
// Relation to an exhaustive search: shoot_ray returns exactly the nearest hit among the visible
// set (shoot_ray_brute with visible_only = true). An exhaustive search over all points (but i's
// leaf) can only find a nearer hit on a point the V-map calls hidden from i; so when the
// exhaustive hit is in the visible set, both agree.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "vmap/visibility_map.h"

namespace vmap {

// The input id of the point nearest `pos`, in input units (linear scan; ties to the lowest id).
// Throws vmap::Error for an empty set or a non-finite position.
uint32_t nearest_point(const PointSet& points, Vec3 pos);
uint32_t nearest_point(const VisibilityMap& vm, Vec3 pos);

// How many points vm.visible_set(i) holds, without listing them: O(links of i's leaf and its
// ancestors). Throws vmap::Error for an id out of range.
uint64_t visible_count(const VisibilityMap& vm, uint32_t i);

struct RayHit {
    bool hit = false;
    uint32_t id = 0;     // input id of the point hit
    float distance = 0;  // along the (normalised) ray, input units
};

struct RayStats {
    uint64_t node_tests = 0;  // ray-box tests
    uint64_t disc_tests = 0;  // ray-disc tests
};

// The first splat hit from input point `from` along `dir` (any non-zero length), pruned by the
// V-map. Throws vmap::Error for an id out of range, a zero or non-finite direction, a scale
// outside (0, 100], or a V-map whose points carry no normals or radii.
RayHit shoot_ray(const VisibilityMap& vm, uint32_t from, Vec3 dir, RayStats* stats = nullptr,
                 float splat_scale = 2.f);

// The same by testing every point: all points outside `from`'s leaf, or only those of
// vm.visible_set(from) when visible_only. For tests and benchmarks.
RayHit shoot_ray_brute(const VisibilityMap& vm, uint32_t from, Vec3 dir, bool visible_only,
                       float splat_scale = 2.f);

}  // namespace vmap

namespace vmap {

// Many point pairs at once, on all cores: `pairs` holds input ids (i0, j0, i1, j1, ...), and
// out[k] becomes the PairVisibility of pair k as a byte (0 hidden, 1 visible, 2 same leaf).
// Throws vmap::Error naming the first pair with an id out of range, before answering any, or
// when out.size() != pairs.size() / 2.
void query_pairs(const VisibilityMap& vm, std::span<const uint32_t> pairs, std::span<uint8_t> out);

// The visible sets of several points, as one CSR: the set of ids[k] is
// targets[offsets[k] .. offsets[k + 1]), sorted (VisibilityMap::visible_set). Throws vmap::Error
// for an id out of range.
struct VisibleSets {
    std::vector<uint64_t> offsets;
    std::vector<uint32_t> targets;
};
VisibleSets visible_sets(const VisibilityMap& vm, std::span<const uint32_t> ids);

}  // namespace vmap
