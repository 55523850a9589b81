// `vmap build`: a scene, mesh or cloud (or the default scene) into a .vmap, alone or across
// the processes of mpirun (vmap/mpi.h), with a summary of what was built.
#include <fmt/format.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <memory>
#include <thread>
#include <nlohmann/json.hpp>

#include "apps/commands.h"
#include "vmap/error.h"
#include "vmap/files.h"
#include "vmap/input.h"
#include "vmap/io.h"
#include "vmap/mpi.h"
#include "vmap/scene.h"
#include "vmap/vmap.h"

namespace vmap::cli {
namespace {

namespace fs = std::filesystem;

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
    InputOptions input;  // the file and its overrides (vmap/input.h)
    std::string output;
    std::string normals = "keep";
    std::vector<double> viewpoint;
    bool count_links = false;
    bool json = false;
    bool shards = false;  // under mpirun: vmap/mpi.h
    std::string schedule = "dynamic";
    int chunks_per_rank = mpi::Options{}.chunks_per_rank;
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
    if (o.viewpoint.size() == 3)
        c.viewpoint = std::array<double, 3>{o.viewpoint[0], o.viewpoint[1], o.viewpoint[2]};
    return c;
}

nlohmann::json build_json(const BuildOptions& o, const VisibilityMap& vm, const BuildStats& st,
                          double input_s, size_t npts, double save_s, const SaveStats& ss) {
    const auto& w = st.work;
    nlohmann::json j = params_json(vm);
    j["input"] = o.input.path;
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
    j["lanes"] = st.lanes;
    j["seconds"] = {{"input", input_s},
                    {"total", st.seconds_total},
                    {"octree", st.seconds_octree},
                    {"visibility", st.seconds_visibility},
                    {"plan", st.seconds_plan},
                    {"wait", st.seconds_wait},
                    {"backend", st.seconds_backend},
                    {"extract", st.seconds_extract},
                    {"links", st.seconds_links},
                    {"save", save_s},
                    {"save_encode", ss.encode_seconds},
                    {"save_write", ss.write_seconds},
                    {"save_sync", ss.sync_seconds}};
    j["file_bytes"] = ss.bytes;
    j["peak_device_bytes"] = st.peak_device_bytes;
    j["warnings"] = st.warnings;
    j["output"] = o.count_links ? nlohmann::json(nullptr) : nlohmann::json(o.output);
    return j;
}

void print_build_details(const VisibilityMap& vm, const BuildStats& st, double input_s,
                         double save_s, const SaveStats& ss) {
    const auto& w = st.work;
    const int cores = tbb::this_task_arena::max_concurrency();
    fmt::print(
        "work:       {:.1f} node tests per facing pair, {:.2f} occluder tests per facing pair\n",
        double(w.node_tests) / std::max<uint64_t>(1, w.facing_pairs),
        double(w.occluder_tests) / std::max<uint64_t>(1, w.facing_pairs));
    fmt::print(
        "time:       input (read, sampled, completed) {:.3f} s, octree {:.3f} s, visibility + "
        "links {:.3f} s in {} batches\n",
        input_s, st.seconds_octree, st.seconds_visibility, st.batches);
    fmt::print(
        "            plan and node tests {:.3f} s, waiting on backend {:.3f} s, link extraction "
        "{:.3f} s{}, "
        "link arrays {:.3f} s; saving {:.3f} s\n",
        st.seconds_plan, st.seconds_wait, st.seconds_extract,
        st.lanes > 1 ? fmt::format(" (summed over {} lanes)", st.lanes) : std::string(),
        st.seconds_links, save_s);
    if (ss.bytes)
        fmt::print(
            "saving:     {:.1f} MB: laid out {:.3f} s, links coded, hashed and written {:.3f} s, "
            "synced to disk {:.3f} s\n",
            ss.bytes / 1e6, ss.encode_seconds, ss.write_seconds, ss.sync_seconds);
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
                         const BuildStats& st, size_t npts, double input_s, double save_s,
                         const SaveStats& ss) {
    const bool verbose = verbosity() == Verbosity::kVerbose;
    const auto& w = st.work;
    fmt::print("input:      {}\n", what);
    fmt::print("points:     {}\n", npts);
    print_params(vm);
    // The note (why not the GPU) went to stderr as the build began; here it rides on the
    // backend's line, so that a terminal does not show it twice as a note.
    fmt::print("backend:    {}{}\n", st.backend, st.note.empty() ? "" : "; " + st.note);
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
    if (verbose) print_build_details(vm, st, input_s, save_s, ss);
    if (!o.count_links) fmt::print("wrote:      {}\n", o.output);
}

// Checks what can be checked before any work, and the build parameters the input does not set.
void check_build(BuildOptions& o) {
    InputOptions& in = o.input;
    if (in.path.empty()) in.path = default_scene_path();
    if (o.output.empty()) o.output = fs::path(in.path).stem().string() + ".vmap";
    io::check_input_path(in.path);
    if (has_extension(in.path, ".vmap"))
        throw Error(
            fmt::format("{}: a .vmap is built already (info, query, render take it)", in.path));
    if (o.shards && !mpi::launched())
        throw UsageError("--shards: one file per rank, under mpirun only");
    if (!o.count_links) check_output(o.output, "-o", {in.path});
    in.cloud = cloud_options(o);
    o.params.progress = stderr_progress();
    in.progress = sampling_progress();
    o.params.keep_links = !o.count_links;
}

// Reads the input (vmap/input.h) and completes bp from it (o.params too).
PointSet read_build_input(BuildOptions& o, BuildParams& bp, std::string& what) {
    // A long build is announced before a scene is sampled, not after.
    bool warned = false;
    o.input.before_sampling = [&](uint64_t points, const OctreeParams& op) {
        warn_if_long(o.input.path, points, op);
        warned = true;
    };
    Input input = load_input(o.input);
    print_notes(input.notes);
    for (const std::string& line : input.done) fmt::print(stderr, "vmap build: {}\n", line);
    what = input.description;
    bp.octree = input.octree;
    o.params.octree = bp.octree;
    bp.visibility.roughness = o.params.visibility.roughness = input.roughness;
    if (!warned) warn_if_long(o.input.path, input.points.size(), bp.octree);
    return std::move(input.points);
}

// What names the input under mpirun, where rank 0 alone reads it: the file and each option that
// changes the points read (those given), e.g. "/data/scenes/a.json, points 3000, seed 7".
std::string input_key(const BuildOptions& o) {
    const InputOptions& in = o.input;
    // The file as an absolute path: ranks started from other folders name the same file alike.
    std::error_code ec;
    const fs::path full = fs::weakly_canonical(fs::path(in.path), ec);
    std::string key = ec ? in.path : full.string();
    auto add = [&](const char* name, const auto& v) {
        if (v) key += fmt::format(", {} {}", name, *v);
    };
    add("points", in.points);
    add("seed", in.seed);
    if (in.pattern) key += fmt::format(", sampling {}", name_of(*in.pattern));
    add("max-height", in.max_height);
    add("leaf-points", in.leaf_points);
    add("delta-floor", in.delta_floor);
    add("roughness", in.roughness);
    if (in.as_points) key += ", as points";
    if (o.normals != "keep") key += fmt::format(", normals {}", o.normals);
    if (const auto& v = in.cloud.viewpoint)
        key += fmt::format(", viewpoint {} {} {}", (*v)[0], (*v)[1], (*v)[2]);
    return key;
}

int run_build(BuildOptions& o) {
    std::string what;
    check_build(o);
    BuildStats st;
    size_t npts = 0;
    VisibilityMap vm;
    double save_s = 0, input_s = 0;
    SaveStats ss;  // the single process's save; mpirun's rank 0 reports only its time
    std::vector<std::string> ranks;
    if (mpi::launched()) {  // mpirun -np N vmap build: the ranks share the work, rank 0 reports
        auto read = [&](BuildParams& bp) {
            const auto ti = std::chrono::steady_clock::now();
            PointSet pts = read_build_input(o, bp, what);
            input_s = seconds_since(ti);
            npts = pts.size();
            return pts;
        };
        mpi::Result r = mpi::build(read, o.params,
                                   {o.output, o.shards, o.count_links, o.schedule, threads(),
                                    o.chunks_per_rank, input_key(o)},
                                   o.input.path);
        if (!r.root) return 0;  // rank 0 reports the job's result
        vm = std::move(r.vm), st = std::move(r.stats), save_s = r.save_seconds;
        ranks = std::move(r.summary);
    } else {
        // The GPU's context is made while the input is read (a copy of the params: reading may
        // set the octree's from the scene file).
        std::jthread warm([p = o.params] { warm_up_gpu(p); });
        const auto ti = std::chrono::steady_clock::now();
        PointSet pts = read_build_input(o, o.params, what);
        input_s = seconds_since(ti);
        warm.join();
        npts = pts.size();
        vm = build_vmap(std::move(pts), o.params, &st, o.input.path);
        const auto ts = std::chrono::steady_clock::now();
        if (!o.count_links) save_vmap(o.output, vm, &ss);
        save_s = seconds_since(ts);
    }
    for (const std::string& w : st.warnings) fmt::print(stderr, "vmap build: warning: {}\n", w);
    if (o.json)
        fmt::print("{}\n", build_json(o, vm, st, input_s, npts, save_s, ss).dump(2));
    else if (verbosity() != Verbosity::kQuiet)
        print_build_summary(o, what, vm, st, npts, input_s, save_s, ss);
    if (!o.json && verbosity() != Verbosity::kQuiet)
        for (const std::string& line : ranks) fmt::print("{}\n", line);
    return 0;
}

}  // namespace

// `vmap build`: a scene, mesh or cloud (or the default scene) into a .vmap.
Command add_build_command(CLI::App& app) {
    auto bo = std::make_shared<BuildOptions>();
    auto* build = app.add_subcommand("build", "Build the V-map of a scene or point cloud");
    add_input_options(build, bo->input,
                      "Scene file (.json), mesh (.ply with faces, .off, .obj, .stl: area-sampled) "
                      "or point cloud (.ply, .xyz, .xyzn, .xyzrgb, .pts, .pcd, ...; normals "
                      "estimated if absent). Default: scenes/cornell-bunny.json");
    build->add_option("-o,--output", bo->output, "Output .vmap file (default: <input name>.vmap)");
    add_predicate_options(build, bo->params.visibility);
    add_choice(build, "--backend", bo->params.backend, "auto (GPU when present), cpu or cuda");
    add_choice(build, "--occluders", bo->params.occluders,
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
    add_choice(build, "--construction", bo->params.construction,
               "auto (nodes: the faster on both backends), nodes "
               "(decide node pairs whole where bounds prove it) or leaf-pairs (walk every "
               "leaf pair: the oracle; the same V-map)");
    build
        ->add_option("--walk-pairs", bo->params.walk_pairs,
                     "Undecided node pairs of at most this many leaf pairs are walked, not split "
                     "(0: the backend's choice)")
        ->capture_default_str();
    build
        ->add_option("--lanes", bo->params.lanes,
                     "Frontiers driving the backend at once: one's host work overlaps the "
                     "others' GPU batches (0: the backend's choice, 3 on the GPU; the same V-map)")
        ->check(CLI::Range(0, 16))
        ->capture_default_str();
    build->add_flag("--count-links", bo->count_links,
                    "Count the links without keeping them and write no file: sizes a V-map "
                    "too large for memory");

    build->add_flag("--json", bo->json, "Print the summary as one JSON object (for scripts)");
    build
        ->add_option("--device", bo->params.device,
                     "CUDA device (of those CUDA_VISIBLE_DEVICES leaves); default 0, under "
                     "mpirun the rank's local rank")
        ->check(CLI::Range(0, 1023));
    build->add_flag("--shards", bo->shards,
                    "Under mpirun: one file of links per rank and -o an index of them (for maps "
                    "beyond one host's memory; load and the queries read it as one map)");
    build
        ->add_option("--schedule", bo->schedule,
                     "Under mpirun: dynamic (rank 0 hands out small chunks of jobs to whichever "
                     "rank asks: balanced better, docs/scaling.md) or static (a share each by a "
                     "work estimate)")
        ->check(CLI::IsMember({"static", "dynamic"}))
        ->capture_default_str();
    build
        ->add_option("--chunks-per-rank", bo->chunks_per_rank,
                     "Under mpirun, dynamic schedule: chunks of jobs per rank (more balance "
                     "better, each costs a message and a round; the same map at any number)")
        ->check(CLI::Range(1, 4096))
        ->capture_default_str();
    return {
        build, [bo]() {
            const bool sampled =
                bo->input.path.empty() || sampled_input(bo->input.path, bo->input.as_points);
            if (sampled && (bo->normals != "keep" || !bo->viewpoint.empty())) {
                fmt::print(
                    stderr,
                    "vmap build: --normals/--viewpoint apply to point clouds, not to scene or "
                    "mesh files (their normals come from the meshes)\n");
                return 2;
            }
            if ((bo->input.points || bo->input.seed) && !bo->input.path.empty() &&
                !sampled_input(bo->input.path, bo->input.as_points)) {
                fmt::print(
                    stderr,
                    "vmap build: --points/--seed apply to scene and mesh files, not to the point "
                    "cloud {}\n",
                    bo->input.path);
                return 2;
            }
            return run_build(*bo);
        }};
}

}  // namespace vmap::cli
