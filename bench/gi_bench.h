// `vmap bench-gi` (bench/gi_bench.cpp; the subcommand is apps/bench_gi_cmd.cpp): time per
// radiosity bounce against the number of points, hierarchical (CPU, CUDA) and brute force.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace vmap::bench {

struct GiBenchOptions {
    std::string scene;
    std::vector<uint64_t> points{5000, 10000, 20000, 40000, 80000};
    int max_height = 12, leaf_points = 4;
    float theta = 4.0f;
    std::string refine = "blocks";
    int bounces = 3, runs = 3;
    uint64_t brute_max = 20000;
    std::vector<std::string> backends;  // cpu, cuda (default: cpu, plus cuda with a device)
    std::string out_dir;
};

// Runs the sweep, prints the Markdown table to stdout, writes bench-gi.md and bench-gi.csv into
// out_dir when set. Fills in the defaults: the scene (scenes/cornell-bunny.json) and the
// backends (cpu and cuda; cuda dropped with a note when no device answers, unless asked for).
// Returns 0; throws vmap::Error.
int run_gi(GiBenchOptions& o);

}  // namespace vmap::bench
