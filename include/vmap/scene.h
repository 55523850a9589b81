// Scenes (DESIGN.md "Scenes"): a JSON file describing a Cornell room, meshes placed in it and an
// area light, sampled into one mixed point set. Also raw point clouds (PLY/OFF without faces).
//
// Scene file (all lengths in metres; see scenes/*.json):
// {
//   "name": "cornell-bunny",
//   "room":  { "size": [0.5528, 0.5488, 0.5592],            // x (width), y (height), z (depth)
//              "floor": [r,g,b], "ceiling": [..], "back": [..],
//              "left": [..] (red, x = width), "right": [..] (green, x = 0) },   // albedo
//   "light": { "center": [x, z], "size": [sx, sz], "emission": [r,g,b] },       // on the ceiling
//            (clipped to the room; the ceiling is not sampled under it)
//   "meshes": [ { "file": "../models/bunny.off",   // relative to the scene file
//                 "size": 0.25,                    // largest extent after scaling (or "scale")
//                 "rotate": [rx, ry, rz],           // degrees, applied x then y then z
//                 "position": [x, y, z],            // where the bottom centre of its box goes
//                 "albedo": [r, g, b], "flip_normals": false } ],
//   "sampling": { "points": 60000, "seed": 1 }      // or "density": points per square metre
//   "octree": { "max_height": 9, "leaf_points": 4 } // defaults for `vmap build`
//   "camera": { "eye": [x,y,z], "target": [x,y,z], "fov": 40, "up": [0,1,0] }  // `vmap render`
// }
// The room is open at z = 0, the side a camera looks in from.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "vmap/camera.h"
#include "vmap/mesh.h"
#include "vmap/octree.h"

namespace vmap {

// One surface of the scene in world space, for sampling and (later) exact ray casting.
struct SceneSurface {
    std::string name;  // "floor", "light", "bunny", ...
    Mesh mesh;         // world space; triangle winding gives the outward normal
    Vec3 albedo{0.8f, 0.8f, 0.8f};
    Vec3 emission{0, 0, 0};
};

struct Scene {
    std::string name;
    std::string path;  // the file it came from
    std::vector<SceneSurface> surfaces;
    uint64_t points = 60000;  // samples in total (after any density rule)
    uint64_t seed = 1;
    std::optional<OctreeParams> octree;  // the file's defaults, if it gave any
    Vec3 room_size{0.5528f, 0.5488f, 0.5592f};
    std::optional<Camera> camera;  // the file's view for `vmap render`, if it gave one
};

// Reads a scene file and the meshes it names. Throws vmap::Error naming the file and the field
// ("scenes/x.json: meshes[0].file: ../models/nope.off: no such file").
Scene load_scene(const std::string& path);

// Area-weighted, seeded sampling of every surface into points with the triangle's normal, the
// surface's albedo and emission, and a splat radius sqrt(area / (pi * points)). The same seed
// gives the same points on every machine and thread count. The points of an emitting surface
// emit exactly its power (sum of disc area x emission = surface area x emission): the binomial
// count of its points would miss it by a few percent, so their emission is scaled by the
// surface's area over their discs'. surface_of (if given) receives each point's surface index
// (into scene.surfaces).
PointSet sample_scene(const Scene& scene, std::vector<uint32_t>* surface_of = nullptr);

// Reads a raw point cloud (PLY or OFF; faces ignored). Estimates normals when the file has none
// (k nearest neighbours), sets splat radii from the neighbour spacing when absent, and albedo 0.8
// when there are no colours.
PointSet load_point_cloud(const std::string& path);

// The built-in default scene (the README's first command): scenes/cornell-bunny.json.
std::string default_scene_path();

}  // namespace vmap
