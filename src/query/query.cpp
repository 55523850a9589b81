// Point-pair queries and visible sets, answered from the V-map (paper §3).
#include <fmt/format.h>

#include <algorithm>

#include "vmap/error.h"
#include "vmap/visibility_map.h"

namespace vmap {

bool VisibilityMap::leaves_visible(int32_t leaf_a, int32_t leaf_b) const {
    const std::vector<int32_t>& skip = d_.octree.skip();
    const std::vector<int32_t>& parent = d_.octree.parent();
    const int32_t nb = d_.octree.leaf_node()[leaf_b];
    // Walk a's ancestors up to (not including) the lowest common ancestor of a and b: a link
    // joins disjoint subtrees, so no node holding b links to a node holding it. The targets of
    // one node are disjoint subtrees sorted by preorder index, so the only candidate ancestor of
    // b among them is the last target <= nb.
    for (int32_t A = d_.octree.leaf_node()[leaf_a]; A >= 0 && !(A <= nb && nb < skip[A]);
         A = parent[A]) {
        const auto ls = links(A);
        auto it = std::upper_bound(ls.begin(), ls.end(), nb);
        if (it != ls.begin() && nb < skip[*(it - 1)]) return true;
    }
    return false;
}

void VisibilityMap::require_links(const char* what) const {
    if (!has_links())
        throw Error(fmt::format("{}: this V-map kept no links (it was built only to count them)",
                                what));
}

PairVisibility VisibilityMap::query(uint32_t i, uint32_t j) const {
    require_links("query");
    const size_t n = d_.order.size();
    if (i >= n || j >= n)
        throw Error(fmt::format("query: point id {} out of range (the V-map has {} points)",
                                std::max(i, j), n));
    const int32_t la = d_.octree.leaf_of_point(d_.inverse[i]);
    const int32_t lb = d_.octree.leaf_of_point(d_.inverse[j]);
    if (la == lb) return PairVisibility::kSameLeaf;
    return leaves_visible(la, lb) ? PairVisibility::kVisible : PairVisibility::kHidden;
}

std::vector<uint32_t> VisibilityMap::visible_set(uint32_t i) const {
    require_links("query");
    if (i >= d_.order.size())
        throw Error(fmt::format("query: point id {} out of range (the V-map has {} points)", i,
                                d_.order.size()));
    std::vector<uint32_t> out;
    for (int32_t A = d_.octree.leaf_node()[d_.octree.leaf_of_point(d_.inverse[i])]; A >= 0;
         A = d_.octree.parent()[A]) {
        for (int32_t B : links(A))
            for (uint32_t k = d_.octree.point_begin()[B]; k < d_.octree.point_end()[B]; ++k)
                out.push_back(d_.order[k]);
    }
    std::sort(out.begin(), out.end());
    return out;
}

}  // namespace vmap
