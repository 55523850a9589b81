// `vmap bench-gi`: time per GI bounce against points (the program is bench/gi_bench.cpp).
#include <memory>

#include "apps/commands.h"
#include "bench/gi_bench.h"

namespace vmap::cli {

Command add_bench_gi_command(CLI::App& app) {
    auto o = std::make_shared<bench::GiBenchOptions>();
    auto* b = app.add_subcommand(
        "bench-gi", "Time per GI bounce against points: hierarchical (CPU, GPU) vs brute force");
    b->add_option("--scene", o->scene, "Scene file (default: scenes/cornell-bunny.json)");
    b->add_option("--points", o->points, "Point counts")
        ->delimiter(',')
        ->check(CLI::Range(uint64_t(100), uint64_t(50000000)))
        ->capture_default_str();
    b->add_option("--max-height", o->max_height, "Octree max_height for every size")
        ->check(CLI::Range(1, 21))
        ->capture_default_str();
    b->add_option("--leaf-points", o->leaf_points, "Octree leaf_points for every size")
        ->check(CLI::Range(1, 1000000))
        ->capture_default_str();
    b->add_option("--theta", o->theta, "Separation parameter")
        ->check(CLI::Range(1e-3, 1e3))
        ->capture_default_str();
    b->add_option("--refine", o->refine, "blocks or links (see vmap gi --help)")
        ->check(CLI::IsMember({"blocks", "links"}))
        ->capture_default_str();
    b->add_option("--bounces", o->bounces, "Bounces per run")
        ->check(CLI::Range(1, 1000))
        ->capture_default_str();
    b->add_option("--runs", o->runs, "Runs per size and backend")
        ->check(CLI::Range(1, 100))
        ->capture_default_str();
    b->add_option("--brute-max", o->brute_max, "Brute force only up to this many points")
        ->capture_default_str();
    b->add_option("--backends", o->backends, "cpu and/or cuda (default: cpu, and cuda if present)")
        ->delimiter(',')
        ->check(CLI::IsMember({"cpu", "cuda"}));
    b->add_option("--out", o->out_dir, "Write bench-gi.md and bench-gi.csv into this folder");
    return {b, [o] { return bench::run_gi(*o); }, true};
}

}  // namespace vmap::cli
