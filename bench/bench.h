// `vmap bench`: the paper's Fig. 10 table (CPU vs GPU V-map construction per scene and octree
// height), measured, with medians and spread, work counted next to time.
#pragma once

#include <cstdint>
#include "vmap/options.h"
#include <string>
#include <vector>

namespace vmap::bench {

struct Options {
    std::vector<std::string> scenes;  // scene files
    std::vector<int> heights{5, 6, 7, 8, 9, 10};
    int leaf_points = 4;
    int runs = 3;
    std::vector<std::string> backends;  // empty: cpu, and cuda when a device is present
    double cpu_budget_s = 60;  // a full CPU run longer than this (estimated) is sampled instead
    uint64_t cpu_sample_pairs = 4000000;
    uint64_t points = 0;                 // 0: each scene's own count
    bool save = true;                    // time writing the .vmap too (end to end)
    std::string out_dir;                 // bench.md and bench.csv here when set
    Construction construction = Construction::kAuto;  // BuildParams::construction
};

// Runs the sweep, prints the Markdown table to stdout, writes files. Returns 0.
int run(const Options& o);

}  // namespace vmap::bench
