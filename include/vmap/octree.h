// The adaptive octree over a point set (DESIGN.md "Octree").
//
// Nodes are stored in depth-first preorder: a node's first child (if any) is the next node, and
// skip[n] is the index just past its subtree, so "m is in the subtree of n" is
// n <= m < skip[n], and any subtree is one contiguous index range. Leaves are numbered in the
// same order, so the leaves under a node are the contiguous range [leaf_begin, leaf_end), and
// points are reordered so the points of a node are [point_begin, point_end).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "vmap/mesh.h"
#include "vmap/vec.h"

namespace vmap {

struct OctreeParams {
    int max_height = 9;   // deepest level a leaf may have (root = level 0); 1..21
    int leaf_points = 1;  // a node splits while it holds more points than this (and is not at
                          // max_height); >= 1
};

// A bounding sphere: centre and radius.
struct Sphere {
    Vec3 center;
    float radius = 0;
};

// An axis-aligned box: the tight bounds of a node's content (points and occluder discs).
struct Box {
    Vec3 lo, hi;
};

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

class Octree {
  public:
    // Builds the octree over `points` (which must have normals; radii optional) and permutes
    // `points` into octree order. `order[k]` is then the input index of the k-th point.
    // Throws vmap::Error for an empty cloud, non-finite coordinates or normals, zero normals,
    // or parameters out of range, naming `source`.
    static Octree build(PointSet& points, const OctreeParams& params, std::vector<uint32_t>& order,
                        const std::string& source = "points");
    // The same in a frame of the cloud's own size: first maps `points` (positions and splat
    // radii) to world / scale, with scale the power of two that brings the bounding cube's edge
    // into [0.5, 1), then builds. Squared distances then never overflow or underflow a float
    // whatever the input's unit, and since the map is a power of two it is exact: a cloud and
    // the same cloud times 2^k give bit-identical octrees apart from `scale`.
    static Octree build_in_unit_frame(PointSet& points, const OctreeParams& params,
                                      std::vector<uint32_t>& order,
                                      const std::string& source = "points");

    // Between the octree's frame and the input's units (world = local x scale), in double.
    Vec3 to_world(Vec3 local) const {
        return {float(local.x * scale), float(local.y * scale), float(local.z * scale)};
    }
    Vec3 to_local(Vec3 world) const {
        return {float(world.x / scale), float(world.y / scale), float(world.z / scale)};
    }

    OctreeView view() const;
    // Derives the packed walk array from boxes, skip and node_leaf (build and load call it).
    void pack_walk();

    int32_t num_nodes() const { return static_cast<int32_t>(skip.size()); }
    int32_t num_leaves() const { return static_cast<int32_t>(leaf_node.size()); }
    int height() const;  // deepest leaf level
    bool is_leaf(int32_t n) const { return node_leaf[n] >= 0; }

    // Children of n, in order (empty for a leaf).
    template <class F>
    void for_each_child(int32_t n, F&& f) const {
        for (int32_t c = n + 1; c < skip[n]; c = skip[c]) f(c);
    }

    // The leaf holding the point at octree position k (0 <= k < number of points).
    int32_t leaf_of_point(uint32_t k) const;

    // Per node (all indexed by node): the cell, the bounding sphere, structure, ranges.
    OctreeParams params;
    double scale = 1;  // input units per octree unit, a power of two (build_in_unit_frame)
    Vec3 root_min;     // corner of the root cube
    float root_size = 0;
    std::vector<Sphere> spheres;
    std::vector<Box> boxes;        // tight content bounds (points and discs), grown for rounding
    std::vector<WalkNode> walk;    // derived: boxes + skip + node_leaf, packed for the walk
    std::vector<float> half_size;  // half the cell edge
    std::vector<int32_t> skip;
    std::vector<int32_t> parent;  // -1 for the root
    std::vector<uint8_t> level;
    std::vector<int32_t> node_leaf;
    std::vector<uint32_t> point_begin, point_end;
    std::vector<int32_t> leaf_begin, leaf_end;

    // Per leaf.
    std::vector<int32_t> leaf_node;
    std::vector<LeafDisc> leaves;
    std::vector<float> leaf_splat;  // largest splat radius of its points
};

}  // namespace vmap
