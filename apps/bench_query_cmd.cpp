// `vmap bench-query`: query latency against scene size (the program is bench/query_bench.cpp).
#include <memory>

#include "apps/commands.h"
#include "bench/query_bench.h"

namespace vmap::cli {

Command add_bench_query_command(CLI::App& app) {
    auto a = std::make_shared<bench::QueryBenchOptions>();
    auto* c = app.add_subcommand("bench-query",
                                 "Time pair, visible-set and ray queries against scene size");
    c->add_option("--scene", a->scene, "Scene file (default: scenes/cornell-bunny.json)");
    c->add_option("--points", a->points, "Point counts, e.g. 5000,20000,80000")
        ->delimiter(',')
        ->check(CLI::Range(uint64_t(100), uint64_t(50000000)));
    c->add_option("--max-height", a->max_height, "Octree max height for every size")
        ->check(CLI::Range(1, 21))
        ->capture_default_str();
    c->add_option("--leaf-points", a->leaf_points, "Octree leaf_points for every size")
        ->check(CLI::Range(1, 1000000))
        ->capture_default_str();
    c->add_option("--queries", a->queries, "Queries per batch")
        ->check(CLI::Range(20, 10000000))
        ->capture_default_str();
    c->add_option("--runs", a->runs, "Timed runs per batch")
        ->check(CLI::Range(1, 100))
        ->capture_default_str();
    add_choice(c, "--backend", a->backend, "Backend for the builds: auto, cpu or cuda");
    c->add_option("--out", a->out_dir, "Write bench-query.md and bench-query.csv here");
    return {c,
            [a] {
                a->progress = stderr_progress();
                return bench::run_query(*a);
            },
            true};
}

}  // namespace vmap::cli
