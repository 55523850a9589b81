// `vmap query`: visibility questions answered from a .vmap file.
//   --pair I J | --pair-pos x,y,z x,y,z     are two points mutually visible?
//   --pairs FILE|- [--out answers.npy]      many pairs: text "I J" lines or an .npy of int pairs
//   --from I [J ...] | --from-pos x,y,z [--ids] [--ply out.ply]   the points visible from points
//   --ray I | --ray-pos x,y,z  --dir dx,dy,dz              first surface hit along a ray
// Positions name the surface point nearest them; ids are input point ids. What was asked for goes
// to stdout (ids only with --ids, one JSON object with --json); sentences about it to stderr.
#include <fmt/format.h>

#include <cstdio>
#include <cmath>
#include <memory>
#include <nlohmann/json.hpp>

#include "apps/commands.h"
#include "apps/query_io.h"
#include "vmap/error.h"
#include "vmap/files.h"
#include "vmap/io.h"
#include "vmap/npy.h"
#include "vmap/query.h"
#include "vmap/render.h"

namespace vmap::cli {
namespace {

using nlohmann::json;

struct QueryArgs {
    std::string path;
    std::vector<uint32_t> pair, from;
    std::vector<std::string> pair_pos;
    std::optional<uint32_t> ray;
    std::string pairs, out, from_pos, ray_pos, dir, ply;
    bool ids = false, json = false;
};

const char* answer_word(uint8_t v) {
    return v == uint8_t(PairVisibility::kVisible)  ? "visible"
           : v == uint8_t(PairVisibility::kHidden) ? "hidden"
                                                   : "same-leaf";
}

uint32_t checked_id(const VisibilityMap& vm, const std::string& path, const char* option,
                    uint32_t id) {
    if (id >= vm.points().size())
        throw Error(fmt::format("{}: {}: point id {} out of range (the V-map has {} points)", path,
                                option, id, vm.points().size()));
    return id;
}

// The point a position option names; says which on stderr.
uint32_t resolve_pos(const VisibilityMap& vm, const char* pos_option, const std::string& pos) {
    const std::array<double, 3>& o = vm.points().origin;  // positions are the input's
    const Vec3 p = parse_position(pos, pos_option, o);
    const uint32_t k = nearest_point(vm, p);
    const Vec3 q = vm.octree().to_world(vm.points().positions[vm.inverse()[k]]);
    if (verbosity() != Verbosity::kQuiet)
        fmt::print(stderr, "{} {}: nearest point {} at ({}), {:.3g} away\n", pos_option, pos, k,
                   position_text(q, o),
                   std::hypot(double(q.x) - p.x, double(q.y) - p.y, double(q.z) - p.z));
    return k;
}

int check_args(const QueryArgs& a) {
    const bool pair = !a.pair.empty() || !a.pair_pos.empty() || !a.pairs.empty();
    const bool from = !a.from.empty() || !a.from_pos.empty();
    const bool ray = a.ray || !a.ray_pos.empty();
    auto usage = [](const char* m) {
        fmt::print(stderr, "vmap query: {}\n", m);
        return 2;
    };
    if (!pair && !from && !ray)
        return usage(
            "give --pair I J, --pair-pos P Q, --pairs FILE, --from I.., --from-pos P, or "
            "--ray I/--ray-pos P with --dir D");
    if (ray != !a.dir.empty()) return usage("--ray/--ray-pos and --dir go together");
    if ((a.ids || !a.ply.empty()) && !from)
        return usage("--ids and --ply go with --from/--from-pos");
    if (!a.out.empty() && a.pairs.empty()) return usage("--out goes with --pairs");
    if (!a.ply.empty() && a.from.size() > 1) return usage("--ply takes one --from point");
    if (!a.out.empty() && !has_extension(a.out, ".npy"))
        return usage("--out writes an .npy file (name it *.npy)");
    return 0;
}

// Single pairs (--pair, --pair-pos) and the batch (--pairs).
void run_pairs(const QueryArgs& a, const VisibilityMap& vm, json& js) {
    std::vector<uint32_t> ids;
    if (!a.pair.empty()) {
        ids = {checked_id(vm, a.path, "--pair", a.pair[0]),
               checked_id(vm, a.path, "--pair", a.pair[1])};
    } else if (!a.pair_pos.empty()) {
        ids = {resolve_pos(vm, "--pair-pos", a.pair_pos[0]),
               resolve_pos(vm, "--pair-pos", a.pair_pos[1])};
    } else {
        ids = read_pairs(a.pairs);
    }
    std::vector<uint8_t> ans(ids.size() / 2);
    try {
        query_pairs(vm, ids, ans);
    } catch (const Error& e) {
        throw Error(fmt::format("{}: {}", a.pairs.empty() ? a.path : a.pairs, e.what()));
    }
    if (!a.out.empty()) {
        write_npy_u8(a.out, ans);
        if (verbosity() != Verbosity::kQuiet)
            fmt::print(stderr, "{} answers (0 hidden, 1 visible, 2 same-leaf) -> {}\n", ans.size(),
                       a.out);
    } else if (a.json) {
        json& list = js["pairs"] = json::array();
        for (size_t k = 0; k < ans.size(); ++k)
            list.push_back({ids[2 * k], ids[2 * k + 1], answer_word(ans[k])});
    } else {
        write_answers(stdout, ids, ans, answer_word);
    }
}

void run_from(const QueryArgs& a, const VisibilityMap& vm, json& js) {
    std::vector<uint32_t> ids;
    for (uint32_t i : a.from) ids.push_back(checked_id(vm, a.path, "--from", i));
    if (ids.empty()) ids.push_back(resolve_pos(vm, "--from-pos", a.from_pos));
    const VisibleSets sets = visible_sets(vm, ids);
    const bool quiet = verbosity() == Verbosity::kQuiet;
    for (size_t k = 0; k < ids.size(); ++k) {
        const uint64_t n = sets.offsets[k + 1] - sets.offsets[k];
        const std::string line =
            fmt::format("{} points visible from {} (of {})", n, ids[k], vm.points().size());
        if (a.json) {
            json e = {{"from", ids[k]}, {"count", n}};
            if (a.ids)
                e["ids"] = std::vector<uint32_t>(sets.targets.begin() + sets.offsets[k],
                                                 sets.targets.begin() + sets.offsets[k + 1]);
            js["from"].push_back(e);
        } else if (a.ids) {
            if (!quiet) fmt::print(stderr, "{}\n", line);
        } else {
            fmt::print("{}\n", line);
        }
    }
    if (a.ids && !a.json) write_id_lists(stdout, sets, ids.size() > 1);
    if (!a.ply.empty()) {
        // The whole cloud in Fig. 9's colours: visible purple, the eye's leaf cyan, the rest
        // dimmed albedo; sRGB bytes, as viewers expect.
        write_colored_ply(a.ply, points_in_input_order(vm), visible_colors(vm, ids[0]));
        if (!quiet) fmt::print(stderr, "wrote:      {}\n", a.ply);
    }
}

void run_ray(const QueryArgs& a, const VisibilityMap& vm, Vec3 dir, json& js) {
    const uint32_t i =
        a.ray ? checked_id(vm, a.path, "--ray", *a.ray) : resolve_pos(vm, "--ray-pos", a.ray_pos);
    RayStats st;
    const RayHit h = shoot_ray(vm, i, dir, &st);
    const Vec3 q = h.hit ? vm.octree().to_world(vm.points().positions[vm.inverse()[h.id]]) : Vec3{};
    if (a.json) {
        js["ray"] = {{"from", i},
                     {"hit", h.hit},
                     {"id", h.hit ? json(h.id) : json(nullptr)},
                     {"distance", h.hit ? json(h.distance) : json(nullptr)},
                     {"position",
                      h.hit ? json(file_position(q, vm.points().origin)) : json(nullptr)},
                     {"node_tests", st.node_tests},
                     {"disc_tests", st.disc_tests}};
        return;
    }
    if (h.hit)
        fmt::print("ray from {}: hits point {} at distance {} ({})\n", i, h.id, h.distance,
                   position_text(q, vm.points().origin));
    else
        fmt::print("ray from {}: no hit\n", i);
    if (verbosity() != Verbosity::kQuiet)
        fmt::print(stderr, "work:       {} node tests, {} disc tests\n", st.node_tests,
                   st.disc_tests);
}

int run_query(const QueryArgs& a) {
    if (const int rc = check_args(a)) return rc;
    // Parse positions and check outputs before loading, so a typo fails fast.
    for (const auto& p : a.pair_pos) parse_vec3(p, "--pair-pos");
    if (!a.from_pos.empty()) parse_vec3(a.from_pos, "--from-pos");
    if (!a.ray_pos.empty()) parse_vec3(a.ray_pos, "--ray-pos");
    const Vec3 dir = a.dir.empty() ? Vec3{} : parse_direction(a.dir, "--dir");
    io::check_input_path(a.path);
    if (!a.pairs.empty() && a.pairs != "-") io::check_input_path(a.pairs);
    check_output(a.out, "--out", {a.path, a.pairs});
    check_output(a.ply, "--ply", {a.path, a.pairs, a.out});

    const VisibilityMap vm = load_vmap(a.path);
    json js = {{"file", a.path}};
    if (!a.pair.empty() || !a.pair_pos.empty() || !a.pairs.empty()) run_pairs(a, vm, js);
    if (!a.from.empty() || !a.from_pos.empty()) run_from(a, vm, js);
    if (a.ray || !a.ray_pos.empty()) run_ray(a, vm, dir, js);
    if (a.json) fmt::print("{}\n", js.dump(2));
    return 0;
}

}  // namespace

Command add_query_command(CLI::App& app) {
    auto a = std::make_shared<QueryArgs>();
    auto* q = app.add_subcommand("query", "Answer visibility queries from a .vmap file");
    q->add_option("file", a->path, "The .vmap file")->required();
    auto* pair =
        q->add_option("--pair", a->pair, "Are input points I and J mutually visible?")->expected(2);
    auto* pair_pos = q->add_option("--pair-pos", a->pair_pos,
                                   "Are the surface points nearest x,y,z and x,y,z mutually "
                                   "visible?")
                         ->expected(2)
                         ->excludes(pair);
    q->add_option("--pairs", a->pairs,
                  "Many pairs: a text file (- for stdin) of 'I J' lines, or an .npy of M x 2 "
                  "integer ids; one 'I J answer' line each")
        ->excludes(pair)
        ->excludes(pair_pos);
    q->add_option("--out", a->out,
                  "With --pairs: write the answers to an .npy of uint8 (0 hidden, 1 visible, 2 "
                  "same-leaf) instead of stdout");
    auto* from = q->add_option("--from", a->from, "Points visible from input points I [J ...]");
    q->add_option("--from-pos", a->from_pos, "Points visible from the point nearest x,y,z")
        ->excludes(from);
    q->add_flag("--ids", a->ids,
                "With --from: print the visible ids (one a line; one line per point for several)");
    q->add_option("--ply", a->ply,
                  "With --from: write the cloud coloured as Fig. 9 (visible purple, eye cyan)");
    auto* ray = q->add_option("--ray", a->ray, "Shoot a ray from input point I (with --dir)");
    q->add_option("--ray-pos", a->ray_pos, "Shoot a ray from the point nearest x,y,z")
        ->excludes(ray);
    q->add_option("--dir", a->dir, "Ray direction dx,dy,dz");
    q->add_flag("--json", a->json, "Print the answers as one JSON object (for scripts)");
    return {q, [a] { return run_query(*a); }};
}

}  // namespace vmap::cli
