// `vmap render`: pictures of a scene, a point cloud or a .vmap file.
//
// Input: a scene (.json) or a mesh file (sampled; --points/--seed override), a point cloud or a
// .vmap file (its points; the camera from --scene, else the default). Modes:
//   albedo    the points' colours, unshaded
//   shaded    colours x (ambient + |n.v|)
//   visible   paper Fig. 9: points visible from an eye point purple, the eye cyan, the rest
//             dimmed; the V-map is the .vmap given, or built on the fly (scene/cloud)
//   heights   paper Fig. 11: `visible` for the V-maps built at each of --heights, side by side
//   decided   where V-map construction stays undecided: each point coloured by the share of its
//             leaf's leaf pairs that were walked (dark blue: all decided at node level; yellow:
//             all walked); builds the V-map
// --ply writes the same colours (without the camera-dependent shading) as a coloured PLY.
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <memory>

#include "apps/commands.h"
#include "vmap/error.h"
#include "vmap/files.h"
#include "vmap/io.h"
#include "vmap/query.h"
#include "vmap/render.h"
#include "vmap/scene.h"

namespace vmap::cli {
namespace {

namespace fs = std::filesystem;

struct RenderArgs {
    InputOptions in;  // the input and its overrides (vmap/input.h)
    CameraOptions cam;
    std::string output, ply, mode = "shaded", eye_pos;
    std::optional<uint32_t> eye_id;
    std::vector<int> heights{7, 9};
    Backend backend = Backend::kAuto;
    int time_runs = 0;
    RenderOptions opt;
};

// What was loaded: points in input order, and the V-map when the input was one.
struct Source {
    PointSet points;
    std::optional<VisibilityMap> vm;
    std::optional<Camera> camera;
    OctreeParams octree;
    float roughness = 0;  // Input::roughness
};

Source load_source(const RenderArgs& a) {
    InputOptions io = a.in;
    io.progress = sampling_progress();
    Input in = load_input(io);
    print_notes(in.notes);
    Source s;
    s.octree = in.octree;
    s.roughness = in.roughness;
    s.camera = in.camera;
    if (in.vmap) {
        s.points = points_in_input_order(*in.vmap);
        s.vm = std::move(in.vmap);
    } else {
        s.points = std::move(in.points);
    }
    if (!a.cam.scene.empty()) s.camera = load_scene(a.cam.scene).camera;
    return s;
}

Camera make_camera(const RenderArgs& a, const Source& s) {
    return apply_camera(a.cam, s.camera ? *s.camera : default_camera(s.points), s.points.origin);
}

VisibilityMap build_at(const RenderArgs& a, const Source& s, std::optional<int> height,
                       BuildStats* stats = nullptr) {
    BuildParams bp;
    bp.octree = s.octree;  // the scene's or the map's, with --max-height/--leaf-points
    bp.visibility.roughness = s.roughness;
    if (height) bp.octree.max_height = *height;
    bp.backend = a.backend;
    bp.progress = stderr_progress();
    warn_if_long(a.in.path, s.points.size(), bp.octree);
    BuildStats st;
    VisibilityMap vm = build_vmap(s.points, bp, &st, a.in.path);
    fmt::print("built:      V-map at max_height {} (height {}): {} links, {:.2f} s on {}\n",
               bp.octree.max_height, vm.octree().height(), vm.num_links(), st.seconds_total,
               st.backend);
    if (stats) *stats = std::move(st);
    return vm;
}

// Per input point: the share of its leaf's pairs that were walked, dark blue (0) to yellow (1).
std::vector<Vec3> decided_colors(const VisibilityMap& vm, const BuildStats& st) {
    const Octree& t = vm.octree();
    const double others = std::max(1, t.num_leaves() - 1);
    std::vector<Vec3> c(vm.points().size());
    for (size_t i = 0; i < c.size(); ++i) {
        const int32_t leaf = t.leaf_of_point(vm.inverse()[i]);
        const float f = float(st.leaf_walked[leaf] / others);
        c[i] = Vec3{0.05f, 0.05f, 0.35f} * (1 - f) + Vec3{1.f, 0.85f, 0.1f} * f;
    }
    return c;
}

uint32_t pick_eye(const RenderArgs& a, const Source& s) {
    if (a.eye_id) {
        if (*a.eye_id >= s.points.size())
            throw Error(fmt::format("{}: --eye-id: point id {} out of range ({} points)", a.in.path,
                                    *a.eye_id, s.points.size()));
        return *a.eye_id;
    }
    const Vec3 p = parse_position(a.eye_pos, "--eye-pos", s.points.origin);
    return nearest_point(s.points, p);
}

std::string with_suffix(const std::string& path, const std::string& suffix) {
    fs::path p(path);
    return (p.parent_path() / (p.stem().string() + suffix + p.extension().string())).string();
}

// --time N: the splatting alone (albedo colours in every mode: the mode only changes colours,
// not the work; no V-map build, no PNG encoding) N times after the run above served as warm-up;
// median and spread, with the work done.
void time_render(const RenderArgs& a, const Source& s, const Camera& cam) {
    std::vector<Vec3> colors = s.points.colors;
    if (colors.empty()) colors.assign(s.points.size(), Vec3{0.8f, 0.8f, 0.8f});
    std::vector<double> secs;
    RenderStats st;
    for (int r = 0; r < a.time_runs; ++r) {
        RenderStats one;
        const auto t0 = std::chrono::steady_clock::now();
        render_points(s.points, colors, cam, a.opt, &one);
        secs.push_back(
            std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
        st = one;
    }
    std::sort(secs.begin(), secs.end());
    fmt::print(
        "render:     {:.3f} s median [{:.3f}-{:.3f}] over {} runs; {}x{} at {}x{} supersampling, "
        "{} points, {} discs on screen, {} tile refs, {} fragments ({:.3g} fragments/s)\n",
        secs[secs.size() / 2], secs.front(), secs.back(), secs.size(), a.opt.width, a.opt.height,
        a.opt.supersample, a.opt.supersample, s.points.size(), st.discs, st.tile_refs, st.fragments,
        st.fragments / secs[secs.size() / 2]);
}

// The usage errors found after parsing (exit 2): a message on stderr, true.
bool usage_error(const RenderArgs& a) {
    const bool needs_eye = a.mode == "visible" || a.mode == "heights";
    if ((a.in.points || a.in.seed) && !a.in.path.empty() &&
        (has_extension(a.in.path, ".vmap") || !sampled_input(a.in.path, a.in.as_points))) {
        fmt::print(stderr,
                   "vmap render: --points/--seed apply to scene and mesh files, not to {}\n",
                   a.in.path);
        return true;
    }
    if (needs_eye && !a.eye_id && a.eye_pos.empty()) {
        fmt::print(stderr, "vmap render: --mode {} needs --eye-id I or --eye-pos x,y,z\n", a.mode);
        return true;
    }
    if (!needs_eye && (a.eye_id || !a.eye_pos.empty())) {
        fmt::print(stderr, "vmap render: --eye-id/--eye-pos apply to --mode visible|heights\n");
        return true;
    }
    return false;
}

// Every option checked and the outputs' paths settled before any work, so a typo costs nothing.
void check_render_options(RenderArgs& a) {
    const auto [w, h] = parse_size(a.cam.size, "--size");
    a.opt.width = w;
    a.opt.height = h;
    if (!a.eye_pos.empty()) parse_vec3(a.eye_pos, "--eye-pos");
    if (a.mode == "heights" && a.heights.empty()) throw Error("--heights: give at least one");
    std::string& input = a.in.path;
    if (input.empty()) input = default_scene_path();
    if (a.output.empty()) a.output = fs::path(input).stem().string() + "-" + a.mode + ".png";
    io::check_input_path(input);
    if (!a.cam.scene.empty()) io::check_input_path(a.cam.scene);
    check_output(a.output, "-o", {input, a.cam.scene});
    check_output(a.ply, "--ply", {input, a.cam.scene, a.output});
}

// The picture of the chosen mode (and its PLY when asked for).
Image render_mode(RenderArgs& a, Source& s, const Camera& cam) {
    Image img;
    if (a.mode == "albedo" || a.mode == "shaded") {
        std::vector<Vec3> colors = s.points.colors;
        if (colors.empty()) colors.assign(s.points.size(), Vec3{0.8f, 0.8f, 0.8f});
        img = render_points(s.points, colors, cam, a.opt);
        if (!a.ply.empty()) write_colored_ply(a.ply, s.points, colors);
    } else if (a.mode == "visible") {
        const uint32_t eye = pick_eye(a, s);
        if (!s.vm) s.vm = build_at(a, s, std::nullopt);
        img = render_visible(*s.vm, eye, cam, a.opt);
        const auto set = s.vm->visible_set(eye);
        const Vec3 e = s.points.positions[eye];
        const std::array<double, 3>& o = s.points.origin;
        fmt::print("eye:        point {} at ({:.4f}, {:.4f}, {:.4f}): {} of {} points visible\n",
                   eye, e.x + o[0], e.y + o[1], e.z + o[2], set.size(), s.points.size());
        if (!a.ply.empty()) write_colored_ply(a.ply, s.points, visible_colors(*s.vm, eye));
    } else if (a.mode == "decided") {
        BuildStats st;
        const VisibilityMap vm = build_at(a, s, std::nullopt, &st);
        const std::vector<Vec3> colors = decided_colors(vm, st);
        a.opt.shade = false;
        img = render_points(s.points, colors, cam, a.opt);
        fmt::print("decided:    {} of {} leaf pairs walked ({:.1f}%), construction {}\n",
                   st.leaf_pairs_walked, st.leaf_pairs,
                   100.0 * st.leaf_pairs_walked / std::max<uint64_t>(1, st.leaf_pairs),
                   st.construction);
        if (!a.ply.empty()) write_colored_ply(a.ply, s.points, colors);
    } else {  // heights
        const uint32_t eye = pick_eye(a, s);
        std::vector<Image> panels;
        std::vector<std::vector<Vec3>> colors;
        for (int ht : a.heights) {
            const VisibilityMap vm = build_at(a, s, ht);
            panels.push_back(render_visible(vm, eye, cam, a.opt));
            const uint8_t white[3] = {255, 255, 255};
            const int scale = std::max(1, panels.back().height / 250);
            draw_text(panels.back(), 6 * scale, 6 * scale, fmt::format("height {}", ht), scale,
                      white);
            if (!a.ply.empty()) colors.push_back(visible_colors(vm, eye));
            fmt::print("height {}:   {} of {} points visible from {}\n", ht,
                       vm.visible_set(eye).size(), s.points.size(), eye);
        }
        img = side_by_side(panels);
        for (size_t k = 0; k < colors.size(); ++k)
            write_colored_ply(with_suffix(a.ply, fmt::format("-h{}", a.heights[k])), s.points,
                              colors[k]);
    }
    return img;
}

int run_render(RenderArgs& a) {
    if (usage_error(a)) return 2;
    check_render_options(a);
    Source s = load_source(a);
    const Camera cam = make_camera(a, s);
    check_camera(cam, "camera (--eye/--target/--up/--fov or the scene's camera)");
    a.opt.shade = a.mode != "albedo";
    const auto t0 = std::chrono::steady_clock::now();
    const Image img = render_mode(a, s, cam);
    if (a.time_runs > 0) time_render(a, s, cam);
    write_png(a.output, img);
    fmt::print("camera:     eye ({}, {}, {}) target ({}, {}, {}) fov {}\n", cam.eye.x, cam.eye.y,
               cam.eye.z, cam.target.x, cam.target.y, cam.target.z, cam.fov_y_deg);
    fmt::print("wrote:      {} ({}x{}, {} points, {:.2f} s)\n", a.output, img.width, img.height,
               s.points.size(), seconds_since(t0));
    if (!a.ply.empty() && a.mode != "heights") fmt::print("wrote:      {}\n", a.ply);
    return 0;
}

}  // namespace

Command add_render_command(CLI::App& app) {
    auto a = std::make_shared<RenderArgs>();
    auto* c = app.add_subcommand("render", "Render a scene, point cloud or V-map to PNG");
    add_input_options(c, a->in,
                      "Scene (.json), mesh (area-sampled), point cloud or .vmap file. Default: "
                      "scenes/cornell-bunny.json");
    c->add_option("-o,--output", a->output, "PNG file (default: <input name>-<mode>.png)");
    c->add_option("--mode", a->mode,
                  "albedo | shaded | visible (Fig. 9) | heights (Fig. 11: visible at each of "
                  "--heights, side by side) | decided (leaf pairs walked per leaf in building "
                  "the V-map)")
        ->check(CLI::IsMember({"albedo", "shaded", "visible", "heights", "decided"}))
        ->capture_default_str();
    c->add_option("--ply", a->ply,
                  "Also write the points with the mode's colours as a PLY (heights: one file per "
                  "height, -h<H> before the extension)");
    add_camera_options(c, a->cam);
    c->add_option("--eye-id", a->eye_id, "visible/heights: the eye is input point I");
    c->add_option("--eye-pos", a->eye_pos,
                  "visible/heights: the eye is the surface point nearest x,y,z");
    c->add_option("--heights", a->heights, "heights: octree max heights, e.g. 7,9")
        ->delimiter(',')
        ->check(max_height_check());
    cli::add_choice(c, "--backend", a->backend, "Backend when building: auto, cpu or cuda");
    c->add_option("--splat-scale", a->opt.splat_scale, "Disc radius = splat radius x this")
        ->check(CLI::Range(0.01f, 100.f))
        ->capture_default_str();
    c->add_option("--supersample", a->opt.supersample, "s x s samples per pixel (1..4)")
        ->check(CLI::Range(1, 4))
        ->capture_default_str();
    c->add_option("--time", a->time_runs,
                  "Also time the render N more times (median, spread, work) for docs/results.md")
        ->check(CLI::Range(1, 1000));
    return {c, [a] { return run_render(*a); }, true};
}

}  // namespace vmap::cli
