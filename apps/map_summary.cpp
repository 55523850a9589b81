// What a V-map holds, as `vmap build` and `vmap info` print it (apps/commands.h).
#include <fmt/format.h>

#include <algorithm>
#include <string>

#include "apps/commands.h"

namespace vmap::cli {
namespace {

// A float as the shortest decimal that reads back to it (0.01, not 0.009999999776).
double short_decimal(float f) { return std::stod(fmt::format("{}", f)); }

}  // namespace

std::vector<uint64_t> links_per_level(const VisibilityMap& vm) {
    const Octree& t = vm.octree();
    int h = 0;  // deepest node (not only leaf), so every level below indexes in range
    for (int32_t n = 0; n < t.num_nodes(); ++n) h = std::max(h, int(t.level()[n]));
    // Each link once, at its first end's level: a node's targets are sorted, so those after it
    // are the tail past upper_bound (a scan of every target took 1-2 s at 4.6e8 links).
    std::vector<uint64_t> links(h + 1);
    for (int32_t n = 0; n < t.num_nodes(); ++n) {
        const std::span<const int32_t> to = vm.links(n);
        links[t.level()[n]] += uint64_t(to.end() - std::upper_bound(to.begin(), to.end(), n));
    }
    return links;
}

void print_tree_summary(const VisibilityMap& vm) {
    const Octree& t = vm.octree();
    const std::vector<uint64_t> links = links_per_level(vm);
    std::vector<uint64_t> nodes(links.size()), leaves(links.size());
    for (int32_t n = 0; n < t.num_nodes(); ++n) {
        nodes[t.level()[n]]++;
        if (t.is_leaf(n)) leaves[t.level()[n]]++;
    }
    fmt::print("  level      nodes     leaves      links\n");
    for (size_t l = 0; l < links.size(); ++l)
        fmt::print("  {:5d} {:10d} {:10d} {:10d}\n", l, nodes[l], leaves[l], links[l]);
}

void print_params(const VisibilityMap& vm) {
    const auto& o = vm.octree_params();
    const auto& v = vm.visibility_params();
    fmt::print(
        "octree:     max_height {}, leaf_points {}, delta_floor {} -> height {}, {} nodes, {} "
        "leaves\n",
        o.max_height, o.leaf_points, o.delta_floor, vm.octree().height(), vm.octree().num_nodes(),
        vm.octree().num_leaves());
    fmt::print(
        "predicate:  K {}, eps {}, facing_tol {}, parallel_tol {}, end_window {}, roughness {}, "
        "core {}\n",
        v.K, v.eps, v.facing_tol, v.parallel_tol, v.end_window, v.roughness, v.core);
}

nlohmann::json params_json(const VisibilityMap& vm) {
    const auto& o = vm.octree_params();
    const auto& v = vm.visibility_params();
    return {{"max_height", o.max_height},
            {"leaf_points", o.leaf_points},
            {"delta_floor", o.delta_floor},
            {"height", vm.octree().height()},
            {"nodes", vm.octree().num_nodes()},
            {"leaves", vm.octree().num_leaves()},
            {"K", v.K},
            {"eps", short_decimal(v.eps)},
            {"facing_tol", short_decimal(v.facing_tol)},
            {"parallel_tol", short_decimal(v.parallel_tol)},
            {"end_window", short_decimal(v.end_window)},
            {"roughness", short_decimal(v.roughness)},
            {"core", short_decimal(v.core)}};
}

}  // namespace vmap::cli
