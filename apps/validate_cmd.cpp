// `vmap validate SCENE...`: V-map answers against exact visibility (Embree rays on the scene's
// triangles) per octree height, as Markdown (stdout or --md) and JSON (--json); with
// --time-embree, Embree rays along leaf-centroid segments timed against the leaf-pair kernel.

#include <fmt/format.h>
#include <tbb/task_arena.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>

#include "apps/commands.h"
#include "vmap/error.h"
#include "vmap/files.h"
#include "vmap/validate.h"

namespace vmap::cli {
namespace {

struct Options {
    std::vector<std::string> scenes;
    ValidateParams vp;
    std::string md, json;
    bool time_embree = false;
    int runs = 5;
    uint64_t embree_pairs = 2000000;
    std::optional<float> roughness;  // --roughness: else measured for a raw cloud
};
Options opt;

void write_file(const std::string& path, const std::string& text, const char* what) {
    try {
        io::write_file_atomic(path, text);
    } catch (const Error& e) {
        throw Error(fmt::format("{}: {}", what, e.what()));
    }
}

}  // namespace

int run_validate_command();

namespace {

// The scenes, the pairs and the V-maps built per height.
void add_sample_options(CLI::App* c) {
    c->add_option("scene", opt.scenes,
                  "Scene files (.json) or mesh files (the mesh is its own truth)")
        ->required();
    c->add_option("--points", opt.vp.points, "Override the scene's number of sample points")
        ->check(CLI::Range(uint64_t(2), uint64_t(50000000)));
    c->add_option("--sampling", opt.vp.sampling,
                  "The samples' pattern instead of the scene's: blue-noise or uniform (the "
                  "octree's disc floor follows it unless --splat-floor is given)")
        ->check(CLI::IsMember(names_of<SamplePattern>()));
    c->add_option("--pairs", opt.vp.pairs, "Random point pairs")
        ->check(CLI::Range(uint64_t(1), uint64_t(1000000000)))
        ->capture_default_str();
    c->add_option("--seed", opt.vp.pair_seed, "Seed of the pair sample")->capture_default_str();
    c->add_option("--heights", opt.vp.heights, "Octree max_height values (default 5..10)")
        ->delimiter(',')
        ->check(max_height_check());
    c->add_option("--leaf-points", opt.vp.leaf_points,
                  "Split nodes with more points than this (default: the scene's)")
        ->check(leaf_points_check());
    cli::add_predicate_options(c, opt.vp.visibility);
    cli::add_choice(c, "--occluders", opt.vp.occluders,
                    "Potential occluders: boxes (walk of the octree, pruned by node boxes) or grid "
                    "(grid walk of "
                    "[7], CPU only)");
    cli::add_choice(c, "--backend", opt.vp.backend, "V-map build backend: auto, cpu or cuda");
}

// How the V-map's answers are predicted and what is scored.
void add_predict_options(CLI::App* c) {
    c->add_option("--predict", opt.vp.predict,
                  "vmap (build and query the V-map per height: all leaf pairs, minutes per "
                  "height beyond ~50k points on a few CPU cores) or direct (the leaf-pair "
                  "predicate on the sampled pairs' leaves only: the same answers, in seconds)")
        ->check(CLI::IsMember({"vmap", "direct"}))
        ->capture_default_str();
    c->add_option("--delta-scale", opt.vp.delta_scale,
                  "With --predict direct: Delta = scale * max(farthest point, floor * splat)")
        ->check(CLI::Range(0.1f, 10.f))
        ->capture_default_str();
    c->add_option("--splat-floor", opt.vp.splat_floor,
                  "With --predict direct: the splat radius multiple Delta never goes below "
                  "(default: the octree's own, src/octree/delta_rule.h)")
        ->check(CLI::Range(0.f, 10.f));
    c->add_option("--ray-offset", opt.vp.ray_offset,
                  "Truth rays skip this fraction of the room size at both ends")
        ->check(CLI::Range(1e-7, 0.01))
        ->capture_default_str();
    c->add_option("--eyes", opt.vp.eyes,
                  "Eyes on the models (and as many uniform), each scored against every point")
        ->check(CLI::Range(uint64_t(0), uint64_t(10000)))
        ->capture_default_str();
    c->add_option("--eye-seed", opt.vp.eye_seed, "Seed of the eyes")->capture_default_str();
    c->add_option("--as-cloud", opt.vp.as_cloud,
                  "Build from the samples as a raw cloud: normals (true normals, radii "
                  "estimated), bare (normals and radii estimated, as for a scan) or, with "
                  "--scan, sensors (bare, with each point's scanner position in the file)")
        ->check(CLI::IsMember({"normals", "bare", "sensors"}));
    CLI::Option* scan =
        c->add_option(
             "--scan", opt.vp.scan,
             "Score a simulated scan instead of the scene's samples: this many scanners in "
             "the room sweep an equal-angle grid of beams (about --points hits in all; "
             "shadows, density falling with distance); built as --as-cloud says (default "
             "bare)")
            ->check(CLI::Range(1u, 64u));
    c->add_option("--scan-seed", opt.vp.scan_seed, "Seed of the scanners' positions")
        ->capture_default_str()
        ->needs(scan);
    c->add_option("--roughness", opt.roughness,
                  "The predicate's roughness (scene units): an occluder of a point's own sheet "
                  "raised above it by less than this does not occlude; default: a raw cloud's "
                  "measured noise (--as-cloud, --cloud), 0 for the scene's samples")
        ->check(CLI::Range(0.f, 1e30f));
    c->add_option(
         "--noise", opt.vp.noise,
         "With --as-cloud or --scan: move each point of the cloud by Gaussian noise of this many "
         "sample spacings per axis, as a scanner's range noise (the truth keeps the exact "
         "points)")
        ->check(CLI::Range(0.0, 10.0));
    c->add_option("--cloud", opt.vp.cloud,
                  "Score this cloud file (PLY/OFF) against the scene's triangles instead of the "
                  "scene's samples")
        ->check(CLI::ExistingFile);
    c->add_option("--dump-eyes", opt.vp.dump_eyes,
                  "Write the eyes of the first height (points, eyes, truth and the V-map's "
                  "answers) to this .npz, for scripts/hpr-compare.sh");
    c->add_flag("--drop-buried", opt.vp.drop_buried,
                "Leave out buried points (covered surface) before sampling pairs");
}

// The tables' files, and --time-embree instead of the scoring.
void add_report_options(CLI::App* c) {
    c->add_option("--md", opt.md, "Write the Markdown here instead of stdout");
    c->add_option("--json", opt.json, "Also write the results as JSON here");
    c->add_flag("--time-embree", opt.time_embree,
                "Instead: time Embree occlusion rays along leaf-centroid segments against the "
                "leaf-pair kernel, on the same sampled leaf pairs, per scene and height");
    c->add_option("--runs", opt.runs, "With --time-embree: timed runs (median, spread)")
        ->check(CLI::Range(1, 100))
        ->capture_default_str();
    c->add_option("--embree-pairs", opt.embree_pairs, "With --time-embree: leaf pairs sampled")
        ->check(CLI::Range(uint64_t(1), uint64_t(1000000000)))
        ->capture_default_str();
}

}  // namespace

Command add_validate_command(CLI::App& app) {
    auto* c = app.add_subcommand(
        "validate",
        "Measure V-map answers against exact visibility from the scene's triangles (Embree "
        "rays), per octree height");
    add_sample_options(c);
    add_predict_options(c);
    add_report_options(c);
    // A later value of a single-valued option replaces an earlier one, so a sweep can vary one
    // setting of a fixed list (scripts/validate-sweep.sh).
    for (const char* name :
         {"--points",   "--pairs",      "--seed",         "--leaf-points",  "-K",
          "--eps",      "--facing-tol", "--parallel-tol", "--end-window",   "--occluders",
          "--backend",  "--predict",    "--delta-scale",  "--splat-floor",  "--ray-offset",
          "--md",       "--json",       "--runs",         "--embree-pairs", "--eyes",
          "--eye-seed", "--as-cloud",   "--cloud",        "--dump-eyes",    "--roughness",
          "--noise",    "--scan",       "--scan-seed",  "--core"})
        c->get_option(name)->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
    return {c, [] { return run_validate_command(); }, true};
}

int run_validate_command() {
    ValidateParams& vp = opt.vp;
    vp.progress = stderr_progress();
    if (opt.roughness) {
        vp.visibility.roughness = *opt.roughness;
        vp.measure_roughness = false;
    }
    for (const std::string& s : opt.scenes) io::check_input_path(s);
    check_output(opt.json, "--json", opt.scenes);
    check_output(opt.md, "--md", opt.scenes);
    check_output(vp.dump_eyes, "--dump-eyes", opt.scenes);
    if (!vp.dump_eyes.empty() && opt.scenes.size() != 1)
        throw Error(
            fmt::format("{}: --dump-eyes: give one scene (the file holds one)", vp.dump_eyes));
    if (opt.time_embree && !opt.json.empty())
        throw Error(
            fmt::format("{}: --json: --time-embree writes its table as Markdown only", opt.json));
    std::string md, json;
    if (opt.time_embree) {
        std::vector<EmbreeTiming> rows;
        for (const std::string& s : opt.scenes)
            for (int h : vp.heights) {
                EmbreeTimingParams p;
                p.points = vp.points;
                p.max_height = h;
                p.leaf_points = vp.leaf_points;
                p.visibility = vp.visibility;
                p.sample_pairs = opt.embree_pairs;
                p.runs = opt.runs;
                rows.push_back(time_embree(s, p));
            }
        md = embree_timing_markdown(rows);
    } else {
        json = "[\n";
        for (size_t k = 0; k < opt.scenes.size(); ++k) {
            const ValidationReport r = validate_scene(opt.scenes[k], vp);
            md += validation_markdown(r);
            json += validation_json(r) + (k + 1 < opt.scenes.size() ? ",\n" : "");
        }
        json += "]\n";
    }
    if (!opt.json.empty()) write_file(opt.json, json, "--json");
    if (!opt.md.empty())
        write_file(opt.md, md, "--md");
    else
        fmt::print("{}", md);
    return 0;
}

}  // namespace vmap::cli
