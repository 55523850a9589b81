// One command's input: scene, mesh, cloud or .vmap, with the overrides (include/vmap/input.h).
#include "vmap/input.h"

#include <fmt/format.h>

#include <filesystem>

#include "vmap/error.h"
#include "vmap/io.h"
#include "vmap/normals.h"
#include "vmap/visibility_map.h"

namespace vmap {
namespace {

// Measured noise from which a cloud's build warns, in sample spacings: noise of half a spacing
// reads 0.33-0.38 (the measure saturates near 0.45 as the noise passes the spacing: the points
// no longer look like a surface at the neighbours' scale), where bare clouds score 84-93% over
// all pairs (docs/validation.md "Noisy scans").
constexpr double kHeavyNoise = 0.33;

void apply_octree_overrides(const InputOptions& o, OctreeParams& p) {
    if (o.max_height) p.max_height = *o.max_height;
    if (o.leaf_points) p.leaf_points = *o.leaf_points;
    if (o.delta_floor) p.delta_floor = *o.delta_floor;
}

void load_map(const InputOptions& o, Input& in) {
    if (o.max_height || o.leaf_points || o.delta_floor || o.roughness)
        throw Error(fmt::format(
            "{}: max_height, leaf_points, delta_floor and roughness (--max-height, "
            "--leaf-points, --delta-floor, --roughness) apply when building a V-map, not to a "
            ".vmap",
            o.path));
    in.kind = InputKind::kVmap;
    in.vmap = load_vmap(o.path);
    in.octree = in.vmap->octree_params();
    in.roughness = in.vmap->visibility_params().roughness;
    in.description = fmt::format("V-map {}", o.path);
}

void load_cloud(const InputOptions& o, Input& in) {
    in.kind = InputKind::kCloud;
    in.points = load_point_cloud(o.path, o.cloud, &in.done);
    in.octree = BuildParams{}.octree;
    if (!o.delta_floor) {
        // Nothing says how the cloud was sampled: the disc floor from how evenly it was.
        const double share = close_neighbour_share(in.points);
        in.octree.delta_floor = delta_floor_of_share(share);
        in.done.push_back(fmt::format(
            "occluder disc floor: {:.2f} splat radii ({:.1f}% of points with a close neighbour; "
            "independent uniform samples have {:.1f}%: {})",
            in.octree.delta_floor, 100.0 * share, 100.0 * kPoissonCloseShare,
            share < 0.25 * kPoissonCloseShare   ? "sampled evenly"
            : share > 0.75 * kPoissonCloseShare ? "sampled independently"
                                                : "in between"));
    }
    apply_octree_overrides(o, in.octree);
    if (o.roughness) {
        in.roughness = *o.roughness;
    } else {
        // A scan's points scatter off their surfaces: steps of the noise's size between a
        // point and its own sheet are no occluders (VisibilityParams::roughness).
        const SurfaceNoise noise = estimate_surface_noise(in.points);
        in.roughness = roughness_of(noise);
        const double share = noise.spacing > 0 ? noise.sigma / noise.spacing : 0.0;
        in.done.push_back(
            in.roughness > 0
                ? fmt::format("surface noise: {:.3g} ({:.2f} sample spacings of {:.3g}): steps "
                              "up to {:.3g} between a point and its own sheet do not occlude",
                              noise.sigma, share, noise.spacing, in.roughness)
                : fmt::format("surface noise: none measured ({:.3f} sample spacings, under {})",
                              share, kNoiseFloor));
        // Noise of half the spacing or more blurs what the points can say: the normals' signs
        // and the thin parts go first, and the roughness reads low.
        if (share >= kHeavyNoise)
            in.done.push_back(fmt::format(
                "warning: the points scatter {:.2f} sample spacings off their surfaces: expect "
                "visibility well below a clean scan's (thin parts and normals' signs suffer "
                "most); denoise the cloud or give its scanner's normals",
                share));
    }
    in.description = fmt::format("point cloud {}", o.path);
}

void load_sampled(const InputOptions& o, Input& in) {
    Scene sc = load_scene(o.path);
    const bool scene_file = has_extension(o.path, ".json");
    in.kind = scene_file ? InputKind::kScene : InputKind::kMesh;
    if (o.points) sc.points = *o.points;
    if (o.seed) sc.seed = *o.seed;
    if (o.pattern) sc.pattern = *o.pattern;
    in.octree = scene_octree(sc);
    apply_octree_overrides(o, in.octree);
    in.roughness = o.roughness.value_or(0.f);  // samples lie on the surfaces
    in.name = sc.name;
    in.camera = sc.camera;
    in.notes = sc.notes;
    in.description =
        scene_file ? fmt::format("scene {} ({}), {} surfaces", sc.name, o.path, sc.surfaces.size())
                   : fmt::format("mesh {} ({} triangles, area-sampled)", o.path,
                                 sc.surfaces[0].mesh.triangles.size());
    in.description += fmt::format(", {} samples", name_of(sc.pattern));
    if (o.before_sampling) o.before_sampling(sc.points, in.octree);
    in.points = sample_scene(sc, nullptr, o.progress);
}

}  // namespace

Input load_input(const InputOptions& o) {
    Input in;
    in.name = std::filesystem::path(o.path).filename().string();
    const bool is_vmap = has_extension(o.path, ".vmap");
    if (is_vmap || !is_scene_input(o.path, o.as_points)) {
        if (o.points || o.seed || o.pattern)
            throw Error(fmt::format(
                "{}: points, seed and sampling (--points, --seed, --sampling) apply when building "
                "from a scene or mesh file, not to {}",
                o.path, is_vmap ? "a .vmap" : "a point cloud"));
        is_vmap ? load_map(o, in) : load_cloud(o, in);
        return in;
    }
    load_sampled(o, in);
    return in;
}

}  // namespace vmap
