// Batches of queries (vmap/query.h): point pairs and visible sets on all cores.
#include <fmt/format.h>

#include "vmap/error.h"
#include "vmap/parallel.h"
#include "vmap/query.h"

namespace vmap {

void query_pairs(const VisibilityMap& vm, std::span<const uint32_t> pairs, std::span<uint8_t> out) {
    vm.require_links("query");
    if (pairs.size() % 2 != 0 || out.size() != pairs.size() / 2)
        throw Error(fmt::format("query_pairs: {} ids for {} answers (expected two ids per answer)",
                                pairs.size(), out.size()));
    const size_t n = vm.order().size();
    for (size_t k = 0; k < pairs.size(); ++k)
        if (pairs[k] >= n)
            throw Error(fmt::format("pair {}: point id {} out of range (the V-map has {} points)",
                                    k / 2, pairs[k], n));
    const Octree& t = vm.octree();
    const std::vector<uint32_t>& inverse = vm.inverse();
    parallel_for_range(out.size(), size_t(4096), [&](size_t k0, size_t k1) {
        for (size_t k = k0; k < k1; ++k) {
            const int32_t la = t.leaf_of_point(inverse[pairs[2 * k]]);
            const int32_t lb = t.leaf_of_point(inverse[pairs[2 * k + 1]]);
            out[k] = la == lb ? uint8_t(PairVisibility::kSameLeaf)
                              : uint8_t(vm.leaves_visible(la, lb) ? PairVisibility::kVisible
                                                                  : PairVisibility::kHidden);
        }
    });
}

VisibleSets visible_sets(const VisibilityMap& vm, std::span<const uint32_t> ids) {
    std::vector<std::vector<uint32_t>> sets(ids.size());
    for (uint32_t i : ids)
        if (i >= vm.order().size())
            throw Error(fmt::format("query: point id {} out of range (the V-map has {} points)", i,
                                    vm.order().size()));
    parallel_for(ids.size(), [&](size_t k) { sets[k] = vm.visible_set(ids[k]); });
    VisibleSets r;
    r.offsets.resize(ids.size() + 1, 0);
    for (size_t k = 0; k < ids.size(); ++k) r.offsets[k + 1] = r.offsets[k] + sets[k].size();
    r.targets.resize(r.offsets.back());
    parallel_for(ids.size(), [&](size_t k) {
        std::copy(sets[k].begin(), sets[k].end(), r.targets.begin() + r.offsets[k]);
    });
    return r;
}

}  // namespace vmap
