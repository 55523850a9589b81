// Small scenes and brute-force oracles shared by the tests.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include "octree/records.h"
#include "visibility/leaf_pair.h"
#include "vmap/scene.h"
#include "vmap/map_access.h"
#include "vmap/vmap.h"

namespace vmap::test {

// A map's points and octree, writable (tests that change a built map).
inline PointSet& points_of(VisibilityMap& vm) { return detail::MapAccess::data(vm).points; }
inline detail::OctreeData& octree_of(VisibilityMap& vm) {
    return detail::OctreeAccess::data(detail::MapAccess::data(vm).octree);
}

inline std::string scene_path(const std::string& name) {
    return std::string(VMAP_SOURCE_DIR) + "/scenes/" + name + ".json";
}
inline std::string oracle_path(const std::string& name) {
    return std::string(VMAP_TEST_DATA) + "/oracle/" + name;
}

// Samples a scene file with n points and seed.
inline PointSet sample(const std::string& scene_file, uint64_t n, uint64_t seed = 1) {
    Scene sc = load_scene(scene_file);
    sc.points = n;
    sc.seed = seed;
    return sample_scene(sc);
}

inline BuildParams cpu_params(int max_height, int leaf_points) {
    BuildParams bp;
    bp.backend = Backend::kCpu;
    bp.octree.max_height = max_height;
    bp.octree.leaf_points = leaf_points;
    return bp;
}

// Dense brute-force leaf-pair matrix: M[a * L + b] for a < b (the orientation the builder uses).
inline std::vector<uint8_t> brute_matrix(const VisibilityMap& vm) {
    const OctreeView v = octree_view(vm.octree());
    const int32_t L = v.num_leaves;
    std::vector<uint8_t> m(size_t(L) * L, 0);
    for (int32_t a = 0; a < L; ++a)
        for (int32_t b = a + 1; b < L; ++b) {
            const bool vis = detail::leaf_pair_visible<false>(v, a, b, vm.visibility_params(),
                                                              static_cast<WorkCounters*>(nullptr));
            m[size_t(a) * L + b] = m[size_t(b) * L + a] = vis;
        }
    return m;
}

}  // namespace vmap::test
