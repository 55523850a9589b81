// `vmap bench-query` (bench/query_bench.cpp; the subcommand is apps/bench_query_cmd.cpp): query
// latency against scene size.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "vmap/options.h"
#include "vmap/progress.h"

namespace vmap::bench {

struct QueryBenchOptions {
    std::string scene;
    std::vector<uint64_t> points{5000, 10000, 20000, 40000, 80000};
    int max_height = 10, leaf_points = 4, queries = 2000, runs = 5;
    Backend backend = Backend::kAuto;
    std::string out_dir;
    ProgressCallback progress;  // for the builds (BuildParams::progress)
};

// Runs the sweep (at least two sizes), prints the Markdown table to stdout, writes
// bench-query.md and bench-query.csv into out_dir when set; an empty scene is
// scenes/cornell-bunny.json. Returns 0; throws vmap::Error.
int run_query(QueryBenchOptions& a);

}  // namespace vmap::bench
