// vmap: view-independent mutual visibility for point models.
//   vmap build [SCENE.json | MESH | CLOUD] -o out.vmap  octree + V-map, with a summary
//   vmap info out.vmap                                what a .vmap holds
//   vmap query out.vmap --pair I J | --from I | --ray I --dir D   (apps/query_cmd.cpp)
//   vmap render [SCENE | CLOUD | out.vmap] --mode M   pictures (apps/render_cmd.cpp)
//   vmap bench-query                                  query latency vs scene size
//   vmap gi [SCENE | out.vmap] -o lit.png             global illumination (apps/gi_cmd.cpp)
//   vmap bench-gi                                     GI time per bounce vs points
//   vmap view [out.vmap | SCENE]                      browser viewer (apps/view_cmd.cpp)
// Exit codes: 0 success, 1 an error in the input or while running, 2 a usage error.
#include <fmt/format.h>
#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/task_arena.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>

#include "apps/commands.h"
#include "apps/gi_cmd.h"
#include "apps/validate_cmd.h"
#include "bench/bench.h"
#include "io/atomic_file.h"
#include "mpi/mpi_build.h"
#include "util/progress.h"
#include "vmap/error.h"
#include "vmap/scene.h"
#include "vmap/version.h"
#include "vmap/vmap.h"

namespace {

using namespace vmap;
namespace fs = std::filesystem;

void print_tree_summary(const VisibilityMap& vm) {
    const Octree& t = vm.octree();
    int h = 0;  // deepest node (not only leaf), so every level below indexes in range
    for (int32_t n = 0; n < t.num_nodes(); ++n) h = std::max(h, int(t.level()[n]));
    std::vector<uint64_t> nodes(h + 1), leaves(h + 1), links(h + 1);
    for (int32_t n = 0; n < t.num_nodes(); ++n) {
        nodes[t.level()[n]]++;
        if (t.is_leaf(n)) leaves[t.level()[n]]++;
        for (int32_t m : vm.links(n))
            if (m > n) links[t.level()[n]]++;  // count each link once, at its first end's level
    }
    fmt::print("  level      nodes     leaves      links\n");
    for (int l = 0; l <= h; ++l)
        fmt::print("  {:5d} {:10d} {:10d} {:10d}\n", l, nodes[l], leaves[l], links[l]);
}

void print_params(const VisibilityMap& vm) {
    const auto& o = vm.octree_params();
    const auto& v = vm.visibility_params();
    fmt::print("octree:     max_height {}, leaf_points {} -> height {}, {} nodes, {} leaves\n",
               o.max_height, o.leaf_points, vm.octree().height(), vm.octree().num_nodes(),
               vm.octree().num_leaves());
    fmt::print("predicate:  K {}, eps {}, facing_tol {}, parallel_tol {}\n", v.K, v.eps,
               v.facing_tol, v.parallel_tol);
}

// Leaf pairs walked against all, and the node pairs per octree level.
void print_construction(const BuildStats& st) {
    fmt::print(
        "construction: {}: {} of {} leaf pairs walked ({:.1f}%), {} node pairs tested ({:.1f} "
        "tree nodes each)\n",
        st.construction, st.leaf_pairs_walked, st.leaf_pairs,
        100.0 * st.leaf_pairs_walked / std::max<uint64_t>(1, st.leaf_pairs), st.node_pairs_tested,
        double(st.shaft_node_tests) / std::max<uint64_t>(1, st.node_pairs_tested));
    if (st.construction != "nodes") return;
    fmt::print("  level node-pairs     tested    visible  invisible      split     walked\n");
    for (size_t l = 0; l < st.levels.size(); ++l) {
        const ConstructionLevel& c = st.levels[l];
        if (c.pairs == 0) continue;
        fmt::print("  {:5d} {:10d} {:10d} {:10d} {:10d} {:10d} {:10d}\n", l, c.pairs, c.tested,
                   c.visible, c.invisible, c.split, c.walked);
    }
}

struct BuildOptions {
    std::string input;
    std::string output;
    std::optional<uint64_t> points, seed;
    std::optional<int> max_height, leaf_points;
    std::string normals = "keep";
    std::vector<float> viewpoint;
    bool count_links = false;
    bool as_points = false;
    bool json = false;
    bool shards = false;                // under mpirun: src/mpi/mpi_build.h
    std::string schedule = "static";
    int threads = 0;
    BuildParams params;
};

CloudOptions cloud_options(const BuildOptions& o) {
    CloudOptions c;
    const std::pair<const char*, NormalsMode> modes[] = {{"keep", NormalsMode::kKeep},
                                                         {"flip", NormalsMode::kFlip},
                                                         {"inward", NormalsMode::kInward},
                                                         {"outward", NormalsMode::kOutward},
                                                         {"estimate", NormalsMode::kEstimate}};
    for (const auto& [name, mode] : modes)
        if (o.normals == name) c.normals = mode;
    if (o.viewpoint.size() == 3) c.viewpoint = Vec3{o.viewpoint[0], o.viewpoint[1], o.viewpoint[2]};
    return c;
}

// The input's points and a description of it: a scene or mesh file is sampled (scene options
// apply), a point cloud is read as it is.
PointSet load_input(BuildOptions& o, std::string& what) {
    if (!is_scene_input(o.input, o.as_points)) {
        if (o.points || o.seed)
            throw Error("--points/--seed apply to scene and mesh files, not point clouds");
        what = fmt::format("point cloud {}", o.input);
        std::vector<std::string> done;
        PointSet pts = load_point_cloud(o.input, cloud_options(o), &done);
        for (const std::string& line : done) fmt::print(stderr, "vmap build: {}\n", line);
        return pts;
    }
    Scene sc = load_scene(o.input);
    cli::print_notes(sc.notes);
    if (o.points) sc.points = *o.points;
    if (o.seed) sc.seed = *o.seed;
    if (sc.octree) o.params.octree = *sc.octree;
    what = has_extension(o.input, ".json")
               ? fmt::format("scene {} ({}), {} surfaces", sc.name, o.input, sc.surfaces.size())
               : fmt::format("mesh {} ({} triangles, area-sampled)", o.input,
                             sc.surfaces[0].mesh.triangles.size());
    return sample_scene(sc);
}

// A float as the shortest decimal that reads back to it (0.01, not 0.009999999776).
double short_decimal(float f) { return std::stod(fmt::format("{}", f)); }

nlohmann::json params_json(const VisibilityMap& vm) {
    const auto& o = vm.octree_params();
    const auto& v = vm.visibility_params();
    return {{"max_height", o.max_height},
            {"leaf_points", o.leaf_points},
            {"height", vm.octree().height()},
            {"nodes", vm.octree().num_nodes()},
            {"leaves", vm.octree().num_leaves()},
            {"K", v.K},
            {"eps", short_decimal(v.eps)},
            {"facing_tol", short_decimal(v.facing_tol)},
            {"parallel_tol", short_decimal(v.parallel_tol)}};
}

nlohmann::json build_json(const BuildOptions& o, const VisibilityMap& vm, const BuildStats& st,
                          size_t npts, double save_s) {
    const auto& w = st.work;
    nlohmann::json j = params_json(vm);
    j["input"] = o.input;
    j["points"] = npts;
    j["backend"] = st.backend;
    j["note"] = st.note;
    j["construction"] = st.construction;
    j["leaf_pairs"] = st.leaf_pairs ? st.leaf_pairs : w.pairs;
    j["leaf_pairs_walked"] = w.pairs;
    j["node_pairs_tested"] = st.node_pairs_tested;
    j["facing_pairs"] = w.facing_pairs;
    j["visible_pairs"] = w.visible_pairs;
    j["node_tests"] = w.node_tests;
    j["occluder_tests"] = w.occluder_tests;
    j["links"] = st.links;
    j["links_kept"] = !o.count_links;
    j["batches"] = st.batches;
    j["seconds"] = {{"total", st.seconds_total},
                    {"octree", st.seconds_octree},
                    {"visibility", st.seconds_visibility},
                    {"plan", st.seconds_plan},
                    {"wait", st.seconds_wait},
                    {"backend", st.seconds_backend},
                    {"extract", st.seconds_extract},
                    {"links", st.seconds_links},
                    {"save", save_s}};
    j["peak_device_bytes"] = st.peak_device_bytes;
    j["warnings"] = st.warnings;
    j["output"] = o.count_links ? nlohmann::json(nullptr) : nlohmann::json(o.output);
    return j;
}

void print_build_details(const VisibilityMap& vm, const BuildStats& st, double save_s) {
    const auto& w = st.work;
    const int cores = tbb::this_task_arena::max_concurrency();
    fmt::print(
        "work:       {:.1f} node tests per facing pair, {:.2f} occluder tests per facing pair\n",
        double(w.node_tests) / std::max<uint64_t>(1, w.facing_pairs),
        double(w.occluder_tests) / std::max<uint64_t>(1, w.facing_pairs));
    fmt::print("time:       octree {:.3f} s, visibility + links {:.3f} s in {} batches\n",
               st.seconds_octree, st.seconds_visibility, st.batches);
    fmt::print(
        "            plan and node tests {:.3f} s, waiting on backend {:.3f} s, link extraction "
        "{:.3f} s, "
        "link arrays {:.3f} s; saving {:.3f} s\n",
        st.seconds_plan, st.seconds_wait, st.seconds_extract, st.seconds_links, save_s);
    const double pps = w.pairs / std::max(1e-9, st.seconds_visibility);
    fmt::print(
        "throughput: {:.3g} leaf pairs/s end to end ({:.3g} per core on {} cores); the "
        "backend alone {:.3g} leaf pairs/s ({:.3f} s)\n",
        pps, pps / cores, cores, w.pairs / std::max(1e-9, st.seconds_backend), st.seconds_backend);
    if (st.peak_device_bytes)
        fmt::print("device:     peak {:.1f} MiB\n", st.peak_device_bytes / 1048576.0);
    if (vm.has_links()) print_tree_summary(vm);
}

void print_build_summary(const BuildOptions& o, const std::string& what, const VisibilityMap& vm,
                         const BuildStats& st, size_t npts, double save_s) {
    const bool verbose = cli::verbosity() == cli::Verbosity::kVerbose;
    const auto& w = st.work;
    fmt::print("input:      {}\n", what);
    fmt::print("points:     {}\n", npts);
    print_params(vm);
    if (!st.note.empty()) fmt::print("note:       {}\n", st.note);
    fmt::print("backend:    {}\n", st.backend);
    fmt::print("leaf pairs: {} tested, {} facing ({:.1f}%), {} visible ({:.1f}%)\n", w.pairs,
               w.facing_pairs, 100.0 * w.facing_pairs / std::max<uint64_t>(1, w.pairs),
               w.visible_pairs, 100.0 * w.visible_pairs / std::max<uint64_t>(1, w.pairs));
    print_construction(st);
    if (o.count_links)
        fmt::print("links:      {} counted, not kept (as link ends they would take {:.2f} GiB)\n",
                   st.links, st.links * 8 / 1073741824.0);
    else
        fmt::print("links:      {} ({} bytes as link ends)\n", st.links, st.links * 8);
    fmt::print("time:       {:.3f} s total{}\n", st.seconds_total,
               verbose ? "" : " (-v for the breakdown and the links per level)");
    if (verbose) print_build_details(vm, st, save_s);
    if (!o.count_links) fmt::print("wrote:      {}\n", o.output);
}

int run_build(BuildOptions& o) {
    if (o.input.empty()) o.input = default_scene_path();
    if (o.output.empty()) o.output = fs::path(o.input).stem().string() + ".vmap";
    io::check_input_path(o.input);
    if (o.shards && !mpi::launched())
        throw cli::UsageError("--shards: one file per rank, under mpirun only");
    if (!o.count_links) cli::check_output(o.output, "-o", {o.input});
    std::string what;
    PointSet pts = load_input(o, what);
    BuildParams& bp = o.params;
    if (o.max_height) bp.octree.max_height = *o.max_height;
    if (o.leaf_points) bp.octree.leaf_points = *o.leaf_points;
    cli::warn_if_long(o.input, pts.size(), bp.octree);
    bp.progress = cli::stderr_progress();
    bp.keep_links = !o.count_links;

    BuildStats st;
    const size_t npts = pts.size();
    VisibilityMap vm;
    double save_s = 0;
    std::vector<std::string> ranks;
    if (mpi::launched()) {  // mpirun -np N vmap build: the ranks share the work, rank 0 reports
        mpi::Result r = mpi::build(std::move(pts), bp,
                                   {o.output, o.shards, o.count_links, o.schedule, o.threads},
                                   o.input);
        if (!r.root) return r.exit_code;
        vm = std::move(r.vm), st = std::move(r.stats), save_s = r.save_seconds;
        ranks = std::move(r.summary);
    } else {
        vm = build_vmap(std::move(pts), bp, &st, o.input);
        const auto ts = std::chrono::steady_clock::now();
        if (!o.count_links) save_vmap(o.output, vm);
        save_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
    }
    for (const std::string& w : st.warnings) fmt::print(stderr, "vmap build: warning: {}\n", w);
    if (o.json)
        fmt::print("{}\n", build_json(o, vm, st, npts, save_s).dump(2));
    else if (cli::verbosity() != cli::Verbosity::kQuiet)
        print_build_summary(o, what, vm, st, npts, save_s);
    if (!o.json && cli::verbosity() != cli::Verbosity::kQuiet)
        for (const std::string& line : ranks) fmt::print("{}\n", line);
    return 0;
}

int run_info(const std::string& path, bool json) {
    io::check_input_path(path);
    VisibilityMap vm = load_vmap(path);
    if (json) {
        nlohmann::json j = params_json(vm);
        j["file"] = path;
        j["bytes"] = fs::file_size(path);
        j["points"] = vm.points().size();
        j["links"] = vm.num_links();
        const Octree& t = vm.octree();
        int h = 0;
        for (int32_t n = 0; n < t.num_nodes(); ++n) h = std::max(h, int(t.level()[n]));
        std::vector<uint64_t> links_per_level(h + 1);
        for (int32_t n = 0; n < t.num_nodes(); ++n)
            for (int32_t m : vm.links(n))
                if (m > n) links_per_level[t.level()[n]]++;
        j["links_per_level"] = links_per_level;
        fmt::print("{}\n", j.dump(2));
        return 0;
    }
    fmt::print("file:       {} ({} bytes)\n", path, fs::file_size(path));
    fmt::print("points:     {}\n", vm.points().size());
    print_params(vm);
    fmt::print("links:      {}\n", vm.num_links());
    print_tree_summary(vm);
    return 0;
}

std::string command_names(CLI::App& app) {
    std::string names;
    for (const CLI::App* s : app.get_subcommands({}))
        names += (names.empty() ? "" : ", ") + s->get_name();
    return names;
}

// The first word that is not an option (nor --threads' value) when it names no subcommand:
// says so, with the list, and returns true.
bool report_unknown_command(CLI::App& app, int argc, char** argv) {
    for (int i = 1; i < argc; ++i) {
        const std::string w = argv[i];
        if (w == "--threads") {
            ++i;
            continue;
        }
        if (w.empty() || w[0] == '-') continue;
        for (const CLI::App* sub : app.get_subcommands({}))
            if (sub->check_name(w)) return false;  // a known command: CLI11 says what is wrong
        fmt::print(stderr, "vmap: unknown command '{}' (the commands: {}; see vmap --help)\n", w,
                   command_names(app));
        return true;
    }
    for (int i = 1; i < argc; ++i)
        if (std::string(argv[i]) != "--threads" || ++i == argc) return false;
    fmt::print(stderr, "vmap: no command given (the commands: {}; see vmap --help)\n",
               command_names(app));
    return true;
}

// `vmap build`: a scene, mesh or cloud (or the default scene) into a .vmap.
cli::Command add_build_command(CLI::App& app, const int* threads) {
    auto bo = std::make_shared<BuildOptions>();
    auto* build = app.add_subcommand("build", "Build the V-map of a scene or point cloud");
    build->add_option("input", bo->input,
                      "Scene file (.json), mesh (.ply with faces, .off, .obj, .stl: area-sampled) "
                      "or point cloud (.ply, .xyz, .xyzn, .xyzrgb, .pts, .pcd, ...; normals "
                      "estimated if absent). Default: scenes/cornell-bunny.json");
    build->add_option("-o,--output", bo->output, "Output .vmap file (default: <input name>.vmap)");
    build->add_flag("--as-points", bo->as_points,
                    "Take a mesh file's vertices as a point cloud instead of sampling its faces");
    build->add_option("--points", bo->points, "Override the scene's number of sample points")
        ->check(CLI::Range(uint64_t(1), uint64_t(50000000)));
    build->add_option("--seed", bo->seed, "Override the scene's sampling seed");
    build
        ->add_option("--max-height", bo->max_height,
                     "Deepest octree level (root = 0); default: the scene's octree.max_height, "
                     "else 9")
        ->check(CLI::Range(1, 21));
    build
        ->add_option("--leaf-points", bo->leaf_points,
                     "Split nodes with more points than this; default: the scene's "
                     "octree.leaf_points, else 4")
        ->check(CLI::Range(1, 1000000));
    cli::add_predicate_options(build, bo->params.visibility);
    cli::add_choice(build, "--backend", bo->params.backend, "auto (GPU when present), cpu or cuda");
    cli::add_choice(build, "--occluders", bo->params.occluders,
                    "Potential occluders: boxes (walk of the octree, pruned by node boxes) or "
                    "grid (grid walk of [7], CPU only); spheres and bresenham are old names");
    build
        ->add_option("--batch-pairs", bo->params.max_batch_pairs,
                     "Leaf pairs evaluated per batch (bounds memory)")
        ->check(CLI::Range(uint64_t(1024), uint64_t(1) << 40))
        ->capture_default_str();

    build
        ->add_option("--normals", bo->normals,
                     "Point clouds: keep (the file's normals; estimated if it has none), flip, "
                     "inward or outward (from the centroid), estimate (even if the file has "
                     "them)")
        ->check(CLI::IsMember({"keep", "flip", "inward", "outward", "estimate"}))
        ->capture_default_str();
    build
        ->add_option("--viewpoint", bo->viewpoint,
                     "Point clouds: orient every normal toward this point X,Y,Z (the scanner)")
        ->delimiter(',')
        ->expected(3);
    cli::add_choice(build, "--construction", bo->params.construction,
                    "auto (nodes on the CPU, leaf-pairs on the GPU: the faster there), nodes "
                    "(decide node pairs whole where bounds prove it) or leaf-pairs (walk every "
                    "leaf pair: the oracle; the same V-map)");
    build
        ->add_option("--walk-pairs", bo->params.walk_pairs,
                     "Undecided node pairs of at most this many leaf pairs are walked, not split "
                     "(0: the backend's choice)")
        ->capture_default_str();
    build->add_flag("--count-links", bo->count_links,
                    "Count the links without keeping them and write no file: sizes a V-map "
                    "too large for memory");

    build->add_flag("--json", bo->json, "Print the summary as one JSON object (for scripts)");
    build->add_option("--device", bo->params.device,
                      "CUDA device (of those CUDA_VISIBLE_DEVICES leaves); default 0, under "
                      "mpirun the rank's local rank")
        ->check(CLI::Range(0, 1023));
    build->add_flag("--shards", bo->shards,
                    "Under mpirun: one file of links per rank and -o an index of them (for maps "
                    "beyond one host's memory; load and the queries read it as one map)");
    build->add_option("--schedule", bo->schedule,
                      "Under mpirun: static (a share each by a work estimate: balanced better, "
                      "docs/scaling.md) or dynamic (rank 0 hands out chunks of jobs)")
        ->check(CLI::IsMember({"static", "dynamic"}))
        ->capture_default_str();
    return {
        build, [bo, threads]() {
            bo->threads = *threads;  // under mpirun: per rank
            const bool sampled = bo->input.empty() || cli::sampled_input(bo->input, bo->as_points);
            if (sampled && (bo->normals != "keep" || !bo->viewpoint.empty())) {
                fmt::print(
                    stderr,
                    "vmap build: --normals/--viewpoint apply to point clouds, not to scene or "
                    "mesh files (their normals come from the meshes)\n");
                return 2;
            }
            if ((bo->points || bo->seed) && !bo->input.empty() &&
                !cli::sampled_input(bo->input, bo->as_points)) {
                fmt::print(
                    stderr,
                    "vmap build: --points/--seed apply to scene and mesh files, not to the point "
                    "cloud {}\n",
                    bo->input);
                return 2;
            }
            return run_build(*bo);
        }};
}

// `vmap info`: what a .vmap file holds.
cli::Command add_info_command(CLI::App& app) {
    auto path = std::make_shared<std::string>();
    auto json = std::make_shared<bool>(false);
    auto* info = app.add_subcommand("info", "Describe a .vmap file");
    info->add_option("file", *path, "The .vmap file")->required();
    info->add_flag("--json", *json, "Print it as one JSON object (for scripts)");
    return {info, [path, json]() { return run_info(*path, *json); }};
}

// `vmap bench`: the construction table (bench/bench.cpp).
cli::Command add_bench_command(CLI::App& app) {
    auto bo2 = std::make_shared<bench::Options>();
    auto* benchc = app.add_subcommand(
        "bench", "Time V-map construction, CPU vs GPU, per scene and height (paper Fig. 10)");
    benchc->add_option("--scene", bo2->scenes,
                       "Scene files (default: cornell-bunny, cornell-dragon, cornell-two-models)");
    benchc->add_option("--heights", bo2->heights, "Octree heights")
        ->delimiter(',')
        ->check(CLI::Range(1, 21));
    benchc->add_option("--leaf-points", bo2->leaf_points, "leaf_points for every run")
        ->check(CLI::Range(1, 1000000))
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
    cli::add_choice(benchc, "--construction", bo2->construction,
                    "auto, nodes or leaf-pairs (as for build)");
    return {benchc, [bo2]() {
                if (bo2->scenes.empty())
                    for (const char* n : {"cornell-bunny", "cornell-dragon", "cornell-two-models"})
                        bo2->scenes.push_back(data_dir() + "/scenes/" + n + ".json");
                return bench::run(*bo2);
            }};
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{
        "vmap: view-independent mutual visibility for point models.\n"
        "Builds an adaptive octree over a point model, computes which leaf pairs see each other\n"
        "(on a CUDA GPU or on all CPU cores) and stores the result as a visibility map of links\n"
        "between octree nodes.\n\n"
        "Start:  vmap build                       (the default scene, scenes/cornell-bunny.json)\n"
        "        vmap build scenes/cornell-dragon.json -o dragon.vmap --max-height 8\n"
        "        vmap query dragon.vmap --pair 10 2000\n"};
    app.require_subcommand(1);
    app.fallthrough();  // global options (--threads) may also follow the subcommand
    int threads = 0;
    app.add_option("--threads", threads, "CPU threads (default: all cores)")
        ->check(CLI::Range(0, 4096));
    app.set_version_flag(
        "--version", fmt::format("vmap {} (commit {}, CUDA {})", vmap::version(), vmap::commit(),
                                 built_with_cuda() ? "on" : "off"));
    bool verbose = false, quiet = false;
    auto* vflag = app.add_flag("-v,--verbose", verbose, "Say more: timing breakdowns, tables");
    app.add_flag("-q,--quiet", quiet, "Say nothing but errors and the output asked for")
        ->excludes(vflag);

    const cli::Command build = add_build_command(app, &threads), info = add_info_command(app),
                       query = cli::add_query_command(app), render = cli::add_render_command(app),
                       bench_query = cli::add_bench_query_command(app),
                       view = cli::add_view_command(app);
    const cli::GiCommands gi = cli::add_gi_commands(app);
    const cli::Command benchc = add_bench_command(app);
    auto* validate = cli::add_validate_command(app);

    cli::harden_options(app);
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        if (app.get_subcommands().empty() && report_unknown_command(app, argc, argv)) return 2;
        const int rc = app.exit(e);
        return rc == 0 ? 0 : 2;
    }
    cli::verbosity() = quiet     ? cli::Verbosity::kQuiet
                       : verbose ? cli::Verbosity::kVerbose
                                 : cli::Verbosity::kNormal;
    // Commands whose stdout is a summary (not the answers asked for) print nothing with -q.
    if (quiet && (render.app->parsed() || bench_query.app->parsed() || *validate || gi.selected() ||
                  benchc.app->parsed()))
        if (!std::freopen("/dev/null", "w", stdout)) return 1;
    std::unique_ptr<tbb::global_control> limit;
    if (threads > 0)
        limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                      threads);
    try {
        for (const cli::Command* c : {&build, &info, &query, &render, &bench_query, &view, &benchc})
            if (c->app->parsed()) return c->run();
        if (*validate) return cli::run_validate_command();
        if (gi.selected()) return gi.run();
    } catch (const cli::UsageError& e) {
        fmt::print(stderr, "vmap: error: {}\n", e.what());
        return 2;
    } catch (const vmap::Error& e) {
        fmt::print(stderr, "vmap: error: {}\n", e.what());
        return 1;
    } catch (const std::bad_alloc&) {
        fmt::print(stderr, "vmap: error: out of memory (try a smaller --max-height or --points)\n");
        return 1;
    } catch (const std::exception& e) {
        fmt::print(stderr, "vmap: internal error: {}\n", e.what());
        return 1;
    }
    return 0;
}
