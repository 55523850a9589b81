// `vmap bench` (see bench.h). Each configuration: the points are sampled once, then the V-map is
// built `runs` times per backend (after one untimed warm-up build), reporting the median and the
// min-max spread. Where a full CPU run would take longer than the budget, the CPU's leaf-pair
// rate is measured on a seeded uniform sample of the leaf pairs and scaled to all pairs; the
// octree and link work of the GPU build (host work either way) is added; such entries are
// marked "est.".
#include "bench/stats.h"
#include "bench/bench.h"

#include <fmt/format.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>

#include "vmap/error.h"
#include "vmap/files.h"
#include "vmap/scene.h"
#include "vmap/version.h"
#include "vmap/vmap.h"

namespace vmap::bench {
namespace {

using Clock = std::chrono::steady_clock;

using bench_stats::Stat;
using bench_stats::stat;

struct Row {
    std::string scene;
    uint64_t points = 0;
    int height = 0, leaf_points = 0;
    int32_t leaves = 0;
    uint64_t pairs = 0, links = 0;
    uint64_t walked = 0, node_pairs_tested = 0;  // leaf pairs walked; node-pair tests
    WorkCounters work;
    Stat cpu, gpu, save;
    bool cpu_done = false, cpu_estimated = false, gpu_done = false;
    double cpu_pair_rate = 0;  // pairs/s on the CPU (sampled or full)
    uint64_t device_bytes = 0;
    double gpu_wait = 0;
    std::vector<double> kernel;  // backend busy seconds per GPU run
};

std::string git_commit() {
    if (const char* c = getenv("VMAP_COMMIT")) return c;
    return vmap::commit();
}

std::string fmt_time(const Stat& s, bool done, bool est) {
    if (!done) return "-";
    if (est) return fmt::format("{:.3g} (est.)", s.median);
    return fmt::format("{:.3g} [{:.3g}-{:.3g}]", s.median, s.lo, s.hi);
}

// What one `vmap bench` call carries from configuration to configuration.
struct Session {
    explicit Session(const Options& opts) : o(opts) {}
    const Options& o;
    bool want_cpu = false, want_gpu = false, have_gpu = false;
    std::string why;  // why there is no GPU
    bool warmed = false;
    std::string tmp;  // where --save writes
};

// The backends asked for (default: cpu, plus cuda where a device answers).
void pick_backends(Session& s) {
    std::vector<std::string> backends = s.o.backends;
    s.have_gpu = !cuda_backend_name(&s.why).empty();
    if (backends.empty()) {
        backends.push_back("cpu");
        if (s.have_gpu) backends.push_back("cuda");
    }
    s.want_cpu = std::count(backends.begin(), backends.end(), "cpu") > 0;
    s.want_gpu = std::count(backends.begin(), backends.end(), "cuda") > 0;
    if (s.want_gpu && !s.have_gpu) throw Error("--backends cuda: " + s.why);
}

// One configuration's measurements on their way into its row.
struct Timing {
    std::vector<double> gpu, cpu, save;
    double non_pair = 0;  // seconds of a build outside the leaf-pair wait
};

void take_counts(Row& r, const VisibilityMap& vm, const BuildStats& st) {
    r.work = st.work;
    r.walked = st.leaf_pairs_walked;
    r.node_pairs_tested = st.node_pairs_tested;
    r.leaves = vm.octree().num_leaves();
    r.links = vm.num_links();
}

void time_save(const Session& s, const VisibilityMap& vm, Timing& tm) {
    if (!s.o.save) return;
    const auto t0 = Clock::now();
    save_vmap(s.tmp, vm);
    tm.save.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
    std::filesystem::remove(s.tmp);
}

void time_gpu(Session& s, const PointSet& pts, BuildParams bp, Row& r, Timing& tm) {
    bp.backend = Backend::kCuda;
    if (!s.warmed) {
        build_vmap(pts, bp);
        s.warmed = true;
    }
    for (int k = 0; k < s.o.runs; ++k) {
        BuildStats st;
        VisibilityMap vm = build_vmap(pts, bp, &st);
        tm.gpu.push_back(st.seconds_total);
        tm.non_pair = st.seconds_total - st.seconds_wait;
        r.gpu_wait = st.seconds_wait;
        r.kernel.push_back(st.seconds_backend);
        take_counts(r, vm, st);
        r.device_bytes = st.peak_device_bytes;
        time_save(s, vm, tm);
    }
    r.gpu = stat(tm.gpu);
    r.gpu_done = true;
}

// Estimate first from a sample; run in full only when within the budget.
void time_cpu(const Session& s, const PointSet& pts, BuildParams bp, Row& r, Timing& tm) {
    const Options& o = s.o;
    bp.backend = Backend::kCpu;
    PointSet copy = pts;
    std::vector<uint32_t> order;
    const Octree t = Octree::build(copy, bp.octree, order, "bench");
    r.cpu_pair_rate = sampled_cpu_pair_rate(t, in_octree_frame(bp.visibility, t.scale()),
                                            std::min<uint64_t>(o.cpu_sample_pairs, 1ull << 40));
    // The GPU run, when there was one, says how many leaf pairs are walked.
    const uint64_t pairs =
        r.gpu_done ? r.walked : uint64_t(t.num_leaves()) * (t.num_leaves() - 1) / 2;
    const double est = pairs / r.cpu_pair_rate;
    if (est * o.runs <= o.cpu_budget_s) {
        for (int k = 0; k < o.runs; ++k) {
            BuildStats st;
            VisibilityMap vm = build_vmap(pts, bp, &st);
            tm.cpu.push_back(st.seconds_total);
            if (!r.gpu_done) {
                take_counts(r, vm, st);
                tm.non_pair = st.seconds_total - st.seconds_wait;
                time_save(s, vm, tm);
            }
            r.cpu_pair_rate = st.work.pairs / std::max(1e-9, st.seconds_wait);
        }
        r.cpu = stat(tm.cpu);
    } else {
        r.cpu = {est + tm.non_pair, est + tm.non_pair, est + tm.non_pair};
        r.cpu_estimated = true;
        if (!r.gpu_done) r.leaves = t.num_leaves();
    }
    r.cpu_done = true;
}

Row bench_one(Session& s, const Scene& sc, const PointSet& pts, int h) {
    Row r;
    r.scene = sc.name;
    r.points = pts.size();
    r.height = h;
    r.leaf_points = s.o.leaf_points;
    BuildParams bp;
    bp.octree = {h, s.o.leaf_points};
    bp.construction = s.o.construction;
    Timing tm;
    if (s.want_gpu) time_gpu(s, pts, bp, r, tm);
    if (s.want_cpu) time_cpu(s, pts, bp, r, tm);
    r.pairs = uint64_t(r.leaves) * (r.leaves - 1) / 2;
    r.save = stat(tm.save);
    return r;
}

// The table's facts apart from the rows.
struct Header {
    int cores = 0;
    std::string device = "none", date;
};

std::string md_row(const Options& o, const Header& hd, const Row& r) {
    const double gpu_rate = r.gpu_done ? r.pairs / std::max(1e-9, r.gpu.median) : 0;
    const double speed = r.gpu_done && r.cpu_done ? r.cpu.median / r.gpu.median : 0;
    const double ntp = double(r.work.node_tests) / std::max<uint64_t>(1, r.work.pairs);
    const double kern = stat(r.kernel).median;
    // A row whose only time is the CPU's estimate built nothing: no counts to show.
    const bool counted = r.gpu_done || (r.cpu_done && !r.cpu_estimated);
    auto count = [&](std::string text) { return counted ? text : std::string("-"); };
    return fmt::format(
        "| {} | {} | {} | {} | {:.3g} | {} | {} | {} | {} | {} | {} | {} | {} | {} | "
        "{} | {} | {} | {} |\n",
        r.scene, r.points, r.height, r.leaves, double(r.pairs),
        count(fmt::format("{:.1f}%", 100.0 * r.walked / std::max<uint64_t>(1, r.pairs))),
        count(fmt::format("{:.3g}", double(r.node_pairs_tested))),
        count(fmt::format("{:.3g}", double(r.links))), fmt_time(r.cpu, r.cpu_done, r.cpu_estimated),
        fmt_time(r.gpu, r.gpu_done, false), speed > 0 ? fmt::format("{:.1f}x", speed) : "-",
        r.gpu_done ? fmt::format("{:.3g}", gpu_rate) : "-",
        r.gpu_done ? fmt::format("{:.3g}", r.pairs / std::max(1e-9, kern)) : "-",
        r.cpu_done ? fmt::format("{:.3g}", r.cpu_pair_rate / hd.cores) : "-",
        count(fmt::format("{:.1f}", ntp)),
        r.gpu_done ? fmt::format("{:.3g}", r.work.node_tests / std::max(1e-9, kern)) : "-",
        o.save && counted ? fmt::format("{:.3g}", r.save.median) : "-",
        r.gpu_done ? fmt::format("{:.0f}", r.device_bytes / 1048576.0) : "-");
}

std::string csv_row(const Header& hd, const Row& r) {
    const double kern = stat(r.kernel).median;
    return fmt::format(
        "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},\"{}\",{},{}\n",
        r.scene, r.points, r.height, r.leaf_points, r.leaves, r.pairs, r.walked,
        r.node_pairs_tested, r.links, r.cpu.median, r.cpu.lo, r.cpu.hi, int(r.cpu_estimated),
        r.gpu.median, r.gpu.lo, r.gpu.hi, r.gpu_done ? r.pairs / r.gpu.median : 0, kern,
        r.cpu_pair_rate / hd.cores, r.work.facing_pairs, r.work.node_tests, r.work.occluder_tests,
        r.save.median, r.device_bytes, hd.cores, hd.device, git_commit(), hd.date);
}

std::string md_table(const Options& o, const Header& hd, const std::vector<Row>& rows) {
    std::string md = fmt::format(
        "vmap bench: {} CPU threads, GPU {}, {} runs, leaf_points {}, construction {}, commit {}, "
        "{}\n\n",
        hd.cores, hd.device, o.runs, o.leaf_points, name_of(o.construction), git_commit(), hd.date);
    md +=
        "| scene | points | max height | leaves | leaf pairs | walked | node pairs tested | links | "
        "CPU s | GPU s | speedup | GPU pairs/s | GPU kernel pairs/s | CPU pairs/s/core | "
        "node tests/pair | GPU node tests/s | save s | device MiB |\n";
    md += "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for (const Row& r : rows) md += md_row(o, hd, r);
    md +=
        "\nTimes in seconds, median [min-max] over the runs, octree to V-map in memory; "
        "\"save s\" adds writing the .vmap. \"est.\": CPU leaf-pair rate measured on a sample "
        "of the matrix (blocks of 8 rows x 32 columns), scaled to all pairs, plus the host work "
        "of the GPU build. \"walked\": the share of leaf pairs the leaf-pair predicate walked "
        "(the rest decided at node level). Pairs/s count every "
        "unordered leaf pair, including those the facing test settles; \"GPU pairs/s\" is end to "
        "end (octree, "
        "visibility, links), \"GPU kernel pairs/s\" the leaf-pair kernel alone (CUDA events).\n";
    return md;
}

std::string csv_table(const Header& hd, const std::vector<Row>& rows) {
    std::string csv =
        "scene,points,height,leaf_points,leaves,leaf_pairs,leaf_pairs_walked,node_pairs_tested,"
        "links,cpu_s,cpu_s_min,cpu_s_max,cpu_estimated,gpu_s,gpu_s_min,gpu_s_max,gpu_pairs_s,"
        "gpu_kernel_s,cpu_pairs_s_core,facing_pairs,node_tests,occluder_tests,save_s,"
        "device_bytes,cpu_threads,device,commit,date\n";
    for (const Row& r : rows) csv += csv_row(hd, r);
    return csv;
}

Header table_header(const Session& s) {
    Header hd;
    hd.cores = tbb::this_task_arena::max_concurrency();
    char date[32];
    const std::time_t now = std::time(nullptr);
    std::strftime(date, sizeof date, "%Y-%m-%d", std::gmtime(&now));
    hd.date = date;
    if (s.have_gpu) hd.device = cuda_backend_name();
    return hd;
}

}  // namespace

int run(const Options& o) {
    if (o.runs < 1 || o.runs > 100) throw Error("--runs: must be 1..100");
    if (!o.out_dir.empty()) io::make_output_folder(o.out_dir, "--out");
    Session s(o);
    pick_backends(s);
    const bool tty = isatty(2);
    s.tmp = (std::filesystem::temp_directory_path() /
             fmt::format("vmap-bench-{}.vmap", getpid()))
                .string();
    std::vector<Row> rows;
    for (const std::string& file : o.scenes) {
        Scene sc = load_scene(file);
        if (o.points) sc.points = o.points;
        const PointSet pts = sample_scene(sc);
        for (int h : o.heights) {
            if (tty) fmt::print(stderr, "\r\033[Kbench: {} height {}", sc.name, h);
            rows.push_back(bench_one(s, sc, pts, h));
        }
    }
    if (tty) fmt::print(stderr, "\r\033[K");
    const Header hd = table_header(s);
    const std::string md = md_table(o, hd, rows);
    fmt::print("{}", md);
    if (!o.out_dir.empty()) {
        io::write_file_atomic(o.out_dir + "/bench.md", md);
        io::write_file_atomic(o.out_dir + "/bench.csv", csv_table(hd, rows));
    }
    return 0;
}

}  // namespace vmap::bench
