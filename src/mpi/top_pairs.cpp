// Top node-pair jobs, shares and the merge (src/mpi/top_pairs.h).
#include "mpi/top_pairs.h"

#include <algorithm>
#include <numeric>
#include <queue>

namespace vmap::mpi {
namespace {

uint64_t leaves_under(const Octree& t, int32_t n) {
    return uint64_t(t.leaf_end()[n] - t.leaf_begin()[n]);
}

// The child pairs resolve(a, b) splits into (both internal: children x children; one a leaf:
// it with the other's children), in the order the single-process planner uses.
void push_kids(const Octree& t, int32_t a, int32_t b, uint32_t parent, TopPairs& tp) {
    auto put = [&](int32_t x, int32_t y) {
        tp.pairs.push_back({x, y, int32_t(parent), 0, 0, leaves_under(t, x) * leaves_under(t, y)});
    };
    if (!t.is_leaf(a) && !t.is_leaf(b)) {
        t.for_each_child(
            a, [&](int32_t ca) { t.for_each_child(b, [&](int32_t cb) { put(ca, cb); }); });
    } else if (t.is_leaf(a)) {
        t.for_each_child(b, [&](int32_t cb) { put(a, cb); });
    } else {
        t.for_each_child(a, [&](int32_t ca) { put(ca, b); });
    }
}

}  // namespace

TopPairs make_top_pairs(const Octree& t, uint64_t max_area) {
    TopPairs tp;
    std::vector<int32_t> ch;
    for (int32_t n = 0; n < t.num_nodes(); ++n) {
        if (t.is_leaf(n)) continue;
        ch.clear();
        t.for_each_child(n, [&](int32_t c) { ch.push_back(c); });
        for (size_t i = 0; i < ch.size(); ++i)
            for (size_t j = i + 1; j < ch.size(); ++j) {
                const uint64_t area = leaves_under(t, ch[i]) * leaves_under(t, ch[j]);
                tp.pairs.push_back({ch[i], ch[j], -1, 0, 0, area});
                tp.total_area += area;
            }
    }
    // Breadth first: a split pair's children go to the end, so the list only grows.
    for (size_t i = 0; i < tp.pairs.size(); ++i) {
        const TopPair p = tp.pairs[i];
        if (p.area <= max_area || (t.is_leaf(p.a) && t.is_leaf(p.b))) continue;
        const uint32_t begin = uint32_t(tp.pairs.size());
        push_kids(t, p.a, p.b, uint32_t(i), tp);
        tp.pairs[i].kids_begin = begin;
        tp.pairs[i].kids_end = uint32_t(tp.pairs.size());
    }
    for (uint32_t i = 0; i < tp.pairs.size(); ++i)
        if (tp.pairs[i].is_job()) tp.jobs.push_back(i);
    return tp;
}

TopPairs make_top_pairs_for(const Octree& t, int ranks) {
    const uint64_t l = uint64_t(t.num_leaves());
    const uint64_t total = l * (l - 1) / 2;
    return make_top_pairs(t, std::max<uint64_t>(1, total / (64 * uint64_t(std::max(1, ranks)))));
}

// Jobs by decreasing area, ties by index (deterministic).
static std::vector<uint32_t> largest_first(const TopPairs& tp) {
    std::vector<uint32_t> order = tp.jobs;
    std::stable_sort(order.begin(), order.end(),
                     [&](uint32_t x, uint32_t y) { return tp.pairs[x].area > tp.pairs[y].area; });
    return order;
}

std::vector<std::vector<uint32_t>> static_shares(const TopPairs& tp, int ranks) {
    std::vector<std::vector<uint32_t>> shares(size_t(std::max(1, ranks)));
    using Load = std::pair<uint64_t, int>;  // (leaf pairs, rank): least loaded, lowest rank
    std::priority_queue<Load, std::vector<Load>, std::greater<Load>> loads;
    for (int r = 0; r < int(shares.size()); ++r) loads.push({0, r});
    for (uint32_t j : largest_first(tp)) {
        auto [load, r] = loads.top();
        loads.pop();
        shares[r].push_back(j);
        loads.push({load + tp.pairs[j].area, r});
    }
    for (auto& s : shares) std::sort(s.begin(), s.end());
    return shares;
}

std::vector<std::vector<uint32_t>> dynamic_chunks(const TopPairs& tp, int ranks, int per_rank) {
    return static_shares(tp, std::max(1, per_rank) * std::max(1, ranks));
}

std::vector<NodePair> job_pairs(const TopPairs& tp, const std::vector<uint32_t>& jobs) {
    std::vector<NodePair> out;
    out.reserve(jobs.size());
    for (uint32_t j : jobs) out.emplace_back(tp.pairs[j].a, tp.pairs[j].b);
    return out;
}

Merge merge_full(const TopPairs& tp, const std::vector<uint8_t>& full_job) {
    const size_t n = tp.pairs.size();
    std::vector<uint8_t> full(n, 0);
    // Children come after their parent: the last first settles every split pair's kids first.
    for (size_t i = n; i-- > 0;) {
        const TopPair& p = tp.pairs[i];
        if (p.is_job()) {
            full[i] = full_job[i];
            continue;
        }
        bool f = true;
        for (uint32_t k = p.kids_begin; k < p.kids_end && f; ++k) f = full[k];
        full[i] = f;
    }
    Merge m;
    m.drop.assign(n, 0);
    for (size_t i = 0; i < n; ++i) {
        const TopPair& p = tp.pairs[i];
        const bool parent_full = p.parent >= 0 && full[p.parent];
        if (p.is_job() && full[i] && parent_full) m.drop[i] = 1;
        if (!p.is_job() && full[i] && !parent_full) m.add.emplace_back(p.a, p.b);
    }
    return m;
}

}  // namespace vmap::mpi
