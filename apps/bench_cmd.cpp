// `vmap bench`: the construction table, CPU against GPU (the program is bench/bench.cpp).
#include <memory>

#include "apps/commands.h"
#include "bench/bench.h"
#include "vmap/version.h"

namespace vmap::cli {

// `vmap bench`: the construction table (bench/bench.cpp).
Command add_bench_command(CLI::App& app) {
    auto bo2 = std::make_shared<bench::Options>();
    auto* benchc = app.add_subcommand(
        "bench", "Time V-map construction, CPU vs GPU, per scene and height (paper Fig. 10)");
    benchc->add_option("--scene", bo2->scenes,
                       "Scene files (default: cornell-bunny, cornell-dragon, cornell-two-models)");
    benchc->add_option("--heights", bo2->heights, "Octree heights")
        ->delimiter(',')
        ->check(max_height_check());
    benchc->add_option("--leaf-points", bo2->leaf_points, "leaf_points for every run")
        ->check(leaf_points_check())
        ->capture_default_str();
    benchc->add_option("--runs", bo2->runs, "Timed runs per configuration (median, spread)")
        ->check(CLI::Range(1, 100))
        ->capture_default_str();
    benchc
        ->add_option("--backends", bo2->backends,
                     "cpu and/or cuda (default: both when a GPU is present)")
        ->delimiter(',')
        ->check(CLI::IsMember({"cpu", "cuda"}));
    benchc
        ->add_option("--cpu-budget", bo2->cpu_budget_s,
                     "Seconds a full CPU sweep may take; beyond, the CPU is timed on a sample")
        ->check(CLI::Range(0.0, 1e7))
        ->capture_default_str();
    benchc->add_option("--points", bo2->points, "Override every scene's point count")
        ->check(CLI::Range(uint64_t(1), uint64_t(50000000)));
    benchc->add_option("--out", bo2->out_dir, "Write bench.md and bench.csv into this folder");
    add_choice(benchc, "--construction", bo2->construction,
                    "auto, nodes or leaf-pairs (as for build)");
    return {benchc,
            [bo2]() {
                if (bo2->scenes.empty())
                    for (const char* n : {"cornell-bunny", "cornell-dragon", "cornell-two-models"})
                        bo2->scenes.push_back(data_dir() + "/scenes/" + n + ".json");
                return bench::run(*bo2);
            },
            true};
}

}  // namespace vmap::cli
