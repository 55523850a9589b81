// `vmap gi` (apps/gi_cmd.cpp) and `vmap bench-gi` (bench/gi_bench.cpp): declared here, registered
// from apps/vmap.cpp with one call; main() runs the selected one inside its error handling.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>

namespace vmap::cli {

struct GiCommands {
    CLI::App* gi = nullptr;
    CLI::App* bench = nullptr;
    std::function<int()> run_gi, run_bench;

    bool selected() const { return (gi && gi->parsed()) || (bench && bench->parsed()); }
    int run() const { return gi && gi->parsed() ? run_gi() : run_bench(); }
};

GiCommands add_gi_commands(CLI::App& app);

// bench/gi_bench.cpp: declares `bench-gi` on `app`, returns the subcommand and its runner.
std::pair<CLI::App*, std::function<int()>> add_gi_bench_command(CLI::App& app);

}  // namespace vmap::cli
