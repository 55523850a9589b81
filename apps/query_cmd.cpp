// `vmap query`: visibility questions answered from a .vmap file.
//   --pair I J | --pair-pos x,y,z x,y,z     are two points mutually visible?
//   --from I | --from-pos x,y,z [--ids] [--ply out.ply]   the points visible from one point
//   --ray I | --ray-pos x,y,z  --dir dx,dy,dz              first surface hit along a ray
// Positions name the surface point nearest them; ids are input point ids.
#include <fmt/format.h>

#include <cmath>
#include <memory>

#include "apps/commands.h"
#include "io/atomic_file.h"
#include "vmap/error.h"
#include "vmap/io.h"
#include "vmap/query.h"
#include "vmap/render.h"

namespace vmap::cli {
namespace {

struct QueryArgs {
    std::string path;
    std::vector<uint32_t> pair;
    std::vector<std::string> pair_pos;
    std::optional<uint32_t> from, ray;
    std::string from_pos, ray_pos, dir, ply;
    bool ids = false;
};

uint32_t checked_id(const VisibilityMap& vm, const std::string& path, const char* option,
                    uint32_t id) {
    if (id >= vm.points.size())
        throw Error(fmt::format("{}: {}: point id {} out of range (the V-map has {} points)", path,
                                option, id, vm.points.size()));
    return id;
}

// The point an id or a position option names, and how to describe it.
uint32_t resolve(const VisibilityMap& vm, const std::string& path, const char* id_option,
                 std::optional<uint32_t> id, const char* pos_option, const std::string& pos) {
    if (id) return checked_id(vm, path, id_option, *id);
    const Vec3 p = parse_vec3(pos, pos_option);
    const uint32_t k = nearest_point(vm, p);
    const Vec3 q = vm.octree.to_world(vm.points.positions[vm.inverse[k]]);
    fmt::print("{} {},{},{}: nearest point {} at ({}, {}, {}), {:.3g} away\n", pos_option, p.x, p.y,
               p.z, k, q.x, q.y, q.z,
               std::hypot(double(q.x) - p.x, double(q.y) - p.y, double(q.z) - p.z));
    return k;
}

int run_query(const QueryArgs& a) {
    const int given = (!a.pair.empty() || !a.pair_pos.empty()) + (a.from || !a.from_pos.empty()) +
                      (a.ray || !a.ray_pos.empty());
    if (given == 0) {
        fmt::print(stderr,
                   "vmap query: give --pair I J, --pair-pos P Q, --from I, --from-pos P, or "
                   "--ray I/--ray-pos P with --dir D\n");
        return 2;
    }
    if ((a.ray || !a.ray_pos.empty()) != !a.dir.empty()) {
        fmt::print(stderr, "vmap query: --ray/--ray-pos and --dir go together\n");
        return 2;
    }
    if ((a.ids || !a.ply.empty()) && !(a.from || !a.from_pos.empty())) {
        fmt::print(stderr, "vmap query: --ids and --ply go with --from/--from-pos\n");
        return 2;
    }
    // Parse positions before loading, so a typo fails fast.
    for (const auto& p : a.pair_pos) parse_vec3(p, "--pair-pos");
    if (!a.from_pos.empty()) parse_vec3(a.from_pos, "--from-pos");
    if (!a.ray_pos.empty()) parse_vec3(a.ray_pos, "--ray-pos");
    const Vec3 dir = a.dir.empty() ? Vec3{} : parse_direction(a.dir, "--dir");
    io::check_input_path(a.path);
    check_output(a.ply, "--ply", {a.path});

    const VisibilityMap vm = load_vmap(a.path);
    if (!a.pair.empty() || !a.pair_pos.empty()) {
        uint32_t i, j;
        if (!a.pair.empty()) {
            i = checked_id(vm, a.path, "--pair", a.pair[0]);
            j = checked_id(vm, a.path, "--pair", a.pair[1]);
        } else {
            i = resolve(vm, a.path, "", std::nullopt, "--pair-pos", a.pair_pos[0]);
            j = resolve(vm, a.path, "", std::nullopt, "--pair-pos", a.pair_pos[1]);
        }
        const PairVisibility v = vm.query(i, j);
        fmt::print("{} {} {}\n", i, j,
                   v == PairVisibility::kVisible  ? "visible"
                   : v == PairVisibility::kHidden ? "hidden"
                                                  : "same-leaf");
    }
    if (a.from || !a.from_pos.empty()) {
        const uint32_t i = resolve(vm, a.path, "--from", a.from, "--from-pos", a.from_pos);
        const auto set = vm.visible_set(i);
        fmt::print("{} points visible from {} (of {})\n", set.size(), i, vm.points.size());
        if (a.ids)
            for (uint32_t k : set) fmt::print("{}\n", k);
        if (!a.ply.empty()) {
            // The whole cloud in Fig. 9's colours: visible purple, the eye's leaf cyan, the rest
            // dimmed albedo; sRGB bytes, as viewers expect.
            write_colored_ply(a.ply, points_in_input_order(vm), visible_colors(vm, i));
            fmt::print("wrote:      {}\n", a.ply);
        }
    }
    if (a.ray || !a.ray_pos.empty()) {
        const uint32_t i = resolve(vm, a.path, "--ray", a.ray, "--ray-pos", a.ray_pos);
        RayStats st;
        const RayHit h = shoot_ray(vm, i, dir, &st);
        if (h.hit) {
            const Vec3 q = vm.octree.to_world(vm.points.positions[vm.inverse[h.id]]);
            fmt::print("ray from {}: hits point {} at distance {} ({}, {}, {})\n", i, h.id,
                       h.distance, q.x, q.y, q.z);
        } else {
            fmt::print("ray from {}: no hit\n", i);
        }
        fmt::print("work:       {} node tests, {} disc tests\n", st.node_tests, st.disc_tests);
    }
    return 0;
}

}  // namespace

Command add_query_command(CLI::App& app) {
    auto a = std::make_shared<QueryArgs>();
    auto* q = app.add_subcommand("query", "Answer visibility queries from a .vmap file");
    q->add_option("file", a->path, "The .vmap file")->required();
    auto* pair =
        q->add_option("--pair", a->pair, "Are input points I and J mutually visible?")->expected(2);
    q->add_option("--pair-pos", a->pair_pos,
                  "Are the surface points nearest x,y,z and x,y,z mutually visible?")
        ->expected(2)
        ->excludes(pair);
    auto* from = q->add_option("--from", a->from, "Points visible from input point I (count)");
    q->add_option("--from-pos", a->from_pos, "Points visible from the point nearest x,y,z")
        ->excludes(from);
    q->add_flag("--ids", a->ids, "With --from: list the ids too");
    q->add_option("--ply", a->ply,
                  "With --from: write the cloud coloured as Fig. 9 (visible purple, eye cyan)");
    auto* ray = q->add_option("--ray", a->ray, "Shoot a ray from input point I (with --dir)");
    q->add_option("--ray-pos", a->ray_pos, "Shoot a ray from the point nearest x,y,z")
        ->excludes(ray);
    q->add_option("--dir", a->dir, "Ray direction dx,dy,dz");
    return {q, [a] { return run_query(*a); }};
}

}  // namespace vmap::cli
