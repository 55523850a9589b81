// Option parsing shared by the subcommands in apps/ (apps/commands.h).
#include <fmt/format.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <sstream>

#include "apps/commands.h"
#include "vmap/error.h"
#include "vmap/files.h"
#include "vmap/octree.h"
#include "vmap/scene.h"

namespace vmap::cli {

CLI::Validator max_height_check() {
    return checked_by(&OctreeParams::max_height,
                      fmt::format("INT in [1 - {}]", OctreeParams::kHeightLimit));
}
CLI::Validator leaf_points_check() {
    return checked_by(&OctreeParams::leaf_points,
                      fmt::format("INT in [1 - {}]", OctreeParams::kLeafPointsLimit));
}

CLI::Validator k_check() {
    return checked_by(&VisibilityParams::K,
                      fmt::format("INT in [1 - {}]", VisibilityParams::kKLimit));
}
CLI::Validator eps_check() {
    return checked_by(&VisibilityParams::eps,
                      fmt::format("FLOAT in [0 - {})", VisibilityParams::kEpsLimit));
}
CLI::Validator end_window_check() {
    return checked_by(&VisibilityParams::end_window,
                      fmt::format("FLOAT in [0 - {}]", VisibilityParams::kEndWindowLimit));
}
std::string end_window_help() {
    return "An occluder counts only when its plane is cut farther than this many of the nearer "
           "end's disc radii from that end (0: no such window)";
}

void add_predicate_options(CLI::App* app, VisibilityParams& vp) {
    using P = VisibilityParams;
    const std::string tol = fmt::format("FLOAT in [0 - {})", P::kTolLimit);
    app->add_option("-K", vp.K, "Actual occluders that make a leaf pair invisible")
        ->check(k_check())
        ->capture_default_str();
    app->add_option("--eps", vp.eps, "Occluder plane must cut the segment at t in (eps, 1-eps)")
        ->check(eps_check())
        ->capture_default_str();
    app->add_option("--facing-tol", vp.facing_tol, "Facing test: n.d > tol |d|")
        ->check(checked_by(&P::facing_tol, tol))
        ->capture_default_str();
    app->add_option("--parallel-tol", vp.parallel_tol,
                    "Occluder planes with |n.d| <= tol |d| are ignored")
        ->check(checked_by(&P::parallel_tol, tol))
        ->capture_default_str();
    app->add_option("--end-window", vp.end_window, end_window_help())
        ->check(end_window_check())
        ->capture_default_str();
    app->add_option("--core", vp.core,
                    "A crossing within this share of an occluder's disc radius from its centre "
                    "counts as K occluders (0: every crossing counts one; no core counts where "
                    "the roughness is above 0)")
        ->check(checked_by(&P::core, fmt::format("FLOAT in [0 - {}]", P::kCoreLimit)))
        ->capture_default_str();
}

void add_input_options(CLI::App* app, InputOptions& in, const std::string& help) {
    const OctreeParams fallback;
    app->add_option("input", in.path, help);
    app->add_flag("--as-points", in.as_points,
                  "Take a mesh file's vertices as a point cloud instead of sampling its faces");
    app->add_option("--points", in.points,
                    "Scene and mesh files: sample this many points instead of the scene's number")
        ->check(CLI::Range(uint64_t(1), uint64_t(50000000)));
    app->add_option("--seed", in.seed, "Scene and mesh files: the sampling seed instead of the scene's");
    std::map<std::string, SamplePattern> patterns;
    for (const std::string& n : names_of<SamplePattern>())
        patterns.emplace(n, parse<SamplePattern>(n, "--sampling"));
    app->add_option("--sampling", in.pattern,
                    "Scene and mesh files: blue-noise (uniform candidates thinned so samples keep "
                    "about the spacing apart) or uniform (independent points); default: the "
                    "scene's sampling.pattern, else blue-noise")
        ->transform(CLI::CheckedTransformer(patterns));
    app->add_option("--max-height", in.max_height,
                    fmt::format("Deepest octree level (root = 0) of a V-map built here; default: "
                                "the scene's octree.max_height, else {}",
                                fallback.max_height))
        ->check(max_height_check());
    app->add_option("--leaf-points", in.leaf_points,
                    fmt::format("Split the octree's nodes with more points than this (a V-map "
                                "built here); default: the scene's octree.leaf_points, else {}",
                                fallback.leaf_points))
        ->check(leaf_points_check());
    app->add_option("--delta-floor", in.delta_floor,
                    fmt::format("A V-map built here: a leaf's occluder disc is at least this many "
                                "splat radii wide; default: the scene's octree.delta_floor, else "
                                "{} for blue-noise samples and {} for uniform samples and point "
                                "clouds",
                                OctreeParams::kEvenDeltaFloor, OctreeParams::kDefaultDeltaFloor))
        ->check(checked_by(&OctreeParams::delta_floor,
                           fmt::format("FLOAT in [0 - {}]", OctreeParams::kDeltaFloorLimit)));
    app->add_option("--roughness", in.roughness,
                    "A V-map built here: an occluder of a point's own sheet raised above it by "
                    "less than this (the input's units: a scan's noise) does not occlude; "
                    "default: from a point cloud's measured noise, 0 for scene and mesh files")
        ->check(checked_by(&VisibilityParams::roughness, "FLOAT >= 0"));
}

void add_camera_options(CLI::App* app, CameraOptions& c) {
    app->add_option("--scene", c.scene, "Take the camera from this scene file (for .vmap input)");
    app->add_option("--eye", c.eye, "Camera position x,y,z");
    app->add_option("--target", c.target, "Camera target x,y,z");
    app->add_option("--up", c.up, "Camera up vector x,y,z (default 0,1,0)");
    app->add_option("--fov", c.fov, "Vertical field of view, degrees")
        ->check(CLI::Range(1.f, 179.f));
    app->add_option("--size", c.size, "Image size WxH")->capture_default_str();
}

Camera apply_camera(const CameraOptions& c, Camera base, const std::array<double, 3>& origin) {
    if (!c.eye.empty()) base.eye = parse_position(c.eye, "--eye", origin);
    if (!c.target.empty()) base.target = parse_position(c.target, "--target", origin);
    if (!c.up.empty()) base.up = parse_vec3(c.up, "--up");
    if (c.fov) base.fov_y_deg = *c.fov;
    return base;
}

bool sampled_input(const std::string& path, bool as_points) {
    try {
        return is_scene_input(path, as_points);
    } catch (const Error&) {
        return true;
    }
}

void print_notes(const std::vector<std::string>& notes) {
    for (const std::string& note : notes) fmt::print(stderr, "note:       {}\n", note);
}

namespace {

// "x,y,z" as doubles; throws for anything but three finite numbers.
std::array<double, 3> parse_triple(const std::string& text, const std::string& option) {
    std::array<double, 3> v{};
    size_t at = 0;
    for (int k = 0; k < 3; ++k) {
        const size_t end = k < 2 ? text.find(',', at) : text.size();
        if (end == std::string::npos) break;
        const std::string part = text.substr(at, end - at);
        char* stop = nullptr;
        v[k] = part.empty() || std::isspace(static_cast<unsigned char>(part[0]))
                   ? NAN
                   : std::strtod(part.c_str(), &stop);
        if (stop != part.c_str() + part.size() || !std::isfinite(v[k]))
            throw UsageError(
                fmt::format("{}: '{}' is not x,y,z (three finite numbers)", option, text));
        at = end + 1;
        if (k == 2) return v;
    }
    throw UsageError(fmt::format("{}: '{}' is not x,y,z (three finite numbers)", option, text));
}

}  // namespace

std::array<double, 3> file_position(Vec3 q, const std::array<double, 3>& origin) {
    return {q.x + origin[0], q.y + origin[1], q.z + origin[2]};
}

std::string position_text(Vec3 q, const std::array<double, 3>& origin) {
    if (origin == std::array<double, 3>{0, 0, 0}) return fmt::format("{}, {}, {}", q.x, q.y, q.z);
    const std::array<double, 3> f = file_position(q, origin);
    return fmt::format("{}, {}, {}", f[0], f[1], f[2]);
}

Vec3 parse_vec3(const std::string& text, const std::string& option) {
    return parse_position(text, option, {});
}

Vec3 parse_position(const std::string& text, const std::string& option,
                    const std::array<double, 3>& origin) {
    std::array<double, 3> v = parse_triple(text, option);
    for (int a = 0; a < 3; ++a) v[a] -= origin[a];
    for (double c : v)
        if (std::fabs(c) > std::numeric_limits<float>::max())
            throw UsageError(
                fmt::format("{}: '{}': {} is beyond the float range (3.4e38)", option, text, c));
    return {float(v[0]), float(v[1]), float(v[2])};
}

Vec3 parse_direction(const std::string& text, const std::string& option) {
    const std::array<double, 3> v = parse_triple(text, option);
    const double big = std::max({std::fabs(v[0]), std::fabs(v[1]), std::fabs(v[2])});
    if (!(big > 0)) throw UsageError(fmt::format("{}: '{}': the direction is zero", option, text));
    const double x = v[0] / big, y = v[1] / big, z = v[2] / big;
    const double len = std::sqrt(x * x + y * y + z * z);
    return {float(x / len), float(y / len), float(z / len)};
}

std::pair<int, int> parse_size(const std::string& text, const std::string& option) {
    int w = 0, h = 0;
    char x = 0, extra = 0;
    if (std::sscanf(text.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X'))
        throw UsageError(fmt::format("{}: '{}' is not WxH (e.g. 800x600)", option, text));
    if (w < 1 || h < 1 || w > 16384 || h > 16384)
        throw UsageError(fmt::format("{}: {}x{} out of range (1..16384 each)", option, w, h));
    return {w, h};
}

double estimated_leaf_pairs(uint64_t points, const OctreeParams& op) {
    // Measured: leaves hold about half of leaf_points on average (docs/results.md: the bunny's
    // 40,000 points at leaf_points 4 make 19,225 leaves); at most 8^max_height of them.
    const double cells = std::pow(8.0, op.max_height);
    const double leaves =
        std::max(1.0, std::min(cells, points / std::max(1.0, 0.5 * op.leaf_points)));
    return leaves * (leaves - 1) / 2;
}

void warn_if_long(const std::string& what, uint64_t points, const OctreeParams& op) {
    const double pairs = estimated_leaf_pairs(points, op);
    const int cores = std::max<int>(
        1, std::min<size_t>(
               tbb::this_task_arena::max_concurrency(),
               tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism)));
    // Rates from docs/results.md: 4.5e7 leaf pairs/s per CPU core (the packet walk with node
    // decisions; the CPU backend's expected_pairs_per_second, src/visibility/host_backend.h, whose
    // estimate the build's first progress report then gives: the two agree), 2e9/s on an
    // H100/H200.
    const double cpu_s = pairs / (4.5e7 * cores), gpu_s = pairs / 2e9;
    if (cpu_s < 600) return;
    auto span = [](double s) {
        return s < 120         ? fmt::format("{:.0f} s", s)
               : s < 3600      ? fmt::format("{:.0f} min", s / 60)
               : s < 86400 * 2 ? fmt::format("{:.1f} h", s / 3600)
                               : fmt::format("{:.0f} days", s / 86400);
    };
    fmt::print(stderr,
               "vmap: warning: {}: {} points at max_height {}, leaf_points {} make about {:.2g} "
               "leaf pairs: about {} on {} CPU core(s) ({} on a GPU); lower --points or "
               "--max-height, or raise --leaf-points, for a shorter run\n",
               what, points, op.max_height, op.leaf_points, pairs, span(cpu_s), cores, span(gpu_s));
}

void harden_options(CLI::App& app) {
    const CLI::Validator finite(
        [](std::string& text) {
            char* stop = nullptr;
            const double v = std::strtod(text.c_str(), &stop);
            if (stop != text.c_str() && !std::isfinite(v))
                return fmt::format("'{}' is not a finite number", text);
            return std::string();
        },
        "", "finite");
    const CLI::Validator non_negative(
        [](std::string& text) {
            const size_t k = text.find_first_not_of(" \t");
            if (k != std::string::npos && text[k] == '-')
                return fmt::format("'{}' is negative; expected a count or a non-negative number",
                                   text);
            return std::string();
        },
        "", "non-negative");
    for (CLI::Option* opt : app.get_options()) {
        const std::string type = opt->get_type_name();
        // transform() puts the check first, so it runs before the option's own range check,
        // which NaN passes (every comparison with NaN is false) and "-1" wraps around.
        if (type.rfind("FLOAT", 0) == 0) opt->transform(finite);
        if (type.rfind("UINT", 0) == 0) opt->transform(non_negative);
    }
    for (CLI::App* sub : app.get_subcommands({})) harden_options(*sub);
}

void check_output(const std::string& path, const char* option,
                  const std::vector<std::string>& inputs) {
    if (path.empty()) return;
    for (const std::string& in : inputs)
        if (!in.empty() && io::same_file(path, in))
            throw UsageError(
                fmt::format("{}: {}: is the input {}; it would be overwritten", path, option, in));
    io::check_output_path(path, option);
}

Verbosity& verbosity() {
    static Verbosity v = Verbosity::kNormal;
    return v;
}

int& threads() {
    static int n = 0;
    return n;
}

std::string format_duration(double s) {
    if (!(s >= 0) || s > 1e9) return "a very long time";
    const auto t = static_cast<uint64_t>(s + 0.5);
    if (s < 10) return fmt::format("{:.1f} s", s);
    if (t < 60) return fmt::format("{} s", t);
    if (t < 3600) return fmt::format("{} min {} s", t / 60, t % 60);
    return fmt::format("{} h {} min", t / 3600, (t % 3600) / 60);
}

ProgressCallback stderr_progress() {
    const bool quiet = verbosity() == Verbosity::kQuiet;
    const bool moving = !quiet && isatty(STDERR_FILENO) == 1;
    return [quiet, moving](const ProgressInfo& p) {
        if (quiet) return true;
        if (p.done == 0 && p.seconds < 1e-3) {
            std::string line = fmt::format("{}: {} to do", p.stage, p.total);
            if (*p.backend) line += fmt::format(" on {}", p.backend);
            if (p.estimate_seconds > 0)
                line += fmt::format(", about {}", format_duration(p.estimate_seconds));
            fmt::print(stderr, "{}\n", line);
            if (*p.note) fmt::print(stderr, "note: {}\n", p.note);
            if (p.estimate_seconds > 3600)
                fmt::print(stderr,
                           "warning: this is estimated to take {}; Ctrl-C stops it (fewer "
                           "--points or a lower --max-height make it smaller)\n",
                           format_duration(p.estimate_seconds));
            return true;
        }
        if (!moving) return true;
        if (p.done >= p.total) {
            fmt::print(stderr, "\r\033[K");
        } else {
            const double f = p.total ? double(p.done) / double(p.total) : 1.0;
            fmt::print(stderr, "\r\033[K{}: {:5.1f}%  {} elapsed, about {} left", p.stage, 100 * f,
                       format_duration(p.seconds),
                       p.done ? format_duration(p.eta_seconds) : std::string("?"));
        }
        std::fflush(stderr);
        return true;
    };
}

ProgressCallback sampling_progress() {
    constexpr uint64_t kFrom = 500'000;
    return [cb = stderr_progress()](const ProgressInfo& p) { return p.total < kFrom || cb(p); };
}

}  // namespace vmap::cli
