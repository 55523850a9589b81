// The adaptive octree over a point set (paper §3; docs/design.md).
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
    static constexpr int kHeightLimit = 21;          // max_height in 1..kHeightLimit
    static constexpr int kLeafPointsLimit = 1000000;  // leaf_points in 1..kLeafPointsLimit
    int max_height = 9;   // deepest level a leaf may have (root = level 0)
    int leaf_points = 1;  // a node splits while it holds more points than this (and is not at
                          // max_height)
    // A leaf's occluder disc radius Delta is the distance from its centroid to its farthest
    // point, but never below delta_floor times its largest splat radius: discs wide enough to
    // close the gaps between samples. Independent uniform samples leave holes, so a point cloud
    // of them gets kDefaultDeltaFloor (2.25: docs/validation.md "5. The floor of independent
    // samples, re-measured" counts the scenes meeting the accuracy targets; 2.5 until then,
    // and in files before version 5); a scene sampled as blue noise has no holes wider than
    // about the spacing and gets kEvenDeltaFloor (scene_octree in vmap/scene.h; docs/
    // validation.md "Blue-noise samples"). In [0, kDeltaFloorLimit].
    static constexpr float kDefaultDeltaFloor = 2.25f;
    static constexpr float kEvenDeltaFloor = 2.0f;
    static constexpr float kDeltaFloorLimit = 10.f;
    float delta_floor = kDefaultDeltaFloor;

    // Throws vmap::Error naming `source` and the field for a value out of range.
    void check(const std::string& source) const;
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

// The records the visibility predicate walks (packed for the GPU; src/octree/records.h).
struct WalkNode;
struct LeafDisc;
namespace detail {
struct OctreeAccess;
}

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
        const double s = d_.scale;
        return {float(local.x * s), float(local.y * s), float(local.z * s)};
    }
    Vec3 to_local(Vec3 world) const {
        const double s = d_.scale;
        return {float(world.x / s), float(world.y / s), float(world.z / s)};
    }

    int32_t num_nodes() const { return static_cast<int32_t>(d_.skip.size()); }
    int32_t num_leaves() const { return static_cast<int32_t>(d_.leaf_node.size()); }
    int height() const;  // deepest leaf level
    bool is_leaf(int32_t n) const { return d_.node_leaf[n] >= 0; }

    // Children of n, in order (empty for a leaf).
    template <class F>
    void for_each_child(int32_t n, F&& f) const {
        for (int32_t c = n + 1; c < d_.skip[n]; c = d_.skip[c]) f(c);
    }

    // The leaf holding the point at octree position k (0 <= k < number of points). O(1).
    int32_t leaf_of_point(uint32_t k) const { return d_.point_leaf[k]; }

    const OctreeParams& params() const { return d_.params; }
    double scale() const { return d_.scale; }  // input units per octree unit, a power of two
    Vec3 root_min() const { return d_.root_min; }  // corner of the root cube
    float root_size() const { return d_.root_size; }
    // Per node (all indexed by node): the cell, the bounding sphere, structure, ranges.
    const std::vector<Sphere>& spheres() const { return d_.spheres; }
    // Tight content bounds (points and occluder discs), grown for rounding.
    const std::vector<Box>& boxes() const { return d_.boxes; }
    const std::vector<float>& half_size() const { return d_.half_size; }  // half the cell edge
    const std::vector<int32_t>& skip() const { return d_.skip; }  // end of the subtree
    const std::vector<int32_t>& parent() const { return d_.parent; }  // -1 for the root
    const std::vector<uint8_t>& level() const { return d_.level; }
    const std::vector<int32_t>& node_leaf() const { return d_.node_leaf; }  // -1: internal
    const std::vector<uint32_t>& point_begin() const { return d_.point_begin; }
    const std::vector<uint32_t>& point_end() const { return d_.point_end; }
    const std::vector<int32_t>& leaf_begin() const { return d_.leaf_begin; }
    const std::vector<int32_t>& leaf_end() const { return d_.leaf_end; }
    // Per leaf: its node, the largest splat radius of its points.
    const std::vector<int32_t>& leaf_node() const { return d_.leaf_node; }
    const std::vector<float>& leaf_splat() const { return d_.leaf_splat; }

    Octree();
    ~Octree();
    Octree(const Octree&);
    Octree(Octree&&) noexcept;
    Octree& operator=(const Octree&);
    Octree& operator=(Octree&&) noexcept;

  private:
    friend struct detail::OctreeAccess;  // the builder, the file reader and tests fill it
    struct Data {
        OctreeParams params;
        double scale = 1;
        Vec3 root_min;
        float root_size = 0;
        std::vector<Sphere> spheres;
        std::vector<Box> boxes;
        std::vector<WalkNode> walk;  // derived: boxes + skip + node_leaf, packed for the walk
        std::vector<float> half_size;
        std::vector<int32_t> skip;
        std::vector<int32_t> parent;
        std::vector<uint8_t> level;
        std::vector<int32_t> node_leaf;
        std::vector<uint32_t> point_begin, point_end;
        std::vector<int32_t> leaf_begin, leaf_end;
        std::vector<int32_t> leaf_node;
        std::vector<LeafDisc> leaves;  // what the predicate needs of each leaf
        std::vector<float> leaf_splat;
        std::vector<int32_t> point_leaf;  // derived: per point (octree order), its leaf
    };
    Data d_;
};

}  // namespace vmap
