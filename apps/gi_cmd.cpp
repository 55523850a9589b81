// `vmap gi`: diffuse global illumination over the V-map (paper §6.3, include/vmap/gi.h).
//   vmap gi [SCENE.json | MAP.vmap] [-o image.png] [--ply lit.ply] [--bounces 3] [--theta 1]
// A scene is sampled and its V-map built on the fly (the scene's octree defaults); a .vmap file
// carries the points' emission, albedo and splat radii itself.
#include "apps/gi_cmd.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <memory>
#include <optional>

#include "apps/commands.h"
#include "io/atomic_file.h"
#include "util/progress.h"
#include "vmap/error.h"
#include "vmap/gi.h"
#include "vmap/io.h"
#include "vmap/render.h"
#include "vmap/scene.h"
#include "vmap/vmap.h"

namespace vmap::cli {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

bool has_suffix_ci(std::string s, const std::string& suf) {
    std::transform(s.begin(), s.end(), s.begin(), ::tolower);
    return s.size() >= suf.size() && s.compare(s.size() - suf.size(), suf.size(), suf) == 0;
}

struct GiOptions {
    std::string input;
    std::string image, ply;
    std::optional<uint64_t> points, seed;
    std::optional<int> max_height, leaf_points;
    GiParams gi;
    float exposure = 0;
    std::string scene, eye, target, up, size = "800x800";
    std::optional<float> fov;
    RenderOptions render;
    bool compare = false;
};

// The V-map of the input: loaded, or built from a scene with its octree defaults.
VisibilityMap input_vmap(GiOptions& o, std::string& what, double& build_s,
                         std::optional<Camera>& camera) {
    const auto t0 = Clock::now();
    if (has_suffix_ci(o.input, ".json")) {
        Scene sc = load_scene(o.input);
        camera = sc.camera;
        if (o.points) sc.points = *o.points;
        if (o.seed) sc.seed = *o.seed;
        BuildParams bp;
        if (sc.octree) bp.octree = *sc.octree;
        if (o.max_height) bp.octree.max_height = *o.max_height;
        if (o.leaf_points) bp.octree.leaf_points = *o.leaf_points;
        bp.backend = o.gi.backend;
        bp.progress = detail::stderr_is_terminal();
        warn_if_long(o.input, sc.points, bp.octree);
        BuildStats st;
        VisibilityMap vm = build_vmap(sample_scene(sc), bp, &st, o.input);
        build_s = seconds_since(t0);
        what = fmt::format("scene {} ({}), V-map built on {} in {:.2f} s", sc.name, o.input,
                           st.backend, build_s);
        return vm;
    }
    if (o.points || o.seed || o.max_height || o.leaf_points)
        throw Error(fmt::format(
            "{}: --points/--seed/--max-height/--leaf-points apply to scene files (.json)",
            o.input));
    VisibilityMap vm = load_vmap(o.input);
    if (!o.scene.empty()) camera = load_scene(o.scene).camera;
    build_s = seconds_since(t0);
    what = fmt::format("V-map {} (loaded in {:.2f} s)", o.input, build_s);
    return vm;
}

int run_gi(GiOptions& o) {
    if (o.input.empty()) o.input = default_scene_path();
    io::check_input_path(o.input);
    if (!o.scene.empty()) io::check_input_path(o.scene);
    check_output(o.ply, "--ply", {o.input, o.scene, o.image});
    check_output(o.image, "-o", {o.input, o.scene});
    const auto [width, height] = parse_size(o.size, "--size");
    o.render.width = width, o.render.height = height;
    o.render.shade = false;                          // the light is in the radiosity
    if (!o.eye.empty()) parse_vec3(o.eye, "--eye");  // bad camera options fail before the work
    if (!o.target.empty()) parse_vec3(o.target, "--target");
    if (!o.up.empty()) parse_vec3(o.up, "--up");
    std::string what;
    double build_s = 0;
    std::optional<Camera> scene_camera;
    const VisibilityMap vm = input_vmap(o, what, build_s, scene_camera);
    const PointSet& ps = vm.points;
    PointSet out = points_in_input_order(vm);  // input order and units, for the outputs
    // The camera (the default one frames the points' box, which the order does not change),
    // checked before the solve.
    Camera cam = scene_camera ? *scene_camera : default_camera(out);
    if (!o.eye.empty()) cam.eye = parse_vec3(o.eye, "--eye");
    if (!o.target.empty()) cam.target = parse_vec3(o.target, "--target");
    if (!o.up.empty()) cam.up = parse_vec3(o.up, "--up");
    if (o.fov) cam.fov_y_deg = *o.fov;
    if (!o.image.empty())
        check_camera(cam, "camera (--eye/--target/--up/--fov or the scene's camera)");
    size_t emitters = 0;
    for (const Vec3& e : ps.emission) emitters += e.x > 0 || e.y > 0 || e.z > 0;
    if (emitters == 0)
        throw Error(fmt::format(
            "{}: no emitters: no point has emission > 0 (a scene needs a \"light\"; a .vmap keeps "
            "the emission its scene gave)",
            o.input));
    if (!ps.has_radii())
        throw Error(
            fmt::format("{}: points have no splat radii (needed for their areas)", o.input));

    fmt::print("input:      {}\n", what);
    fmt::print("points:     {} ({} emitting), {} nodes, {} leaves, {} links\n", ps.size(), emitters,
               vm.octree.num_nodes(), vm.octree.num_leaves(), vm.num_links());
    RadiositySolver solver(vm, o.gi);
    const GiStats& st0 = solver.stats();
    if (!st0.note.empty()) fmt::print("note:       {}\n", st0.note);
    fmt::print("backend:    {}\n", st0.backend);
    fmt::print(
        "refinement: {}, theta {}: {} interactions ({} node level, {} point to point), "
        "setup {:.3f} s\n",
        o.gi.refine, o.gi.theta, st0.interactions(), st0.node_interactions, st0.point_interactions,
        st0.seconds_setup);
    std::vector<std::vector<Vec3>> ref;
    std::vector<double> brute_s;
    if (o.compare) brute_force_radiosity(vm, o.gi.bounces, &ref, &brute_s);
    {
        detail::Progress bar("gi bounces", uint64_t(o.gi.bounces), detail::stderr_is_terminal());
        const Vec3 p0 = total_power(vm, solver.radiosity());
        fmt::print("power:      emitted {:.4g} {:.4g} {:.4g} W\n", p0.x, p0.y, p0.z);
        for (int b = 0; b < o.gi.bounces; ++b) {
            solver.bounce();
            bar.update(uint64_t(b + 1));
            const auto B = solver.radiosity();
            const Vec3 p = total_power(vm, B);
            std::string cmp;
            if (o.compare)
                cmp = fmt::format(", brute force {:.3f} s, relative RMS vs brute force {:.4f}",
                                  brute_s[b], relative_rms(B, ref[b]));
            fmt::print("bounce {:2d}:  {:.4f} s, leaving power {:.4g} {:.4g} {:.4g} W{}\n", b + 1,
                       solver.stats().seconds_bounce.back(), p.x, p.y, p.z, cmp);
        }
    }
    const std::vector<Vec3> B = solver.radiosity();
    std::vector<Vec3> colors;
    const float exposure = tone_map(vm, B, o.exposure, colors);
    fmt::print("tone map:   exposure {:.4g} (display = clamp(exposure x radiosity), sRGB)\n",
               exposure);

    std::vector<Vec3> lit(colors.size());
    for (size_t k = 0; k < colors.size(); ++k) lit[vm.order[k]] = colors[k];
    if (!o.image.empty()) {
        const auto t0 = Clock::now();
        const Image img = render_points(out, lit, cam, o.render);
        write_png(o.image, img);
        fmt::print("wrote:      {} ({}x{}, rendered in {:.2f} s)\n", o.image, img.width, img.height,
                   seconds_since(t0));
    }
    if (!o.ply.empty()) {
        // PLY colours are bytes as they are displayed: sRGB-encode the linear colours.
        out.colors.resize(lit.size());
        for (size_t i = 0; i < lit.size(); ++i)
            out.colors[i] =
                Vec3{linear_to_srgb8(lit[i].x) / 255.0f, linear_to_srgb8(lit[i].y) / 255.0f,
                     linear_to_srgb8(lit[i].z) / 255.0f};
        out.emission.clear();
        write_ply(o.ply, out);
        fmt::print("wrote:      {} (lit display colours)\n", o.ply);
    }
    return 0;
}

}  // namespace

GiCommands add_gi_commands(CLI::App& app) {
    auto o = std::make_shared<GiOptions>();
    GiCommands c;
    auto* gi = app.add_subcommand(
        "gi", "Diffuse global illumination over the V-map (hierarchical radiosity; paper §6.3)");
    c.gi = gi;
    gi->add_option("input", o->input,
                   "Scene file (.json; V-map built on the fly) or .vmap file. Default: "
                   "scenes/cornell-bunny.json");
    gi->add_option("-o,--output", o->image, "Write the lit scene as a PNG");
    gi->add_option("--ply", o->ply, "Write the points with their lit display colours (PLY)");
    gi->add_option("--bounces", o->gi.bounces, "Gather steps after B = E (1: direct light)")
        ->check(CLI::Range(0, 10000))
        ->capture_default_str();
    gi->add_option("--theta", o->gi.theta,
                   "Separation parameter: node-level transfer when the centres are more than "
                   "theta x (sum of the node sizes) apart; larger is finer and slower")
        ->check(CLI::Range(1e-3, 1e3))
        ->capture_default_str();
    gi->add_option("--backend", o->gi.backend,
                   "auto (GPU when present), cpu or cuda; for the V-map build and the bounces")
        ->check(CLI::IsMember({"auto", "cpu", "cuda"}))
        ->capture_default_str();
    gi->add_option("--refine", o->gi.refine,
                   "blocks: links summed into well-separated node pairs (fast); links: every "
                   "V-map link moves energy itself (exact visibility, slower)")
        ->check(CLI::IsMember({"blocks", "links"}))
        ->capture_default_str();
    gi->add_option("--exposure", o->exposure,
                   "Display colour = clamp(exposure x radiosity) (linear, then sRGB); 0: "
                   "automatic (95th percentile of the lit points -> 0.8)")
        ->check(CLI::Range(0.0f, 1e9f))
        ->capture_default_str();
    gi->add_option("--scene", o->scene, "Take the camera from this scene file (for .vmap input)");
    gi->add_option("--eye", o->eye, "Camera position x,y,z");
    gi->add_option("--target", o->target, "Camera target x,y,z");
    gi->add_option("--up", o->up, "Camera up vector x,y,z (default 0,1,0)");
    gi->add_option("--fov", o->fov, "Vertical field of view, degrees")
        ->check(CLI::Range(1.f, 179.f));
    gi->add_option("--size", o->size, "Image size WxH")->capture_default_str();
    gi->add_option("--splat-scale", o->render.splat_scale, "Disc radius = splat radius x this")
        ->check(CLI::Range(0.01f, 100.f))
        ->capture_default_str();
    gi->add_option("--supersample", o->render.supersample, "s x s samples per pixel (1..4)")
        ->check(CLI::Range(1, 4))
        ->capture_default_str();
    gi->add_option("--points", o->points, "Override the scene's number of sample points")
        ->check(CLI::Range(uint64_t(1), uint64_t(50000000)));
    gi->add_option("--seed", o->seed, "Override the scene's sampling seed");
    gi->add_option("--max-height", o->max_height, "Override the scene's octree max_height")
        ->check(CLI::Range(1, 21));
    gi->add_option("--leaf-points", o->leaf_points, "Override the scene's octree leaf_points")
        ->check(CLI::Range(1, 1000000));
    gi->add_flag("--compare-brute", o->compare,
                 "Also run the brute-force gather (every visible point pair) and print the "
                 "relative RMS difference per bounce (small scenes)");
    c.run_gi = [o] { return run_gi(*o); };
    auto [bench, run_bench] = add_gi_bench_command(app);
    c.bench = bench;
    c.run_bench = run_bench;
    return c;
}

}  // namespace vmap::cli
