// The per-node link arrays (detail::LinkArrays, src/vmap/links.cpp) against a plain reference:
// random link lists (no duplicates, either end first, in pieces of any size) must give each
// node's targets sorted, at both ends, whatever the pieces, the order and the thread count.
#include "vmap/links.h"

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <ostream>
#include <random>
#include <set>
#include <span>
#include <vector>

#include "vmap/error.h"
#include "vmap/map_access.h"
#include "vmap/vmap.h"

namespace vmap {
namespace {

using detail::Link;

struct Case {
    int32_t nodes;
    size_t links;
    int32_t hub_links;  // links of node `hub` (one huge node), on top
    uint64_t seed;
};
void PrintTo(const Case& c, std::ostream* os) {
    *os << c.nodes << " nodes, " << c.links << " links, hub " << c.hub_links << ", seed " << c.seed;
}

// `c.links` distinct random links (either end first) plus c.hub_links from one node; most
// nodes of a large case have none.
std::vector<Link> random_links(const Case& c, int32_t hub) {
    std::mt19937_64 rng(c.seed);
    std::uniform_int_distribution<int32_t> node(0, c.nodes - 1);
    std::set<std::pair<int32_t, int32_t>> seen;
    std::vector<Link> out;
    auto add = [&](int32_t a, int32_t b) {
        if (a == b || !seen.insert({std::min(a, b), std::max(a, b)}).second) return;
        out.push_back(rng() & 1 ? Link{a, b} : Link{b, a});
    };
    while (out.size() < c.links) add(node(rng), node(rng));
    for (int32_t k = 0; k < c.hub_links && k < c.nodes; ++k) add(hub, k);
    std::shuffle(out.begin(), out.end(), rng);
    return out;
}

// Each node's targets, sorted: the arrays the builder must make (every end, sorted as pairs).
void reference(int32_t nodes, const std::vector<Link>& links, std::vector<uint64_t>& offsets,
               std::vector<int32_t>& targets) {
    std::vector<Link> ends;
    for (auto [a, b] : links) ends.push_back({a, b}), ends.push_back({b, a});
    std::sort(ends.begin(), ends.end());
    offsets.assign(size_t(nodes) + 1, 0);
    targets.clear();
    for (auto [a, b] : ends) ++offsets[a + 1], targets.push_back(b);
    for (int32_t n = 0; n < nodes; ++n) offsets[n + 1] += offsets[n];
}

// The links cut into pieces of random sizes (empty ones too), counted a few pieces at a time
// as the frontier does, then finished, on `threads` threads.
VisibilityMap arrays(int32_t nodes, const std::vector<Link>& links, uint64_t seed, int threads) {
    std::mt19937_64 rng(seed);
    std::vector<std::span<const Link>> pieces;
    for (size_t i = 0; i < links.size() || pieces.empty();) {
        const size_t n = std::min<size_t>(links.size() - i, rng() % 3 == 0 ? 0 : rng() % 70000);
        pieces.push_back(std::span<const Link>(links).subspan(i, n));
        i += n;
    }
    VisibilityMap vm;
    tbb::task_arena(threads).execute([&] {
        detail::LinkArrays la(nodes);
        for (size_t i = 0; i < pieces.size(); i += 3)
            la.count({pieces.begin() + i, pieces.begin() + std::min(pieces.size(), i + 3)});
        la.finish(vm, pieces);
    });
    return vm;
}

class LinkArraysRandom : public ::testing::TestWithParam<Case> {};

TEST_P(LinkArraysRandom, EachNodesTargetsSortedAtBothEnds) {
    const Case c = GetParam();
    const int32_t hub = c.nodes / 3;
    const std::vector<Link> links = random_links(c, hub);
    std::vector<uint64_t> offsets;
    std::vector<int32_t> targets;
    reference(c.nodes, links, offsets, targets);
    for (int threads : {1, 3}) {
        SCOPED_TRACE(threads);
        const VisibilityMap vm = arrays(c.nodes, links, c.seed + threads, threads);
        ASSERT_EQ(vm.link_offsets(), offsets);
        ASSERT_EQ(vm.num_links(), links.size());
        ASSERT_TRUE(std::equal(targets.begin(), targets.end(), vm.link_targets().begin(),
                               vm.link_targets().end()));
    }
}

// Small and large node counts (a node's index in its bucket has fewer bits as they grow), a
// node with more link ends than a bucket holds, empty maps, most nodes without links.
INSTANTIATE_TEST_SUITE_P(
    Cases, LinkArraysRandom,
    ::testing::Values(Case{1, 0, 0, 1}, Case{2, 1, 0, 2}, Case{3, 3, 0, 3}, Case{50, 600, 0, 4},
                      Case{1000, 200000, 0, 5}, Case{5000, 0, 0, 6}, Case{90000, 150000, 90000, 7},
                      Case{70000, 30, 0, 8}, Case{(1 << 20) + 3, 300000, 1000, 9},
                      Case{(1 << 22) + 1, 100000, 0, 10}, Case{300, 0, 299, 11}));

TEST(LinkArrays, RunsInAnyOrderGiveTheSameBytes) {
    const Case c{20000, 400000, 25000, 12};
    std::vector<Link> links = random_links(c, 7);
    const VisibilityMap a = arrays(c.nodes, links, 1, 2);
    std::sort(links.begin(), links.end());  // sorted input, the other extreme
    const VisibilityMap b = arrays(c.nodes, links, 2, 1);
    EXPECT_EQ(a.link_offsets(), b.link_offsets());
    EXPECT_TRUE(std::equal(a.link_targets().begin(), a.link_targets().end(),
                           b.link_targets().begin(), b.link_targets().end()));
}

TEST(LinkArrays, OutOfRangeAndSelfLinksAreRefused) {
    for (Link bad : {Link{0, 5}, Link{-1, 2}, Link{2, -3}, Link{3, 3}, Link{5, 1}}) {
        SCOPED_TRACE(testing::Message() << bad.first << "," << bad.second);
        const std::vector<Link> links{{0, 1}, bad, {2, 4}};
        detail::LinkArrays la(5);
        try {
            la.count({std::span<const Link>(links)});
            FAIL() << "no error";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("out of range (5 nodes)"), std::string::npos);
        }
    }
}

TEST(LinkArrays, FinishingOtherPiecesThanCountedIsAnError) {
    const std::vector<Link> counted{{0, 1}, {2, 4}}, other{{0, 1}, {3, 4}, {1, 2}};
    detail::LinkArrays la(5);
    la.count({std::span<const Link>(counted)});
    VisibilityMap vm;
    EXPECT_THROW(la.finish(vm, {std::span<const Link>(other)}), Error);
}

}  // namespace
}  // namespace vmap
