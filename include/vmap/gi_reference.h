// The exact answer the GI is measured against: Monte Carlo path tracing of diffuse
// interreflection over a scene's triangles (Embree 3), with the surfaces, albedos and emitters
// the points were sampled from and exact visibility.
//
// At a surface point x with normal n, albedo rho and emission E the radiosity (W/m^2 per
// channel, the quantity vmap's GI computes) is B(x) = E + rho H(x), H the irradiance. Each path
// from x samples, at every vertex, the emitters by area (next-event estimation: one point on the
// emitting triangles, exact shadow ray) and continues in a cosine-distributed direction to the
// nearest triangle, multiplying the throughput by that surface's albedo; emission found by the
// continuation ray is not counted again. A back face hit ends the path (no point stands for a
// back side). The direct light found at vertex d is light after d + 1 bounces, so one path gives
// B after 1, 2, ..., K bounces (vmap's --bounces K) and converged (every bounce until the
// throughput falls below 1e-6 or the path leaves the scene); each with its standard error over
// the samples. Seeded: sample s of point i draws from a counter-based generator keyed by (seed,
// i, s), so the result does not depend on the thread count.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "vmap/progress.h"

#include "vmap/scene.h"
#include "vmap/vec.h"

namespace vmap {

struct ReferenceParams {
    uint32_t samples = 1024;  // paths per point (>= 2)
    int bounces = 3;          // results after 1..bounces bounces, then converged
    uint64_t seed = 1;
    ProgressCallback progress;  // points done (vmap/progress.h); false cancels
};

// Where to evaluate: a point on a surface, its (outward) unit normal, albedo and emission.
struct ReferencePoint {
    Vec3 position, normal, albedo, emission;
};

struct ReferenceResult {
    // value[k][i]: radiosity at point i after k + 1 bounces for k < bounces; value[bounces][i]:
    // converged. std_error alike (the standard error of the mean over the samples).
    std::vector<std::vector<Vec3>> value, std_error;
    uint64_t rays = 0;  // rays traced (continuation and shadow)
    double seconds = 0;
};

// Throws vmap::Error naming `source` when Embree fails, the scene has no triangles or no
// emitting triangles, or samples < 2 or bounces < 1.
ReferenceResult path_trace_radiosity(const std::vector<SceneSurface>& surfaces,
                                     const std::vector<ReferencePoint>& at,
                                     const ReferenceParams& params, const std::string& source);

}  // namespace vmap
