// Subcommands defined outside apps/main.cpp. Each add_* function declares its options on `app`
// and returns the subcommand with the function that runs it after parsing; main() calls run()
// inside its error handling (vmap::Error -> exit 1), and a run() returning 2 is a usage error.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <nlohmann/json.hpp>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "vmap/progress.h"
#include "vmap/camera.h"
#include "vmap/error.h"
#include "vmap/input.h"
#include "vmap/octree.h"
#include "vmap/options.h"
#include "vmap/vec.h"
#include "vmap/visibility.h"
#include "vmap/vmap.h"

namespace vmap::cli {

// A usage error found after parsing (main exits 2 for it, 1 for other vmap::Errors).
class UsageError : public Error {
  public:
    using Error::Error;
};

// A subcommand: what add_*_command declared, and what runs it once parsed. `summary` says its
// stdout is a summary, not the answers asked for (-q silences it).
struct Command {
    CLI::App* app = nullptr;
    std::function<int()> run;
    bool summary = false;
};

// Every subcommand is registered the same way: main() calls these in turn.
Command add_build_command(CLI::App& app);        // apps/build_cmd.cpp
Command add_info_command(CLI::App& app);         // apps/info_cmd.cpp
Command add_query_command(CLI::App& app);        // apps/query_cmd.cpp
Command add_render_command(CLI::App& app);       // apps/render_cmd.cpp
Command add_gi_command(CLI::App& app);           // apps/gi_cmd.cpp
Command add_validate_command(CLI::App& app);     // apps/validate_cmd.cpp
Command add_view_command(CLI::App& app);         // apps/view_cmd.cpp
// The benchmarks' programs are bench/<name>.cpp, on the public headers only, each with its
// options and run function in bench/<name>.h; their subcommands are registered here as the
// others are.
Command add_bench_command(CLI::App& app);        // apps/bench_cmd.cpp (bench/bench.cpp)
Command add_bench_query_command(CLI::App& app);  // apps/bench_query_cmd.cpp (bench/query_bench.cpp)
Command add_bench_gi_command(CLI::App& app);     // apps/bench_gi_cmd.cpp (bench/gi_bench.cpp)

// What a V-map holds (apps/map_summary.cpp, for build and info): the links per octree level
// (each link once, at its first end's level), the level table, the parameters as two lines or
// as JSON.
std::vector<uint64_t> links_per_level(const VisibilityMap& vm);
void print_tree_summary(const VisibilityMap& vm);
void print_params(const VisibilityMap& vm);
nlohmann::json params_json(const VisibilityMap& vm);

// Option values (usage errors, exit 2, for a malformed one):
// "x,y,z" -> Vec3; throws UsageError naming `option` for anything else (or non-finite values).
Vec3 parse_vec3(const std::string& text, const std::string& option);
// A position "x,y,z" in the input's coordinates, relative to `origin` (PointSet::origin),
// subtracted in double.
Vec3 parse_position(const std::string& text, const std::string& option,
                    const std::array<double, 3>& origin);
// "WxH" -> (W, H), each 1..16384; throws UsageError naming `option`.
// "dx,dy,dz" -> the unit vector along it (normalised in double, so tiny and huge components
// work); throws UsageError naming `option` for a zero or non-finite direction.
Vec3 parse_direction(const std::string& text, const std::string& option);
std::pair<int, int> parse_size(const std::string& text, const std::string& option);

// An option taking one of E's names (vmap/options.h: backend, occluders, construction, refine),
// into `target`, whose current value is the default shown.
template <class E>
CLI::Option* add_choice(CLI::App* app, const std::string& flag, E& target,
                        const std::string& help) {
    std::map<std::string, E> names;
    for (const std::string& n : names_of<E>()) names.emplace(n, parse<E>(n, flag));
    return app->add_option(flag, target, help)
        ->transform(CLI::CheckedTransformer(names))
        ->default_str(name_of(target));
}

// A check of one option by the library's own: the value is set into a default P, and
// P::check (whose message it gives) decides, so every range is defined once, in the library.
// `range` is what --help shows.
template <class P, class T>
CLI::Validator checked_by(T P::*field, const std::string& range) {
    return CLI::Validator(
        [field](std::string& text) {
            P p;
            if (!CLI::detail::lexical_cast(text, p.*field)) return "'" + text + "' is not a number";
            try {
                p.check("");
            } catch (const Error& e) {
                return std::string(e.what()).substr(2);  // check's text after its ": "
            }
            return std::string();
        },
        range);
}
// OctreeParams::check's ranges of max_height and leaf_points; VisibilityParams::check's of K
// eps and end_window; the end window's help line.
CLI::Validator max_height_check();
CLI::Validator leaf_points_check();
CLI::Validator k_check();
CLI::Validator eps_check();
CLI::Validator end_window_check();
std::string end_window_help();

// The predicate's options (-K, --eps, --facing-tol, --parallel-tol, --end-window) into `vp`, in
// the ranges
// VisibilityParams::check accepts.
void add_predicate_options(CLI::App* app, VisibilityParams& vp);

// The input of build, render, gi and view and its overrides into `in` (vmap/input.h): the
// positional `input` (described by `help`), --as-points, --points, --seed, --max-height and
// --leaf-points.
void add_input_options(CLI::App* app, InputOptions& in, const std::string& help);

// The camera of render and gi: --scene (a scene file's camera), --eye, --target, --up, --fov,
// --size. apply_camera gives `base` with the options given in place (UsageError naming the
// option for a malformed one).
struct CameraOptions {
    std::string scene, eye, target, up, size = "800x800";
    std::optional<float> fov;
};
void add_camera_options(CLI::App* app, CameraOptions& c);
// "x, y, z" of a position relative to `origin`, in the input's coordinates (floats as such
// when the origin is zero, else the doubles).
std::string position_text(Vec3 q, const std::array<double, 3>& origin);
// The same position as numbers in the file's coordinates (q + origin, in double), e.g. for JSON.
std::array<double, 3> file_position(Vec3 q, const std::array<double, 3>& origin);
// --eye and --target are positions in the input's coordinates (relative to `origin`).
Camera apply_camera(const CameraOptions& c, Camera base,
                    const std::array<double, 3>& origin = {});

// Adds to every numeric option of `app` and its subcommands: floating-point values must be
// finite (NaN and infinities refused), unsigned ones must not be negative (no "-1" wrapping to
// 2^64-1). Call after all options are declared.
void harden_options(CLI::App& app);

// Leaf pairs a build of `points` points with `op` is expected to test (an estimate), and a
// warning on stderr with the expected time when that is over ten minutes on this machine's CPU
// cores: printed before the work starts, so an hours-long job is never a surprise.
double estimated_leaf_pairs(uint64_t points, const OctreeParams& op);
void warn_if_long(const std::string& what, uint64_t points, const OctreeParams& op);

// Whether the input is sampled: a scene file, or a mesh file unless `as_points` (is_scene_input),
// so --points/--seed apply. A file that cannot be read counts as sampled: its loader reports it.
bool sampled_input(const std::string& path, bool as_points);

// Prints what the input files held but vmap does not use (Scene::notes), one "note:" line each.
void print_notes(const std::vector<std::string>& notes);

// How much the commands say: -q nothing but errors and asked-for output, the default a short
// summary, -v the timing breakdown too. Set once by main() from -q/-v.
enum class Verbosity { kQuiet, kNormal, kVerbose };
Verbosity& verbosity();

// CPU threads asked for with --threads (0: all cores). Set once by main().
int& threads();

// "42 s", "12 min 5 s", "3 h 20 min".
std::string format_duration(double seconds);

// Progress on stderr for the library's callbacks: unless -q, one line naming the job's size,
// where it runs and the library's estimate of its time (with a warning beyond an hour) before
// the work starts; then, when stderr is a terminal, a line that moves with percent and ETA.
ProgressCallback stderr_progress();

// stderr_progress() for the blue-noise sampling of a scene or mesh (InputOptions::progress):
// silent below 500,000 candidates to remove (about 170,000 points, a second or two here), so
// that a small scene's errors and output stay as they were; the 1.1M-point dragon's 3.3M
// removals show.
ProgressCallback sampling_progress();

// Fails early (before any work or output) unless `path` can be written: its folder exists and
// is writable, and it is not a folder, FIFO or device (vmap::Error naming the file and
// `option`); and when it is one of `inputs` (the same file, however spelled), a UsageError. An
// empty path is no output.
void check_output(const std::string& path, const char* option,
                  const std::vector<std::string>& inputs = {});

}  // namespace vmap::cli
