// `vmap bench-gi`: time per radiosity bounce against the number of points, hierarchical solver
// (CPU, and CUDA when a device is present) and the brute-force gather over every visible point
// pair (up to --brute-max points), with medians, spread, the work per bounce and the fitted
// log-log slopes (time ~ points^slope). The one-off setup (node sums, refinement, upload) is
// reported apart from the bounces; the V-map build is not timed here (`vmap bench` does that).
#include "bench/stats.h"
#include "bench/gi_bench.h"

#include <fmt/format.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <optional>

#include "vmap/error.h"
#include "vmap/files.h"
#include "vmap/gi.h"
#include "vmap/scene.h"
#include "vmap/vmap.h"

namespace vmap::bench {
namespace {

using bench_stats::Stat;
using bench_stats::stat;
std::string fmt_stat(const Stat& s) {
    if (!s.done) return "-";
    return fmt::format("{:.3g} [{:.3g}-{:.3g}]", s.median, s.lo, s.hi);
}

struct Row {
    uint64_t points = 0;
    int32_t leaves = 0;
    uint64_t links = 0, interactions = 0, node_interactions = 0, brute_pairs = 0;
    Stat setup_cpu, cpu, setup_gpu, gpu, brute;
    double rms = -1;  // hierarchical vs brute force after `bounces`
};

// Least-squares slope of log(y) on log(x) over the rows that have y.
double slope(const std::vector<Row>& rows, Stat Row::*m) {
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    int n = 0;
    for (const Row& r : rows) {
        const Stat& s = r.*m;
        if (!s.done || s.median <= 0) continue;
        const double x = std::log(double(r.points)), y = std::log(s.median);
        sx += x, sy += y, sxx += x * x, sxy += x * y, ++n;
    }
    if (n < 2) return NAN;
    return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

// What one `vmap bench-gi` call carries from size to size.
struct GiSession {
    explicit GiSession(GiBenchOptions& opts) : o(opts) {}
    GiBenchOptions& o;
    bool explicit_backends = false;
    bool gpu_used = false;
    std::string gpu_name;
};

// `runs` solves of `bounces` bounces on backend `be`; the CPU's first solution goes to `hier`.
// No device for cuda: dropped with a note (an error if cuda was asked for).
void time_solver(GiSession& s, const VisibilityMap& vm, const std::string& be, Row& r,
                 std::vector<Vec3>& hier) {
    GiBenchOptions& o = s.o;
    GiParams gp;
    gp.theta = o.theta;
    gp.backend = parse<Backend>(be, "--backends");
    gp.refine = parse<GiRefine>(o.refine, "--refine");
    std::vector<double> setup, per;
    for (int run = 0; run < o.runs; ++run) {
        // Backend cuda without a device: the solver refuses (vmap::Error; it falls back only for
        // backend auto). Asked for by name, that is the command's error; by default the table
        // leaves the GPU column out.
        std::optional<RadiositySolver> made;
        try {
            made.emplace(vm, gp);
        } catch (const Error& e) {
            if (be != "cuda" || s.explicit_backends) throw;
            fmt::print(stderr, "bench-gi: no GPU column ({})\n", e.what());
            o.backends.pop_back();
            break;
        }
        RadiositySolver& solver = *made;
        const GiStats& st = solver.stats();
        if (be == "cuda") s.gpu_used = true, s.gpu_name = st.backend;
        setup.push_back(st.seconds_setup);
        r.interactions = st.interactions();
        r.node_interactions = st.node_interactions;
        for (int b = 0; b < o.bounces; ++b) solver.bounce();
        const auto& sb = solver.stats().seconds_bounce;
        per.insert(per.end(), sb.begin(), sb.end());
        if (run == 0 && be == "cpu") hier = solver.radiosity();
    }
    (be == "cpu" ? r.setup_cpu : r.setup_gpu) = stat(setup);
    (be == "cpu" ? r.cpu : r.gpu) = stat(per);
}

// The brute-force gather (2 bounces x max(1, runs/2)) and the hierarchical solution's error.
void time_brute(const GiBenchOptions& o, const VisibilityMap& vm, const std::vector<Vec3>& hier,
                Row& r) {
    std::vector<double> per;
    std::vector<Vec3> B;
    for (int run = 0; run < std::max(1, o.runs / 2); ++run)
        B = brute_force_radiosity(vm, std::min(o.bounces, 2), nullptr, &per, &r.brute_pairs);
    r.brute = stat(per);
    if (!hier.empty() && o.bounces <= 2) r.rms = relative_rms(hier, B);
    if (!hier.empty() && o.bounces > 2) {
        // The error after `bounces`: one more brute-force solve of full length.
        r.rms = relative_rms(hier, brute_force_radiosity(vm, o.bounces));
    }
}

Row bench_size(GiSession& s, const Scene& base, uint64_t n) {
    const GiBenchOptions& o = s.o;
    Scene sc = base;
    sc.points = n;
    BuildParams bp;
    bp.octree.max_height = o.max_height;
    bp.octree.leaf_points = o.leaf_points;
    bp.backend = Backend::kAuto;
    const VisibilityMap vm = build_vmap(sample_scene(sc), bp, nullptr, o.scene);
    Row r;
    r.points = vm.points().size();
    r.leaves = vm.octree().num_leaves();
    r.links = vm.num_links();
    std::vector<Vec3> hier;
    for (const std::string& be : {std::string("cpu"), std::string("cuda")})
        if (std::find(o.backends.begin(), o.backends.end(), be) != o.backends.end())
            time_solver(s, vm, be, r, hier);
    if (r.points <= o.brute_max) time_brute(o, vm, hier, r);
    return r;
}

std::string md_table(const GiSession& s, const std::vector<Row>& rows) {
    const GiBenchOptions& o = s.o;
    char host[256] = {0};
    gethostname(host, sizeof(host) - 1);
    const std::time_t now = std::time(nullptr);
    char date[64];
    std::strftime(date, sizeof(date), "%Y-%m-%d %H:%M UTC", std::gmtime(&now));
    std::string md = fmt::format(
        "Scene {}, refine {}, theta {}, octree max_height {} leaf_points {}; {} bounces x {} runs "
        "per backend; host {} ({} threads){}; {}.\n\n",
        std::filesystem::path(o.scene).filename().string(), o.refine, o.theta, o.max_height,
        o.leaf_points, o.bounces, o.runs, host, tbb::this_task_arena::max_concurrency(),
        s.gpu_used ? ", GPU " + s.gpu_name : "", date);
    md +=
        "| points | leaves | links | interactions (node level) | setup CPU s | bounce CPU s | "
        "setup GPU s | bounce GPU s | brute pairs | bounce brute s | rel. RMS vs brute |\n";
    md += "|---|---|---|---|---|---|---|---|---|---|---|\n";
    for (const Row& r : rows)
        md += fmt::format("| {} | {} | {} | {} ({}) | {} | {} | {} | {} | {} | {} | {} |\n",
                          r.points, r.leaves, r.links, r.interactions, r.node_interactions,
                          fmt_stat(r.setup_cpu), fmt_stat(r.cpu), fmt_stat(r.setup_gpu),
                          fmt_stat(r.gpu), r.brute.done ? fmt::format("{}", r.brute_pairs) : "-",
                          fmt_stat(r.brute), r.rms >= 0 ? fmt::format("{:.4f}", r.rms) : "-");
    auto sl = [&](Stat Row::*m) {
        const double v = slope(rows, m);
        return std::isnan(v) ? std::string("-") : fmt::format("{:.2f}", v);
    };
    md += fmt::format(
        "\nLog-log slopes of the median time per bounce against points: hierarchical CPU {}, "
        "hierarchical GPU {}, brute force {}. Times are median [min-max] over every bounce of "
        "every run (brute force: 2 bounces x max(1, runs/2)).\n",
        sl(&Row::cpu), sl(&Row::gpu), sl(&Row::brute));
    return md;
}

std::string csv_table(const std::vector<Row>& rows) {
    std::string csv =
        "points,leaves,links,interactions,node_interactions,setup_cpu,bounce_cpu,"
        "bounce_cpu_lo,bounce_cpu_hi,setup_gpu,bounce_gpu,bounce_gpu_lo,bounce_gpu_hi,"
        "brute_pairs,bounce_brute,bounce_brute_lo,bounce_brute_hi,rms\n";
    for (const Row& r : rows)
        csv += fmt::format("{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n", r.points,
                           r.leaves, r.links, r.interactions, r.node_interactions,
                           r.setup_cpu.median, r.cpu.median, r.cpu.lo, r.cpu.hi,
                           r.setup_gpu.median, r.gpu.median, r.gpu.lo, r.gpu.hi, r.brute_pairs,
                           r.brute.median, r.brute.lo, r.brute.hi, r.rms);
    return csv;
}

}  // namespace

int run_gi(GiBenchOptions& o) {
    if (o.scene.empty()) o.scene = default_scene_path();
    if (!o.out_dir.empty()) io::make_output_folder(o.out_dir, "--out");
    GiSession s(o);
    // Default: cpu and cuda; cuda is dropped (with a note) when no device answers.
    s.explicit_backends = !o.backends.empty();
    if (!s.explicit_backends) o.backends = {"cpu", "cuda"};
    const Scene base = load_scene(o.scene);
    std::vector<Row> rows;
    for (uint64_t n : o.points) {
        rows.push_back(bench_size(s, base, n));
        fmt::print(stderr, "bench-gi: {} points done\n", rows.back().points);
    }
    const std::string md = md_table(s, rows);
    fmt::print("{}", md);
    if (!o.out_dir.empty()) {
        io::write_file_atomic(o.out_dir + "/bench-gi.md", md);
        io::write_file_atomic(o.out_dir + "/bench-gi.csv", csv_table(rows));
    }
    return 0;
}

}  // namespace vmap::bench
