// `vmap gi`: diffuse global illumination over the V-map (paper §6.3, include/vmap/gi.h).
//   vmap gi [SCENE.json | MESH | CLOUD | MAP.vmap] [-o image.png] [--ply lit.ply] [--theta 1]
// A scene or mesh is sampled and its V-map built on the fly (the scene's octree defaults), a
// point cloud's V-map built from its points; a .vmap file carries the points' emission, albedo
// and splat radii itself.
#include "apps/gi_cmd.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <memory>
#include <optional>

#include "apps/commands.h"
#include "vmap/error.h"
#include "vmap/files.h"
#include "vmap/gi.h"
#include "vmap/io.h"
#include "vmap/render.h"
#include "vmap/scene.h"
#include "vmap/vmap.h"

namespace vmap::cli {
namespace {

using Clock = std::chrono::steady_clock;


// The points that emit; none is an error naming what to add, raised before any V-map is built.
size_t count_emitters(const PointSet& ps, const std::string& input) {
    size_t emitters = 0;
    for (const Vec3& e : ps.emission) emitters += e.x > 0 || e.y > 0 || e.z > 0;
    if (emitters == 0)
        throw Error(fmt::format(
            "{}: no emitters: no point has emission > 0; add \"emission\": [r, g, b] to a mesh "
            "or cloud entry of a scene file (or a \"light\" with the room), or the properties "
            "emission_r, emission_g, emission_b to a PLY cloud (a .vmap keeps its input's)",
            input));
    return emitters;
}

// The V-map of the input (vmap/input.h): loaded, or built from a scene or mesh (sampled, with
// the scene's octree defaults) or a point cloud; the scene's camera, or --scene's.
VisibilityMap input_vmap(GiOptions& o, std::string& what, double& build_s,
                         std::optional<Camera>& camera) {
    const auto t0 = Clock::now();
    if (has_extension(o.in.path, ".vmap") &&
        (o.K != kGiVmapK || o.eps != kGiVmapEps || o.end_window != kGiVmapEndWindow ||
         o.core != kGiVmapCore || o.in.delta_floor))
        throw Error(fmt::format(
            "{}: -K/--eps/--end-window/--core/--delta-floor apply when the V-map is built, not to "
            "a .vmap",
            o.in.path));
    o.in.progress = sampling_progress();
    Input in = load_input(o.in);
    print_notes(in.notes);
    camera = in.camera;
    if (!o.cam.scene.empty()) camera = load_scene(o.cam.scene).camera;
    if (in.vmap) {
        build_s = seconds_since(t0);
        what = fmt::format("V-map {} (loaded in {:.2f} s)", o.in.path, build_s);
        count_emitters(in.vmap->points(), o.in.path);  // its one error before any note
        // A map saved by `vmap build` at its defaults has no end window; the GI's own maps have
        // one (docs/gi.md "The end window"): say so, the map is still used as it is.
        const VisibilityParams& vp = in.vmap->visibility_params();
        if (vp.end_window != kGiVmapEndWindow || vp.K != kGiVmapK || vp.eps != kGiVmapEps)
            fmt::print(stderr,
                       "vmap gi: note: {} was built with -K {} --eps {} --end-window {}; the V-map "
                       "vmap gi builds itself has -K {} --eps {} --end-window {} (closer to exact "
                       "GI: docs/gi.md \"The end window\"; vmap build takes the same options)\n",
                       o.in.path, vp.K, vp.eps, vp.end_window, kGiVmapK, kGiVmapEps,
                       kGiVmapEndWindow);
        return std::move(*in.vmap);
    }
    count_emitters(in.points, o.in.path);
    BuildParams bp = gi_build_params(in.octree, o);
    bp.visibility.roughness = in.roughness;
    warn_if_long(o.in.path, in.points.size(), bp.octree);
    BuildStats st;
    VisibilityMap vm = build_vmap(std::move(in.points), bp, &st, o.in.path);
    build_s = seconds_since(t0);
    what = in.kind == InputKind::kCloud
               ? fmt::format("point cloud {}, V-map built on {} in {:.2f} s", o.in.path,
                             st.backend, build_s)
               : fmt::format("{} {} ({}), V-map built on {} in {:.2f} s",
                             in.kind == InputKind::kScene ? "scene" : "mesh", in.name, o.in.path,
                             st.backend, build_s);
    return vm;
}

// --compare-brute: each bounce (and the final gather) against the brute-force gather.
void compare_brute(const VisibilityMap& vm, const std::vector<std::vector<Vec3>>& hier,
                   int hier_bounces, bool gather) {
    std::vector<std::vector<Vec3>> ref;
    std::vector<double> brute_s;
    brute_force_radiosity(vm, int(hier.size()), &ref, &brute_s);
    for (size_t b = 0; b < hier.size(); ++b)
        fmt::print("compare {:2d}: {}, brute force {:.3f} s, relative RMS vs brute force {:.4f}\n",
                   b + 1, gather && int(b) == hier_bounces ? "final gather" : "hierarchical",
                   brute_s[b], relative_rms(hier[b], ref[b]));
}

// Hierarchical bounces (a fixed number, or until the last one added less than the tolerance of
// the power), then the final gather; progress and power per bounce on stdout.
std::vector<Vec3> solve(const VisibilityMap& vm, GiOptions& o) {
    o.gi.progress = stderr_progress();
    RadiositySolver solver(vm, o.gi);
    const GiStats& st0 = solver.stats();
    if (!st0.note.empty()) fmt::print("note:       {}\n", st0.note);
    fmt::print("backend:    {}\n", st0.backend);
    fmt::print(
        "refinement: {}, theta {}: {} interactions ({} node level, {} point to point), "
        "setup {:.3f} s\n",
        name_of(o.gi.refine), o.gi.theta, st0.interactions(), st0.node_interactions, st0.point_interactions,
        st0.seconds_setup);
    const bool gather = o.final_gather && (!o.bounces || *o.bounces > 0);
    const int fixed = o.bounces ? *o.bounces - (gather ? 1 : 0) : -1;
    const int limit = fixed >= 0 ? fixed : o.max_bounces;
    std::vector<std::vector<Vec3>> hier;
    const Vec3 p0 = total_power(vm, solver.radiosity());
    fmt::print("power:      emitted {:.6g} {:.6g} {:.6g} W\n", p0.x, p0.y, p0.z);
    double previous = double(p0.x) + p0.y + p0.z;
    {
        const ProgressCallback cb = stderr_progress();
        const auto t0 = std::chrono::steady_clock::now();
        auto report = [&](int done) {  // a bounce takes long enough to report each one
            const double s = seconds_since(t0);
            ProgressInfo p;
            p.stage = "gi bounces", p.done = uint64_t(done), p.total = uint64_t(limit);
            p.seconds = s, p.eta_seconds = done ? s / done * (limit - done) : 0;
            if (!cb(p)) throw Cancelled("gi: cancelled");
        };
        report(0);
        for (int b = 0; b < limit; ++b) {
            solver.bounce();
            report(b + 1);
            const auto B = solver.radiosity();
            if (o.compare) hier.push_back(B);
            const Vec3 p = total_power(vm, B);
            const double now = double(p.x) + p.y + p.z;
            fmt::print("bounce {:2d}:  {:.4f} s, leaving power {:.6g} {:.6g} {:.6g} W\n", b + 1,
                       solver.stats().seconds_bounce.back(), p.x, p.y, p.z);
            if (fixed < 0 && now > 0 && std::abs(now - previous) <= o.tolerance * now) {
                fmt::print("converged:  the last bounce added {:.2g} of the power (tolerance {})\n",
                           (now - previous) / now, o.tolerance);
                break;
            }
            previous = now;
        }
        report(limit);  // the end, also when it converged early
    }
    std::vector<Vec3> B = solver.radiosity();
    const int hier_bounces = solver.bounces_done();
    if (gather) {
        const auto t0 = Clock::now();
        B = solver.final_gather(o.gather_theta);
        const Vec3 p = total_power(vm, B);
        fmt::print(
            "gather:     final gather (bounce {}), theta {}: {:.3f} s, leaving power {:.6g} {:.6g} "
            "{:.6g} W\n",
            hier_bounces + 1, o.gather_theta, seconds_since(t0), p.x, p.y, p.z);
        hier.push_back(B);
    }
    if (o.compare) compare_brute(vm, hier, hier_bounces, gather);
    return B;
}

// Display colours: exposure x radiosity (linear, unclamped; the PNG clamps, the PFM does not).
std::vector<Vec3> display(const std::vector<Vec3>& B, float exposure) {
    std::vector<Vec3> c(B.size());
    for (size_t i = 0; i < B.size(); ++i) c[i] = B[i] * exposure;
    return c;
}

float auto_exposure(const VisibilityMap& vm, const std::vector<Vec3>& B) {
    std::vector<Vec3> unused;
    return tone_map(vm, B, 0.0f, unused);
}

// Appends the bytes of a trivially copyable value (the files below are little-endian, as the
// machines vmap runs on).
template <class T>
void put(std::string& out, const T& v) {
    out.append(reinterpret_cast<const char*>(&v), sizeof v);
}

// The image as PFM (little-endian float RGB, rows bottom-up), in radiosity units: the linear
// render divided by the exposure. Written atomically (vmap/files.h).
void write_pfm(const std::string& path, const Image& img, float exposure) {
    std::string out = fmt::format("PF\n{} {}\n-1.0\n", img.width, img.height);
    out.reserve(out.size() + size_t(12) * img.width * img.height);
    for (int y = img.height - 1; y >= 0; --y)
        for (int x = 0; x < img.width; ++x) {
            const Vec3 c = img.linear[size_t(y) * img.width + x] / exposure;
            put(out, c.x), put(out, c.y), put(out, c.z);
        }
    io::write_file_atomic(path, out);
}

// Points (input order) with their display colours (uchar sRGB) and linear radiosity as float
// properties radiosity_r/g/b (W/m^2), binary little-endian, written atomically.
void write_lit_ply(const std::string& path, const PointSet& pts, const std::vector<Vec3>& B,
                   float exposure) {
    // Positions in the input's coordinates: double when the input had its zero elsewhere.
    const std::array<double, 3>& o = pts.origin;
    const bool shifted = o != std::array<double, 3>{0, 0, 0};
    const char* xyz = shifted ? "double" : "float";
    std::string out = fmt::format(
        "ply\nformat binary_little_endian 1.0\ncomment vmap gi: display = sRGB(clamp({} x "
        "radiosity))\nelement vertex {}\nproperty {} x\nproperty {} y\nproperty "
        "{} z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty uchar "
        "red\nproperty uchar green\nproperty uchar blue\nproperty float radius\nproperty "
        "float radiosity_r\nproperty float radiosity_g\nproperty float radiosity_b\n"
        "end_header\n",
        exposure, pts.size(), xyz, xyz, xyz);
    out.reserve(out.size() + size_t(43) * pts.size());
    for (size_t i = 0; i < pts.size(); ++i) {
        const Vec3 p = pts.positions[i], n = pts.normals[i], b = B[i];
        if (shifted)
            for (double v : {p.x + o[0], p.y + o[1], p.z + o[2]}) put(out, v);
        else
            for (float v : {p.x, p.y, p.z}) put(out, v);
        for (float v : {n.x, n.y, n.z}) put(out, v);
        for (float c : {b.x, b.y, b.z}) put(out, linear_to_srgb8(c * exposure));
        for (float v : {pts.radii[i], b.x, b.y, b.z}) put(out, v);
    }
    io::write_file_atomic(path, out);
}

void write_outputs(const VisibilityMap& vm, const std::vector<Vec3>& B, float exposure,
                   const Camera& cam, GiOptions& o) {
    // Back to input order for the outputs.
    const PointSet out = points_in_input_order(vm);
    std::vector<Vec3> lit(B.size());
    for (size_t k = 0; k < B.size(); ++k) lit[vm.order()[k]] = B[k];
    if (!o.image.empty() || !o.pfm.empty()) {
        const auto t0 = Clock::now();
        o.render.keep_linear = !o.pfm.empty();
        const Image img = render_points(out, display(lit, exposure), cam, o.render);
        if (!o.image.empty()) write_png(o.image, img);
        if (!o.pfm.empty()) write_pfm(o.pfm, img, exposure);
        fmt::print("wrote:      {} ({}x{}, rendered in {:.2f} s)\n",
                   o.image.empty() ? o.pfm : o.image, img.width, img.height, seconds_since(t0));
        if (!o.image.empty() && !o.pfm.empty())
            fmt::print("wrote:      {} (linear radiosity, W/m^2)\n", o.pfm);
    }
    if (!o.ply.empty()) {
        write_lit_ply(o.ply, out, lit, exposure);
        fmt::print("wrote:      {} (display colours and linear radiosity_r/g/b)\n", o.ply);
    }
}

int run_gi(GiOptions& o) {
    if (o.in.path.empty()) o.in.path = default_scene_path();
    io::check_input_path(o.in.path);
    if (!o.cam.scene.empty()) io::check_input_path(o.cam.scene);
    if (o.reference) return run_gi_reference(o);
    if (o.image.empty()) o.image = std::filesystem::path(o.in.path).stem().string() + "-gi.png";
    check_output(o.ply, "--ply", {o.in.path, o.cam.scene, o.image});
    check_output(o.pfm, "--pfm", {o.in.path, o.cam.scene, o.image, o.ply});
    check_output(o.image, "-o", {o.in.path, o.cam.scene});
    const auto [width, height] = parse_size(o.cam.size, "--size");
    o.render.width = width, o.render.height = height;
    o.render.shade = false;                          // the light is in the radiosity
    apply_camera(o.cam, Camera{});  // bad camera options fail before the work
    std::string what;
    double build_s = 0;
    std::optional<Camera> scene_camera;
    const VisibilityMap vm = input_vmap(o, what, build_s, scene_camera);
    const PointSet& ps = vm.points();
    PointSet out = points_in_input_order(vm);  // input order and units, for the outputs
    // The camera (the default one frames the points' box, which the order does not change),
    // checked before the solve.
    Camera cam = apply_camera(o.cam, scene_camera ? *scene_camera : default_camera(out), out.origin);
    if (!o.image.empty() || !o.pfm.empty())
        check_camera(cam, "camera (--eye/--target/--up/--fov or the scene's camera)");
    const size_t emitters = count_emitters(ps, o.in.path);
    if (!ps.has_radii())
        throw Error(
            fmt::format("{}: points have no splat radii (needed for their areas)", o.in.path));

    fmt::print("input:      {}\n", what);
    fmt::print("points:     {} ({} emitting), {} nodes, {} leaves, {} links\n", ps.size(), emitters,
               vm.octree().num_nodes(), vm.octree().num_leaves(), vm.num_links());
    const std::vector<Vec3> B = solve(vm, o);
    const float exposure = o.exposure > 0 ? o.exposure : auto_exposure(vm, B);
    fmt::print(
        "tone map:   exposure {} (display = clamp(exposure x radiosity), sRGB; radiosity in "
        "W/m^2 per channel)\n",
        exposure);
    write_outputs(vm, B, exposure, cam, o);
    return 0;
}

}  // namespace

BuildParams gi_build_params(const OctreeParams& octree, const GiOptions& o) {
    BuildParams bp;
    bp.octree = octree;
    if (o.in.max_height) bp.octree.max_height = *o.in.max_height;
    if (o.in.leaf_points) bp.octree.leaf_points = *o.in.leaf_points;
    if (o.in.delta_floor) bp.octree.delta_floor = *o.in.delta_floor;
    bp.visibility.K = o.K;
    bp.visibility.eps = o.eps;
    bp.visibility.end_window = o.end_window;
    bp.visibility.core = o.core;
    bp.backend = o.gi.backend;
    bp.progress = stderr_progress();
    return bp;
}

namespace {

// The options, by group.
void add_output_options(CLI::App* gi, GiOptions* o) {
    gi->add_option("-o,--output", o->image, "PNG of the lit scene (default: <input name>-gi.png)");
    gi->add_option("--ply", o->ply,
                   "Write the points with their display colours and linear radiosity "
                   "(float radiosity_r/g/b, W/m^2) as PLY");
    gi->add_option("--pfm", o->pfm, "Write the picture as linear radiosity (PFM, W/m^2)");
}

void add_solver_options(CLI::App* gi, GiOptions* o) {
    gi->add_option("--bounces", o->bounces,
                   "Exactly this many gather steps after B = E, the final gather included (1: "
                   "direct light). Default: until converged (--tolerance)")
        ->check(CLI::Range(0, 10000));
    gi->add_option("--tolerance", o->tolerance,
                   "Converged when the last bounce added less than this fraction of the power")
        ->check(CLI::Range(1e-9, 1.0))
        ->capture_default_str();
    gi->add_option("--max-bounces", o->max_bounces, "At most this many bounces when converging")
        ->check(CLI::Range(1, 10000))
        ->capture_default_str();
    gi->add_flag("!--no-final-gather", o->final_gather,
                 "Skip the final per-point gather (the picture then shows the hierarchy's "
                 "receiver blocks)");
    gi->add_option("--gather-theta", o->gather_theta,
                   "Final gather: a node is seen as one source when farther than this x its size")
        ->check(CLI::PositiveNumber)
        ->capture_default_str();
    gi->add_option("--theta", o->gi.theta,
                   "Separation parameter: node-level transfer when the centres are more than "
                   "theta x (sum of the node sizes) apart; larger is finer and slower")
        ->check(CLI::Range(1e-3, 1e3))
        ->capture_default_str();
    cli::add_choice(gi, "--backend", o->gi.backend, "auto (GPU when present), cpu or cuda; for the V-map build and the bounces");
    cli::add_choice(gi, "--refine", o->gi.refine, "blocks: links summed into well-separated node pairs (fast); links: every "
                   "V-map link moves energy itself (exact visibility, slower)");
}

void add_picture_options(CLI::App* gi, GiOptions* o) {
    gi->add_option("--exposure", o->exposure,
                   "Display colour = clamp(exposure x radiosity) (linear, then sRGB); 0: "
                   "automatic (95th percentile of the lit points -> 0.8)")
        ->check(CLI::Range(0.0f, 1e9f))
        ->capture_default_str();
    add_camera_options(gi, o->cam);
    gi->add_option("--splat-scale", o->render.splat_scale, "Disc radius = splat radius x this")
        ->check(CLI::Range(0.01f, 100.f))
        ->capture_default_str();
    gi->add_option("--supersample", o->render.supersample, "s x s samples per pixel (1..4)")
        ->check(CLI::Range(1, 4))
        ->capture_default_str();
}

// Sampling and the V-map built here.
void add_build_options(CLI::App* gi, GiOptions* o) {
    gi->add_option("-K", o->K, "V-map built here: actual occluders that hide a leaf pair")
        ->check(k_check())
        ->capture_default_str();
    gi->add_option("--eps", o->eps,
                   "V-map built here: an occluder's plane must cut the segment at t in (eps, "
                   "1 - eps)")
        ->check(eps_check())
        ->capture_default_str();
    gi->add_option("--end-window", o->end_window,
                   "V-map built here: " + end_window_help() +
                       " (the GI's default is 2, vmap build's 0: docs/gi.md \"The end window\")")
        ->check(end_window_check())
        ->capture_default_str();
    gi->add_option("--core", o->core,
                   "V-map built here: a crossing within this share of an occluder's disc radius "
                   "from its centre counts as K occluders")
        ->check(CLI::Range(0.f, VisibilityParams::kCoreLimit))
        ->capture_default_str();
}

void add_reference_options(CLI::App* gi, GiOptions* o) {
    gi->add_flag("--compare-brute", o->compare,
                 "Also run the brute-force gather (every visible point pair) and print the "
                 "relative RMS difference per bounce (small scenes)");
    gi->add_flag("--reference", o->reference,
                 "Measure the GI against a path-traced reference over the scene's triangles "
                 "(Embree) at sample points and print the error table (a scene file, or a .vmap of "
                 "it with --scene; with -o: the picture reference | vmap gi | error)");
    gi->add_option("--ref-points", o->ref_points,
                   "Reference: this many non-emitting points, and as many model points")
        ->check(CLI::Range(size_t(1), size_t(1000000)))
        ->capture_default_str();
    gi->add_option("--ref-samples", o->ref.samples, "Reference: paths per point")
        ->check(CLI::Range(2u, 100000000u))
        ->capture_default_str();
    gi->add_option("--ref-seed", o->ref.seed, "Reference: seed (points and paths)")
        ->capture_default_str();
    gi->add_option("--ref-bounces", o->ref.bounces,
                   "Reference: the table shows 1..this many bounces, then converged")
        ->check(CLI::Range(1, 100))
        ->capture_default_str();
    gi->add_option("--ref-out", o->ref_out,
                   "Reference: write the sample points, the reference with its standard errors "
                   "and each method's values (CSV)");
    gi->add_flag("!--no-brute", o->brute, "Reference: leave out the brute-force gather");
    gi->add_option("--ref-picture-samples", o->ref_picture_samples,
                   "Reference with -o: paths per point for the side-by-side picture (reference "
                   "| vmap gi | error) at every point")
        ->check(CLI::Range(2u, 1000000u))
        ->capture_default_str();
}

}  // namespace

Command add_gi_command(CLI::App& app) {
    auto o = std::make_shared<GiOptions>();
    auto* gi = app.add_subcommand(
        "gi", "Diffuse global illumination over the V-map (hierarchical radiosity; paper §6.3)");
    add_input_options(gi, o->in,
                      "Scene file (.json), mesh or point cloud (V-map built on the fly) or .vmap "
                      "file. Default: scenes/cornell-bunny.json");
    GiOptions* p = o.get();
    add_output_options(gi, p);
    add_solver_options(gi, p);
    add_picture_options(gi, p);
    add_build_options(gi, p);
    add_reference_options(gi, p);
    return {gi, [o] { return run_gi(*o); }, true};
}

}  // namespace vmap::cli
