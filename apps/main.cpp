// vmap: view-independent mutual visibility for point models.
//   vmap build [SCENE.json | MESH | CLOUD] -o out.vmap  octree + V-map, with a summary
//   vmap info out.vmap                                what a .vmap holds
//   vmap query out.vmap --pair I J | --from I | --ray I --dir D
//   vmap render [SCENE | CLOUD | out.vmap] --mode M   pictures
//   vmap gi [SCENE | out.vmap] -o lit.png             global illumination
//   vmap validate SCENE                               V-map answers against exact visibility
//   vmap view [out.vmap | SCENE]                      browser viewer
//   vmap bench, bench-query, bench-gi                 construction, query and GI timings
// Each subcommand is apps/<name>_cmd.cpp (the benchmarks' programs in bench/); this file only
// registers them (apps/commands.h) and runs the one parsed.
// Exit codes: 0 success, 1 an error in the input or while running, 2 a usage error.
#include <fmt/format.h>
#include <tbb/global_control.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <vector>

#include "apps/commands.h"
#include "vmap/error.h"
#include "vmap/mpi.h"
#include "vmap/version.h"

namespace {

using namespace vmap;

std::string command_names(CLI::App& app) {
    std::string names;
    for (const CLI::App* s : app.get_subcommands({}))
        names += (names.empty() ? "" : ", ") + s->get_name();
    return names;
}

// The first word that is not an option (nor --threads' value) when it names no subcommand:
// says so, with the list, and returns true.
bool report_unknown_command(CLI::App& app, int argc, char** argv) {
    for (int i = 1; i < argc; ++i) {
        const std::string w = argv[i];
        if (w == "--threads") {
            ++i;
            continue;
        }
        if (w.empty() || w[0] == '-') continue;
        for (const CLI::App* sub : app.get_subcommands({}))
            if (sub->check_name(w)) return false;  // a known command: CLI11 says what is wrong
        fmt::print(stderr, "vmap: unknown command '{}' (the commands: {}; see vmap --help)\n", w,
                   command_names(app));
        return true;
    }
    for (int i = 1; i < argc; ++i)
        if (std::string(argv[i]) != "--threads" || ++i == argc) return false;
    fmt::print(stderr, "vmap: no command given (the commands: {}; see vmap --help)\n",
               command_names(app));
    return true;
}

// The parsed subcommand run inside the one error handling: a UsageError exits 2, any other
// failure 1, with one line on stderr.
int run_command(const cli::Command& c) {
    try {
        return c.run();
    } catch (const cli::UsageError& e) {
        fmt::print(stderr, "vmap: error: {}\n", e.what());
        return 2;
    } catch (const vmap::Error& e) {
        fmt::print(stderr, "vmap: error: {}\n", e.what());
        return 1;
    } catch (const std::bad_alloc&) {
        fmt::print(stderr, "vmap: error: out of memory (try a smaller --max-height or --points)\n");
        return 1;
    } catch (const std::exception& e) {
        fmt::print(stderr, "vmap: internal error: {}\n", e.what());
        return 1;
    }
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{
        "vmap: view-independent mutual visibility for point models.\n"
        "Builds an adaptive octree over a point model, computes which leaf pairs see each other\n"
        "(on a CUDA GPU or on all CPU cores) and stores the result as a visibility map of links\n"
        "between octree nodes.\n\n"
        "Start:  vmap build                       (the default scene, scenes/cornell-bunny.json)\n"
        "        vmap build scenes/cornell-dragon.json -o dragon.vmap --max-height 8\n"
        "        vmap query dragon.vmap --pair 10 2000\n"};
    app.require_subcommand(1);
    app.fallthrough();  // global options (--threads) may also follow the subcommand
    app.add_option("--threads", cli::threads(), "CPU threads (default: all cores)")
        ->check(CLI::Range(0, 4096));
    app.set_version_flag(
        "--version", fmt::format("vmap {} (commit {}, CUDA {})", vmap::version(), vmap::commit(),
                                 built_with_cuda() ? "on" : "off"));
    bool verbose = false, quiet = false;
    auto* vflag = app.add_flag("-v,--verbose", verbose, "Say more: timing breakdowns, tables");
    app.add_flag("-q,--quiet", quiet, "Say nothing but errors and the output asked for")
        ->excludes(vflag);

    std::vector<cli::Command> commands;
    for (auto add : {cli::add_build_command, cli::add_info_command, cli::add_query_command,
                     cli::add_render_command, cli::add_bench_query_command, cli::add_view_command,
                     cli::add_gi_command, cli::add_bench_gi_command, cli::add_bench_command,
                     cli::add_validate_command})
        commands.push_back(add(app));
    cli::harden_options(app);
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        if (app.get_subcommands().empty() && report_unknown_command(app, argc, argv)) return 2;
        const int rc = app.exit(e);
        return rc == 0 ? 0 : 2;
    }
    cli::verbosity() = quiet     ? cli::Verbosity::kQuiet
                       : verbose ? cli::Verbosity::kVerbose
                                 : cli::Verbosity::kNormal;
    std::unique_ptr<tbb::global_control> limit;
    // Under mpirun, vmap build gives each rank --threads itself (vmap/mpi.h), all but rank 0's
    // save: that may use the cores the other ranks have finished with.
    const bool per_rank = vmap::mpi::launched() && app.got_subcommand("build");
    if (cli::threads() > 0 && !per_rank)
        limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                      cli::threads());
    for (const cli::Command& c : commands) {
        if (!c.app->parsed()) continue;
        // A command whose stdout is a summary (not the answers asked for) prints nothing with -q.
        if (quiet && c.summary && !std::freopen("/dev/null", "w", stdout)) return 1;
        return run_command(c);
    }
    return 0;
}
