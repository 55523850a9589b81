// The per-node link arrays (detail::LinkArrays: count, then finish; `seconds_links` of the
// build is finish): a saved V-map's links are turned back into the list the construction hands
// the arrays, in the construction's order, and the arrays are rebuilt from it `runs` times.
// Prints the median and spread (min..max) of count, finish and both, links/s, the threads used,
// and checks that every run's arrays equal the loaded ones byte for byte (exit 1 if not).
//   links_bench FILE.vmap [--runs N (default 5)] [--threads T (default: all cores)]
//               [--seed S (default 1)] [--job-leaves L (default 64)] [--sinks S (default 16)]
// The order: the build walks jobs (node pairs of at most about walk_pairs leaf pairs) and emits
// each job's links row by row (for a leaf of the first node, its visible leaves of the second,
// ascending: nodes are in depth-first preorder), into per-thread sinks of 2^20-link blocks, and
// the threads take jobs in no fixed order. Here a job is the pair of the links' ends' highest
// ancestors with at most L leaves; jobs are shuffled (seeded) and dealt to `sinks` sinks.
// FILE.vmap comes from e.g. `vmap build --backend cpu -o /tmp/links-default.vmap` (the default
// scene: 3.3e7 links) or, on the GPU machine, `vmap build scenes/cornell-dragon.json --backend
// cuda --max-height 10 --leaf-points 1 -o lp1.vmap` (4.6e8 links).
#include <fmt/format.h>
#include <sys/resource.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "vmap/error.h"
#include "vmap/links.h"
#include "vmap/map_access.h"
#include "vmap/visibility_map.h"

namespace {

using vmap::detail::Link;

struct Options {
    std::string file;
    int runs = 5;
    int threads = 0;
    uint64_t seed = 1;
    int32_t job_leaves = 64;
    int sinks = 16;
};

Options parse(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto value = [&]() -> uint64_t {
            const char* v = i + 1 < argc ? argv[++i] : "";
            uint64_t x = 0;
            const auto [end, ec] = std::from_chars(v, v + std::strlen(v), x);
            if (ec != std::errc() || *end || !*v)
                throw vmap::Error(fmt::format("links_bench: {} needs a number, not '{}'", a, v));
            return x;
        };
        if (a == "--runs")
            o.runs = int(std::min<uint64_t>(value(), 1000000));
        else if (a == "--threads")
            o.threads = int(std::min<uint64_t>(value(), 65536));
        else if (a == "--seed")
            o.seed = value();
        else if (a == "--job-leaves")
            o.job_leaves = int32_t(std::min<uint64_t>(value(), 1 << 30));
        else if (a == "--sinks")
            o.sinks = int(std::min<uint64_t>(value(), 65536));
        else if (!a.empty() && a[0] != '-' && o.file.empty())
            o.file = a;
        else
            throw vmap::Error(fmt::format("links_bench: unknown argument '{}'", a));
    }
    if (o.file.empty())
        throw vmap::Error(
            "links_bench: usage: links_bench FILE.vmap [--runs N] "
            "[--threads T] [--seed S] [--job-leaves L] [--sinks S]");
    if (o.runs < 1 || o.threads < 0 || o.job_leaves < 1 || o.sinks < 1)
        throw vmap::Error(
            "links_bench: --runs, --job-leaves and --sinks must be >= 1, --threads >= 0");
    return o;
}

// Per node: the job side it belongs to (its highest ancestor with at most L leaves, or itself).
std::vector<int32_t> job_sides(const vmap::Octree& t, int32_t max_leaves) {
    std::vector<int32_t> side(t.num_nodes());
    for (int32_t n = 0; n < t.num_nodes(); ++n) {  // preorder: a parent comes before its children
        const int32_t p = t.parent()[n];
        side[n] = (p >= 0 && t.leaf_end()[p] - t.leaf_begin()[p] <= max_leaves) ? side[p] : n;
    }
    return side;
}

uint64_t mix(uint64_t x) {  // splitmix64's finaliser
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

// The links of vm (each once, first end the lower node, as the sibling pairs give them) in the
// construction's order (see the file comment), as the sinks' blocks.
std::vector<std::vector<Link>> build_order(const vmap::VisibilityMap& vm, const Options& o) {
    const vmap::Octree& t = vm.octree();
    const std::vector<int32_t> side = job_sides(t, o.job_leaves);
    struct Keyed {
        uint64_t job;
        Link link;
    };
    std::vector<Keyed> all;
    all.reserve(vm.num_links());
    for (int32_t a = 0; a < t.num_nodes(); ++a)
        for (int32_t b : vm.links(a))
            if (a < b) {
                const uint64_t key = (uint64_t(uint32_t(side[a])) << 32) | uint32_t(side[b]);
                all.push_back({mix(key ^ mix(o.seed)), {a, b}});
            }
    tbb::parallel_sort(all.begin(), all.end(), [](const Keyed& x, const Keyed& y) {
        return x.job != y.job ? x.job < y.job : x.link < y.link;
    });
    // Deal the jobs to the sinks (a job's links stay together), then cut into blocks.
    std::vector<std::vector<Link>> sink(o.sinks);
    std::mt19937_64 rng(o.seed);
    for (size_t i = 0; i < all.size();) {
        size_t j = i;
        while (j < all.size() && all[j].job == all[i].job) ++j;
        std::vector<Link>& s = sink[rng() % o.sinks];
        for (; i < j; ++i) s.push_back(all[i].link);
    }
    std::vector<std::vector<Link>> blocks;
    for (const auto& s : sink)
        for (size_t i = 0; i < s.size(); i += vmap::detail::LinkSink::kBlock)
            blocks.emplace_back(s.begin() + i,
                                s.begin() + std::min(s.size(), i + vmap::detail::LinkSink::kBlock));
    return blocks;
}

// CPU seconds (user + system) of the process so far: against the wall time, how busy the
// threads were.
double cpu_seconds() {
    rusage u;
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
           1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double seconds(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

struct Spread {
    double median, lo, hi;
};
Spread spread(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    const size_t n = v.size();
    return {n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]), v.front(), v.back()};
}

int run(const Options& o) {
    vmap::VisibilityMap vm = vmap::load_vmap(o.file);
    vm.require_links("links_bench");
    const std::vector<uint64_t> ref_offsets = vm.link_offsets();
    const std::vector<int32_t> ref_targets(vm.link_targets().begin(), vm.link_targets().end());
    const std::vector<std::vector<Link>> blocks = build_order(vm, o);
    std::vector<std::span<const Link>> spans(blocks.begin(), blocks.end());
    const int threads = o.threads ? o.threads : tbb::info::default_concurrency();
    const int32_t nodes = vm.octree().num_nodes();
    fmt::print(
        "{}: {} nodes, {} links ({} link ends, {:.2f} GB of targets), {} blocks, {} threads\n",
        o.file, nodes, vm.num_links(), ref_targets.size(), ref_targets.size() * 4e-9, blocks.size(),
        threads);
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    tbb::task_arena arena(threads);
    std::vector<double> tc, tf, tt, cpu;
    bool same = true;
    for (int r = 0; r <= o.runs; ++r) {  // run 0 warms up
        double c = 0, f = 0;
        const double cpu0 = cpu_seconds();
        vmap::detail::MapAccess::data(vm).link_targets.reset();  // as in a build: no arrays yet
        arena.execute([&] {
            vmap::detail::LinkArrays la(nodes);
            auto t0 = std::chrono::steady_clock::now();
            la.count(spans);
            c = seconds(t0);
            t0 = std::chrono::steady_clock::now();
            la.finish(vm, spans);
            f = seconds(t0);
        });
        const double cpu1 = cpu_seconds();
        same = same && vm.link_offsets() == ref_offsets &&
               std::memcmp(vm.link_targets().data(), ref_targets.data(),
                           ref_targets.size() * sizeof(int32_t)) == 0;
        if (r == 0) continue;
        tc.push_back(c), tf.push_back(f), tt.push_back(c + f), cpu.push_back(cpu1 - cpu0);
    }
    const Spread c = spread(tc), f = spread(tf), t = spread(tt), u = spread(cpu);
    fmt::print(
        "| threads | runs | count s | finish s (seconds_links) | count + finish s | links/s | CPU "
        "s |\n");
    fmt::print("|---:|---:|---|---|---|---:|---:|\n");
    fmt::print(
        "| {} | {} | {:.3f} ({:.3f}..{:.3f}) | {:.3f} ({:.3f}..{:.3f}) | {:.3f} ({:.3f}..{:.3f}) | "
        "{:.3g} | {:.2f} |\n",
        threads, o.runs, c.median, c.lo, c.hi, f.median, f.lo, f.hi, t.median, t.lo, t.hi,
        double(vm.num_links()) / t.median, u.median);
    fmt::print("{}\n",
               same ? "arrays byte-identical to the file's" : "ARRAYS DIFFER from the file's");
    return same ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        return run(parse(argc, argv));
    } catch (const std::exception& e) {
        fmt::print(stderr, "error: {}\n", e.what());
        return 2;
    }
}
