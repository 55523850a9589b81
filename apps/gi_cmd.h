// What `vmap gi` (apps/gi_cmd.cpp) and its error table (apps/gi_error.cpp) share; the commands
// are registered as every other (apps/commands.h).
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <optional>
#include <string>

#include "apps/commands.h"
#include "vmap/gi.h"
#include "vmap/gi_reference.h"
#include "vmap/render.h"
#include "vmap/vmap.h"

namespace vmap::cli {

// The predicate for a V-map built by `vmap gi` (docs/gi.md "The V-map for the GI"): the GI weighs
// pairs by form factor, so near pairs, which `vmap build`'s eps hides too often, count most.
inline constexpr int kGiVmapK = 2;
inline constexpr float kGiVmapEps = 0.01f;
inline constexpr float kGiVmapEndWindow = 2.0f;
inline constexpr float kGiVmapCore = VisibilityParams::kDefaultCore;
// Its occluder discs' floor is vmap build's (scene_octree: by how the scene is sampled; docs/gi.md
// "The occluder disc's floor").

// The options of `vmap gi`.
struct GiOptions {
    InputOptions in;  // the input and its overrides (vmap/input.h)
    CameraOptions cam;
    std::string image, ply, pfm;
    int K = kGiVmapK;  // the predicate for a V-map built here
    float eps = kGiVmapEps;
    float end_window = kGiVmapEndWindow;
    float core = kGiVmapCore;
    GiParams gi;
    std::optional<int> bounces;  // fixed bounce count (the final gather included); else converge
    double tolerance = 1e-3;     // converged: the last bounce added less than this of the power
    int max_bounces = 200;
    bool final_gather = true;
    float gather_theta = 2.0f;
    float exposure = 0;
    RenderOptions render;
    bool compare = false;
    // --reference
    bool reference = false, brute = true;
    size_t ref_points = 1000;
    uint32_t ref_picture_samples = 128;
    ReferenceParams ref;
    std::string ref_out;
};

// The build parameters of the V-map `vmap gi` makes from a scene file: the scene's octree
// defaults and the options above.
BuildParams gi_build_params(const OctreeParams& octree, const GiOptions& o);

// apps/gi_error.cpp: `vmap gi SCENE --reference`, the error table.
int run_gi_reference(GiOptions& o);

}  // namespace vmap::cli
