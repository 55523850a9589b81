// A command's input, however it is given: a scene file, a mesh file (area-sampled, or its
// vertices as a cloud), a point cloud or a .vmap, with the overrides of the scene's sampling and
// octree that `vmap build`, `render`, `gi` and `view` offer. One function reads it for all.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "vmap/camera.h"
#include "vmap/octree.h"
#include "vmap/progress.h"
#include "vmap/scene.h"
#include "vmap/vmap.h"

namespace vmap {

struct InputOptions {
    std::string path;
    bool as_points = false;                      // a mesh file's vertices as a point cloud
    std::optional<uint64_t> points, seed;        // sampling: scene and mesh files only
    std::optional<SamplePattern> pattern;        // sampling: scene and mesh files only
    std::optional<int> max_height, leaf_points;  // the octree: not for a .vmap (it has one)
    std::optional<float> delta_floor;            // the octree: not for a .vmap
    std::optional<float> roughness;              // the predicate's: not for a .vmap
    CloudOptions cloud;                          // point clouds only
    // Scene and mesh files: called with the number of points and the octree parameters before
    // the sampling starts (which takes seconds for millions of points), e.g. to warn that the
    // build will be long before any work.
    std::function<void(uint64_t points, const OctreeParams&)> before_sampling;
    // Scene and mesh files: the blue-noise sampling's progress (sample_scene), when set.
    ProgressCallback progress;
};

enum class InputKind { kScene, kMesh, kCloud, kVmap };

struct Input {
    InputKind kind = InputKind::kScene;
    std::string name;                   // the scene's name, else the file's name
    std::string description;            // "scene NAME (PATH), N surfaces", "point cloud PATH", ...
    PointSet points;                    // sampled or read, in input order (empty for a .vmap)
    std::optional<VisibilityMap> vmap;  // a .vmap input
    std::optional<Camera> camera;       // a scene's camera
    OctreeParams octree;                // the scene's (or the map's, or the default) with overrides
    // The predicate's roughness for building from it (VisibilityParams::roughness): a cloud's
    // measured noise (estimate_surface_noise, roughness_of), or InputOptions::roughness when
    // given; 0 for samples of a scene or mesh, which lie on their surfaces; the map's for a .vmap.
    float roughness = 0;
    std::vector<std::string> notes;     // what the files held but vmap does not use (Scene::notes)
    std::vector<std::string> done;      // what the cloud reader estimated (load_point_cloud)
};

// Reads `o.path`: a .vmap as it is; a scene file, or a mesh file unless o.as_points
// (is_scene_input), sampled with o.points and o.seed in place of the scene's; any other file as
// a point cloud (load_point_cloud with o.cloud). o.max_height, o.leaf_points and o.delta_floor
// replace the scene's octree parameters (scene_octree; else BuildParams' defaults). Throws
// vmap::Error naming the file for what its loader refuses, for points, seed or pattern given with a
// cloud or a .vmap, and for max_height, leaf_points, delta_floor or roughness given with a .vmap.
Input load_input(const InputOptions& o);

}  // namespace vmap
