// What the visibility predicate walks, packed for the GPU, and the library's write access to an
// Octree (the builder, the .vmap reader and tests fill one; users only read it).
#pragma once

#include <cstdint>
#include <type_traits>
#include <utility>
#include <vector>

#include "vmap/octree.h"

namespace vmap {

// A node as the predicate walks it, packed in 32 bytes (two 16-byte loads on the GPU): its
// content box, the end of its subtree, its leaf index (-1 for internal nodes).
struct alignas(16) WalkNode {
    Vec3 lo;
    int32_t skip = 0;
    Vec3 hi;
    int32_t leaf = -1;
};

// What the visibility predicate needs of a leaf, packed in 32 bytes (one load on the GPU).
struct alignas(16) LeafDisc {
    Vec3 centroid;    // mean of its points
    float delta = 0;  // occluder disc radius: farthest point from the centroid, >= splat radius
    Vec3 normal;      // normalised mean of its points' normals (zero when flagged)
    uint32_t flags = 0;
};
inline constexpr uint32_t kLeafNormalDegenerate = 1u;  // normals cancel out: no usable plane

// `points_box` grown to hold the occluder disc of `d` (centroid, normal, Delta): a disc with
// unit normal n reaches Delta sqrt(1 - n_i^2) from its centre along axis i (the full Delta when
// the normal is flagged, i.e. zero).
Box grow_by_disc(Box points_box, const LeafDisc& d);
// The smallest box holding both.
inline Box merge(const Box& a, const Box& b) {
    return {{a.lo.x < b.lo.x ? a.lo.x : b.lo.x, a.lo.y < b.lo.y ? a.lo.y : b.lo.y,
             a.lo.z < b.lo.z ? a.lo.z : b.lo.z},
            {a.hi.x > b.hi.x ? a.hi.x : b.hi.x, a.hi.y > b.hi.y ? a.hi.y : b.hi.y,
             a.hi.z > b.hi.z ? a.hi.z : b.hi.z}};
}

// A plain, non-owning view of the arrays the predicate traverses; cheap to copy into a kernel.
struct OctreeView {
    const WalkNode* walk = nullptr;    // per node: box, end of subtree, leaf index (preorder)
    const LeafDisc* leaves = nullptr;  // per leaf
    int32_t num_nodes = 0;
    int32_t num_leaves = 0;
};

namespace detail {

struct OctreeAccess {
    // Every array of the octree, writable (field names as Octree's accessors).
    static auto& data(Octree& t) { return t.d_; }
    static const std::vector<LeafDisc>& leaves(const Octree& t) { return t.d_.leaves; }
    static const std::vector<WalkNode>& walk(const Octree& t) { return t.d_.walk; }
    // Derives the packed walk array (from boxes, skip and node_leaf) and the leaf of every
    // point (from the leaves' point ranges); build and load call it.
    static void pack_walk(Octree& t);
};

// The writable arrays of an Octree (Octree::Data, named through the accessor).
using OctreeData = std::remove_reference_t<decltype(OctreeAccess::data(std::declval<Octree&>()))>;

// The slack every content box grows by: the float walk tests err by a few ulps of the
// coordinates' magnitude, so boxes grow by 8 ulps of (largest |coordinate| + root size).
float content_slack(double maxabs, float root_size);

// The Delta rule and the content boxes, in one place (the builder, and validation's variants
// of the rule): every leaf's Delta becomes scale * max(farthest point from the centroid,
// floor * its largest splat radius) (octree/delta_rule.h: the builder's scale 1 and floor
// kDeltaSplatFloor); a leaf's box holds its points and its occluder disc, grown by `slack`, an
// internal node's the union of its children's; then the walk array is packed again. Leaf
// centroids and normals must be set; `pts` in octree order.
void apply_delta_rule(Octree& t, const PointSet& pts, float scale, float floor, float slack);

}  // namespace detail

// The leaf records and the view the predicate walks.
inline const std::vector<LeafDisc>& leaf_discs(const Octree& t) {
    return detail::OctreeAccess::leaves(t);
}
inline const std::vector<WalkNode>& walk_nodes(const Octree& t) {
    return detail::OctreeAccess::walk(t);
}
inline OctreeView octree_view(const Octree& t) {
    return OctreeView{walk_nodes(t).data(), leaf_discs(t).data(), t.num_nodes(), t.num_leaves()};
}

}  // namespace vmap
