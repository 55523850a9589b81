// `vmap bench-query`: query latency against scene size (issue 4; the paper claims queries grow
// sub-linearly with the scene). For each point count the scene is sampled and its V-map built
// (same octree policy for every size), then batches of seeded random queries are timed: point
// pairs, visible-set counts, visible-set listings, rays pruned by the V-map, and (fewer) rays by
// testing every point, for contrast. Each batch runs once untimed, then `runs` times; the table
// gives the median latency per query and the min-max spread over runs, with the work done (set
// sizes, node and disc tests per ray). The last line fits latency ~ N^k between the smallest and
// largest size: k < 1 is sub-linear.
#include "bench/query_bench.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>

#include "vmap/error.h"
#include "vmap/files.h"
#include "vmap/query.h"
#include "vmap/scene.h"

namespace vmap::bench {
namespace {

struct Spread {
    double median = 0, lo = 0, hi = 0;
};
Spread spread(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return {v[v.size() / 2], v.front(), v.back()};
}

// Times `batch` (which runs `count` queries) once untimed and then `runs` times; microseconds
// per query.
template <class F>
Spread time_batch(int runs, size_t count, F&& batch) {
    batch();
    std::vector<double> us;
    for (int r = 0; r < runs; ++r) {
        const auto t0 = std::chrono::steady_clock::now();
        batch();
        const double s =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        us.push_back(1e6 * s / double(std::max<size_t>(count, 1)));
    }
    return spread(us);
}

struct Row {
    uint64_t points = 0;
    int height = 0;
    int32_t leaves = 0;
    size_t links = 0;
    double build_s = 0;
    Spread pair, count, list, ray, brute;
    double set_size = 0, node_tests = 0, disc_tests = 0, hit_rate = 0;
    double pair_probes = 0;  // per pair query: ancestors walked + binary-search steps
};

std::string fmt_spread(const Spread& s) {
    return fmt::format("{:.3g} [{:.3g}-{:.3g}]", s.median, s.lo, s.hi);
}

volatile uint64_t g_sink;  // keeps the timed loops from being optimised away

VisibilityMap build_sized(const QueryBenchOptions& a, uint64_t n, Row& r) {
    Scene sc = load_scene(a.scene);
    sc.points = n;
    PointSet pts = sample_scene(sc);
    BuildParams bp;
    bp.octree.max_height = a.max_height;
    bp.octree.leaf_points = a.leaf_points;
    bp.backend = a.backend;
    bp.progress = a.progress;
    BuildStats st;
    VisibilityMap vm = build_vmap(std::move(pts), bp, &st, a.scene);
    r.points = n;
    r.height = vm.octree().height();
    r.leaves = vm.octree().num_leaves();
    r.links = vm.num_links();
    r.build_s = st.seconds_total;
    return vm;
}

// Seeded queries: ids uniform over the points; ray directions in the hemisphere of the point's
// normal (normal + a random unit vector).
struct Queries {
    std::vector<uint32_t> a, b;
    std::vector<Vec3> dirs;
};
Queries make_queries(const VisibilityMap& vm, uint64_t n, size_t Q) {
    std::mt19937_64 rng(12345 + n);
    std::uniform_int_distribution<uint32_t> pick(0, uint32_t(n - 1));
    std::normal_distribution<float> gauss;
    Queries q{std::vector<uint32_t>(Q), std::vector<uint32_t>(Q), std::vector<Vec3>(Q)};
    for (size_t k = 0; k < Q; ++k) {
        q.a[k] = pick(rng);
        q.b[k] = pick(rng);
        Vec3 g{gauss(rng), gauss(rng), gauss(rng)};
        g = g / std::max(length(g), 1e-6f);
        const Vec3 nrm = vm.points().normals[vm.inverse()[q.a[k]]];
        q.dirs[k] = nrm + g;
        if (!(length(q.dirs[k]) > 1e-3f)) q.dirs[k] = nrm;
    }
    return q;
}

void time_queries(int runs, const VisibilityMap& vm, const Queries& q, Row& r) {
    const size_t Q = q.a.size();
    const size_t Ql = std::max<size_t>(1, Q / 20), Qb = std::max<size_t>(1, Q / 20);
    r.pair = time_batch(runs, Q, [&] {
        uint64_t s = 0;
        for (size_t k = 0; k < Q; ++k) s += uint64_t(vm.query(q.a[k], q.b[k]));
        g_sink = s;
    });
    r.count = time_batch(runs, Q, [&] {
        uint64_t s = 0;
        for (size_t k = 0; k < Q; ++k) s += visible_count(vm, q.a[k]);
        g_sink = s;
    });
    r.list = time_batch(runs, Ql, [&] {
        uint64_t s = 0;
        for (size_t k = 0; k < Ql; ++k) s += vm.visible_set(q.a[k]).size();
        g_sink = s;
    });
    r.ray = time_batch(runs, Q, [&] {
        uint64_t s = 0;
        for (size_t k = 0; k < Q; ++k) s += shoot_ray(vm, q.a[k], q.dirs[k]).id;
        g_sink = s;
    });
    r.brute = time_batch(runs, Qb, [&] {
        uint64_t s = 0;
        for (size_t k = 0; k < Qb; ++k) s += shoot_ray_brute(vm, q.a[k], q.dirs[k], false).id;
        g_sink = s;
    });
}

// Work, counted once outside the timing.
void count_work(const VisibilityMap& vm, const Queries& q, Row& r) {
    const size_t Q = q.a.size();
    RayStats rs;
    uint64_t hits = 0, set = 0;
    for (size_t k = 0; k < Q; ++k) {
        hits += shoot_ray(vm, q.a[k], q.dirs[k], &rs).hit;
        set += visible_count(vm, q.a[k]);
    }
    const Octree& t = vm.octree();
    uint64_t probes = 0;
    for (size_t k = 0; k < Q; ++k)
        for (int32_t A = t.leaf_node()[t.leaf_of_point(vm.inverse()[q.a[k]])]; A >= 0;
             A = t.parent()[A])
            probes += 1 + uint64_t(std::ceil(std::log2(double(vm.links(A).size()) + 1)));
    r.pair_probes = double(probes) / Q;
    r.set_size = double(set) / Q;
    r.node_tests = double(rs.node_tests) / Q;
    r.disc_tests = double(rs.disc_tests) / Q;
    r.hit_rate = double(hits) / Q;
}

std::string md_table(const QueryBenchOptions& a, const std::vector<Row>& rows) {
    std::string md = fmt::format(
        "Scene {}, max_height {}, leaf_points {}; {} queries per batch ({} for listings and "
        "brute-force rays), {} timed runs after a warm-up; microseconds per query, median "
        "[min-max] over runs.\n\n",
        std::filesystem::path(a.scene).filename().string(), a.max_height, a.leaf_points, a.queries,
        std::max(1, a.queries / 20), a.runs);
    md +=
        "| points | height | leaves | links | build s | pair us | pair probes | visible count us | "
        "visible list us | visible set size | ray us | ray node tests | ray disc tests | ray hits "
        "| brute-force ray us |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for (const Row& r : rows)
        md += fmt::format(
            "| {} | {} | {} | {} | {:.2f} | {} | {:.0f} | {} | {} | {:.0f} | {} | {:.0f} | {:.0f} "
            "| {:.0f}% | {} |\n",
            r.points, r.height, r.leaves, r.links, r.build_s, fmt_spread(r.pair), r.pair_probes,
            fmt_spread(r.count), fmt_spread(r.list), r.set_size, fmt_spread(r.ray), r.node_tests,
            r.disc_tests, 100 * r.hit_rate, fmt_spread(r.brute));
    const Row &f = rows.front(), &l = rows.back();
    const double span = std::log(double(l.points) / double(f.points));
    auto slope = [&](double a0, double a1) { return std::log(a1 / a0) / span; };
    md += fmt::format(
        "\nGrowth exponent k (latency ~ N^k, {} to {} points): pair {:.2f}, visible count {:.2f}, "
        "visible list {:.2f}, ray {:.2f}, brute-force ray {:.2f}.\n",
        f.points, l.points, slope(f.pair.median, l.pair.median),
        slope(f.count.median, l.count.median), slope(f.list.median, l.list.median),
        slope(f.ray.median, l.ray.median), slope(f.brute.median, l.brute.median));
    return md;
}

std::string csv_table(const std::vector<Row>& rows) {
    std::string csv =
        "points,height,leaves,links,build_s,pair_us,count_us,list_us,set_size,ray_us,"
        "ray_node_tests,ray_disc_tests,ray_hit_rate,brute_ray_us\n";
    for (const Row& r : rows)
        csv += fmt::format("{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n", r.points, r.height,
                           r.leaves, r.links, r.build_s, r.pair.median, r.count.median,
                           r.list.median, r.set_size, r.ray.median, r.node_tests, r.disc_tests,
                           r.hit_rate, r.brute.median);
    return csv;
}

}  // namespace

int run_query(QueryBenchOptions& a) {
    if (a.scene.empty()) a.scene = default_scene_path();
    if (a.points.size() < 2) throw Error("--points: give at least two sizes");
    if (!a.out_dir.empty()) io::make_output_folder(a.out_dir, "--out");
    std::vector<Row> rows;
    for (uint64_t n : a.points) {
        Row r;
        const VisibilityMap vm = build_sized(a, n, r);
        const Queries q = make_queries(vm, n, size_t(a.queries));
        time_queries(a.runs, vm, q, r);
        count_work(vm, q, r);
        fmt::print(stderr, "bench-query: {} points done ({} leaves, build {:.1f} s)\n", n, r.leaves,
                   r.build_s);
        rows.push_back(r);
    }
    const std::string md = md_table(a, rows);
    fmt::print("{}", md);
    if (!a.out_dir.empty()) {
        io::write_file_atomic(a.out_dir + "/bench-query.md", md);
        io::write_file_atomic(a.out_dir + "/bench-query.csv", csv_table(rows));
    }
    return 0;
}

}  // namespace vmap::bench
