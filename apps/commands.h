// Subcommands defined outside apps/vmap.cpp. Each add_* function declares its options on `app`
// and returns the subcommand with the function that runs it after parsing; main() calls run()
// inside its error handling (vmap::Error -> exit 1), and a run() returning 2 is a usage error.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "vmap/progress.h"
#include "vmap/vec.h"

namespace vmap::cli {

struct Command {
    CLI::App* app = nullptr;
    std::function<int()> run;
};

Command add_render_command(CLI::App& app);       // apps/render_cmd.cpp
Command add_query_command(CLI::App& app);        // apps/query_cmd.cpp
Command add_bench_query_command(CLI::App& app);  // bench/query_bench.cpp
Command add_view_command(CLI::App& app);         // apps/view_cmd.cpp

// "x,y,z" -> Vec3; throws vmap::Error naming `option` for anything else (or non-finite values).
Vec3 parse_vec3(const std::string& text, const std::string& option);
// "WxH" -> (W, H), each 1..16384; throws vmap::Error naming `option`.
std::pair<int, int> parse_size(const std::string& text, const std::string& option);

bool ends_with_ci(std::string s, const std::string& suffix);

// Whether the input is sampled: a scene file, or a mesh file unless `as_points` (is_scene_input),
// so --points/--seed apply. A file that cannot be read counts as sampled: its loader reports it.
bool sampled_input(const std::string& path, bool as_points);

// Prints what the input files held but vmap does not use (Scene::notes), one "note:" line each.
void print_notes(const std::vector<std::string>& notes);

// How much the commands say: -q nothing but errors and asked-for output, the default a short
// summary, -v the timing breakdown too. Set once by main() from -q/-v.
enum class Verbosity { kQuiet, kNormal, kVerbose };
Verbosity& verbosity();

// "42 s", "12 min 5 s", "3 h 20 min".
std::string format_duration(double seconds);

// Progress on stderr for the library's callbacks: unless -q, one line naming the job's size,
// where it runs and the library's estimate of its time (with a warning beyond an hour) before
// the work starts; then, when stderr is a terminal, a line that moves with percent and ETA.
ProgressCallback stderr_progress();

// Fails early (before any work or output) when an output's folder does not exist; throws
// vmap::Error naming the file and `option`. An empty path is no output.
void check_output(const std::string& path, const char* option);

}  // namespace vmap::cli
