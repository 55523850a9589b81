// Scenes (docs/design.md "Scenes and sampling"): a JSON file describing a Cornell room, meshes and point clouds
// placed in it and an area light, sampled into one mixed point set. A mesh file on its own
// (PLY with faces, OFF, OBJ, STL) is a scene of one surface with no room. Also raw point clouds
// (files without faces).
//
// Scene file (all lengths in metres; see scenes/*.json):
// {
//   "name": "cornell-bunny",
//   "room":  { "size": [0.5528, 0.5488, 0.5592],            // x (width), y (height), z (depth)
//              "floor": [r,g,b], "ceiling": [..], "back": [..],
//              "left": [..] (red, x = width), "right": [..] (green, x = 0) },   // albedo
//            or null: no room, no light (just the meshes and clouds); absent: the default room
//   "light": { "center": [x, z], "size": [sx, sz], "emission": [r,g,b] },       // on the ceiling
//            (clipped to the room; the ceiling is not sampled under it; needs the room)
//   "meshes": [ { "file": "../models/bunny.off",   // relative to the scene file; any mesh format
//                 "size": 0.25,                    // largest extent after scaling (or "scale":
//                                                  //  a factor, or [sx, sy, sz] per axis)
//                 "rotate": [rx, ry, rz],           // degrees, applied x then y then z
//                 "position": [x, y, z],            // where the bottom centre of its box goes
//                 "albedo": [r, g, b],              // default: the file's vertex colours, else
//                 0.75 "emission": [r, g, b],            // W/m^2; default: the file's, else none
//                 "flip_normals": false } ],
//   "clouds": [ { "file": "scan.ply", ... } ]       // point clouds, placed like meshes (same keys
//                                                   // but flip_normals); normals estimated and
//                                                   // radii set when the file has none
//   Without a room, a mesh or cloud with none of size, scale, rotate and position keeps the
//   file's coordinates exactly; with some, position defaults to its own bottom centre.
//   "sampling": { "points": 60000, "seed": 1 }      // or "density": points per square metre;
//                                                   // "pattern": "blue-noise" (default) | "uniform"
//   "octree": { "max_height": 9, "leaf_points": 4 } // defaults for `vmap build` (and
//                                                   // "delta_floor", else by the pattern)
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
#include "vmap/options.h"
#include "vmap/progress.h"

namespace vmap {

// One surface of the scene in world space, for sampling and (later) exact ray casting.
struct SceneSurface {
    std::string name;  // "floor", "light", "bunny", ...
    Mesh mesh;         // world space; triangle winding gives the outward normal
    Vec3 albedo{0.8f, 0.8f, 0.8f};
    Vec3 emission{0, 0, 0};
    // Per-vertex values from the mesh file, interpolated over each triangle when sampling; when
    // empty, albedo and emission hold for the whole surface.
    std::vector<Vec3> vertex_colors;
    std::vector<Vec3> vertex_emission;
    bool is_model = false;  // a mesh placed in the scene (not the room or its light)
};

struct Scene {
    std::string name;
    std::string path;  // the file it came from
    std::vector<SceneSurface> surfaces;
    // Point clouds in world space, complete (normals, colours, radii, emission), appended after
    // the surfaces' samples.
    std::vector<PointSet> clouds;
    uint64_t points = 60000;  // samples of the surfaces in total (after any density rule)
    uint64_t seed = 1;
    SamplePattern pattern = SamplePattern::kBlueNoise;  // "sampling": {"pattern": ...}
    std::optional<OctreeParams> octree;  // the file's defaults, if it gave any
    std::optional<float> delta_floor;    // "octree": {"delta_floor": ...}, if the file gave it
    bool has_room = true;
    // The room's size; without a room, the size of the surfaces' and clouds' bounding box (the
    // scene's scale, for validation tolerances).
    Vec3 room_size{0.5528f, 0.5488f, 0.5592f};
    std::optional<Camera> camera;  // the file's view for `vmap render`, if it gave one
    // What the files held that is not used (ModelData::notes), for the tool to print.
    std::vector<std::string> notes;
};

// Reads a scene file (.json) and the meshes and clouds it names, or a mesh file as a scene of
// that one surface (no room, faces wound outward as for a scene's mesh, the file's vertex colours
// and emission, else albedo 0.8). Throws vmap::Error naming the file and the field
// ("scenes/x.json: meshes[0].file: ../models/nope.off: no such file"; "scan.xyz: has no faces").
Scene load_scene(const std::string& path);

// The total area of the scene's surfaces (room, light and meshes), in squared scene units.
double scene_area(const Scene& sc);

// Whether `vmap build/render/gi/validate` take the file as a scene: a .json file, or a mesh
// file (model_has_faces) unless `as_points` asks for its vertices as a point cloud.
bool is_scene_input(const std::string& path, bool as_points = false);

// Area-weighted, seeded sampling of every surface into points with the triangle's normal, the
// surface's albedo and emission (or the per-vertex values, interpolated), and a splat radius
// sqrt(area / (pi * points)); then the scene's clouds. The same seed gives the same points on
// every machine and thread count. The points of an emitting surface emit exactly its power (the
// binomial count of its points would miss it by a few percent, so their emission is scaled by
// the surface's area over their discs'). `surface_of`, when given, receives each point's index
// into scene.surfaces (kNoSurface for a cloud's points). `progress`, when set, reports the
// blue-noise elimination (stage "sampling (candidates removed)", seconds for millions of
// points) and can cancel it (vmap::Cancelled).
inline constexpr uint32_t kNoSurface = 0xffffffffu;
PointSet sample_scene(const Scene& scene, std::vector<uint32_t>* surface_of = nullptr,
                      const ProgressCallback& progress = {});

// The octree parameters a V-map of the scene's samples is built with by default: the file's
// max_height and leaf_points (else OctreeParams'), and its delta_floor, else the floor for how
// the scene is sampled (OctreeParams::kEvenDeltaFloor for blue noise, kDefaultDeltaFloor for
// uniform samples).
OctreeParams scene_octree(const Scene& scene);

// What to do with a raw cloud's normals (`vmap build --normals`).
enum class NormalsMode {
    kKeep,      // the file's normals (estimated when it has none)
    kFlip,      // the file's normals, negated (an error when it has none)
    kInward,    // the file's (or estimated) normal axes, each toward the cloud's centroid
    kOutward,   // ... each away from the centroid
    kEstimate,  // estimated from the positions even when the file has normals
};

struct CloudOptions {
    NormalsMode normals = NormalsMode::kKeep;
    // Orient every normal toward it (the scanner's position), in the file's coordinates (double:
    // a georeferenced scan's millions of units; PointSet::origin is subtracted).
    std::optional<std::array<double, 3>> viewpoint;
};

// Reads a raw point cloud (PLY or OFF; faces ignored) and completes it: normals per
// options.normals (estimated ones oriented toward options.viewpoint when given, else toward the
// file's per-point sensor positions when it has them, else by free space: vmap/normals.h),
// splat radii from same-surface neighbours when absent (estimate_radii), albedo 0.8 when there
// are no colours. `done`, when given, receives one line per thing estimated or changed.
PointSet load_point_cloud(const std::string& path, const CloudOptions& options = {},
                          std::vector<std::string>* done = nullptr);

// The built-in default scene (the README's first command): scenes/cornell-bunny.json.
std::string default_scene_path();

}  // namespace vmap
