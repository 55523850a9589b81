// V-map construction against a brute-force leaf-pair matrix (the invariant is the oracle: a
// link means every leaf under one end sees every leaf under the other, and every visible leaf
// pair is covered by exactly one link).
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <thread>
#include <set>

#include "backend_fixture.h"
#include "test_files.h"
#include "test_util.h"
#include "vmap/error.h"

namespace vmap {
namespace {

using LinkSet = std::set<std::pair<int32_t, int32_t>>;

LinkSet links_of(const VisibilityMap& vm) {
    LinkSet s;
    for (int32_t n = 0; n < vm.octree().num_nodes(); ++n)
        for (int32_t m : vm.links(n)) s.insert({std::min(n, m), std::max(n, m)});
    return s;
}

// The construction (paper §4.3: sibling rectangles resolved top down), written as plainly as
// possible over the dense matrix.
struct Naive {
    const Octree& t;
    const std::vector<uint8_t>& m;
    LinkSet out;
    bool full(int32_t a, int32_t b) const {
        const int32_t L = t.num_leaves();
        for (int32_t x = t.leaf_begin()[a]; x < t.leaf_end()[a]; ++x)
            for (int32_t y = t.leaf_begin()[b]; y < t.leaf_end()[b]; ++y)
                if (!m[size_t(x) * L + y]) return false;
        return true;
    }
    std::vector<int32_t> kids(int32_t n) const {
        std::vector<int32_t> k;
        t.for_each_child(n, [&](int32_t c) { k.push_back(c); });
        return k;
    }
    void resolve(int32_t a, int32_t b) {
        if (full(a, b)) {
            out.insert({std::min(a, b), std::max(a, b)});
            return;
        }
        if (t.is_leaf(a) && t.is_leaf(b)) return;
        if (!t.is_leaf(a) && !t.is_leaf(b)) {
            for (int32_t x : kids(a))
                for (int32_t y : kids(b)) resolve(x, y);
        } else if (t.is_leaf(a)) {
            for (int32_t y : kids(b)) resolve(a, y);
        } else {
            for (int32_t x : kids(a)) resolve(x, b);
        }
    }
    LinkSet run() {
        for (int32_t n = 0; n < t.num_nodes(); ++n) {
            const auto k = kids(n);
            for (size_t i = 0; i < k.size(); ++i)
                for (size_t j = i + 1; j < k.size(); ++j) resolve(k[i], k[j]);
        }
        return out;
    }
};

std::vector<int32_t> ancestors_or_self(const Octree& t, int32_t leaf) {
    std::vector<int32_t> v;
    for (int32_t n = t.leaf_node()[leaf]; n >= 0; n = t.parent()[n]) v.push_back(n);
    return v;
}

void check_invariant(const VisibilityMap& vm) {
    const Octree& t = vm.octree();
    const int32_t L = t.num_leaves();
    const auto m = test::brute_matrix(vm);
    const LinkSet links = links_of(vm);
    // Exactly the links of the plain construction.
    EXPECT_EQ(links, (Naive{t, m, {}}.run()));
    // Every leaf pair covered by exactly one link when visible, by none when not.
    std::vector<std::vector<int32_t>> anc(L);
    for (int32_t l = 0; l < L; ++l) anc[l] = ancestors_or_self(t, l);
    uint64_t visible = 0;
    for (int32_t a = 0; a < L; ++a)
        for (int32_t b = a + 1; b < L; ++b) {
            int cover = 0;
            for (int32_t x : anc[a])
                for (int32_t y : anc[b]) cover += links.count({std::min(x, y), std::max(x, y)});
            ASSERT_EQ(cover, m[size_t(a) * L + b] ? 1 : 0) << "leaves " << a << ", " << b;
            ASSERT_EQ(vm.leaves_visible(a, b), bool(m[size_t(a) * L + b]));
            ASSERT_EQ(vm.leaves_visible(b, a), bool(m[size_t(a) * L + b]));
            visible += m[size_t(a) * L + b];
        }
    EXPECT_GT(visible, 0u);
    // No link could be moved up a level: for a link between non-siblings, the pair of parents
    // (when they are disjoint subtrees) is not fully visible.
    auto disjoint = [&](int32_t x, int32_t y) {
        return !(x <= y && y < t.skip()[x]) && !(y <= x && x < t.skip()[y]);
    };
    for (auto [a, b] : links) {
        const int32_t p = t.parent()[a], q = t.parent()[b];
        if (p == q) continue;
        if (disjoint(p, q)) {
            EXPECT_FALSE((Naive{t, m, {}}.full(p, q))) << a << " " << b;
        }
    }
}

using test::BuildCase;

// Both constructions on every backend, each against the brute-force matrix.
class VmapOracle : public test::OnEachBackendWith<BuildCase> {};

TEST_P(VmapOracle, LinksCoverExactlyTheVisibleLeafPairs) {
    const BuildCase c = param();
    const PointSet ps = test::sample(c.file(), c.points, 3);
    for (const Construction method : {Construction::kNodes, Construction::kLeafPairs}) {
        SCOPED_TRACE(name_of(method));
        BuildParams bp = build_params(c.height, c.leaf_points);
        bp.construction = method;
        BuildStats st;
        VisibilityMap vm = build_vmap(ps, bp, &st);
        EXPECT_EQ(st.construction, name_of(method));
        expect_ran_here(st.backend);
        const int32_t L = vm.octree().num_leaves();
        EXPECT_EQ(st.leaf_pairs, uint64_t(L) * (L - 1) / 2);
        EXPECT_EQ(st.work.pairs, st.leaf_pairs_walked) << "each walked pair once";
        if (method == Construction::kNodes)
            EXPECT_LT(st.leaf_pairs_walked, st.leaf_pairs) << "node-level decisions";
        else
            EXPECT_EQ(st.leaf_pairs_walked, st.leaf_pairs) << "every leaf pair walked";
        std::set<int> levels;
        for (int32_t l : vm.octree().leaf_node()) levels.insert(vm.octree().level()[l]);
        EXPECT_GE(levels.size(), 2u) << "the case should have leaves at mixed depths";
        check_invariant(vm);
    }
}

VMAP_ON_EACH_BACKEND_WITH(VmapOracle,
                          ::testing::Values(BuildCase{"cornell-empty", 1500, 4, 4},
                                            BuildCase{"cornell-bunny", 2000, 5, 2},
                                            BuildCase{"cornell-bunny", 2500, 7, 4},
                                            BuildCase{"cornell-two-models", 2500, 8, 6},
                                            BuildCase{"./room-with-block.json", 2000, 6, 1},
                                            BuildCase{"./room-with-block.json", 3000, 9, 8}),
                          [](const BuildCase& c) { return test::case_name(c, true); });

class VmapBuild : public test::OnEachBackend {};

TEST_P(VmapBuild, TinyBatchesGiveTheSameLinks) {
    // Batches of 1024 pairs force jobs of 64 pairs: node pairs split into sub-rectangles, links
    // reassembled across jobs and batches. The reference: the CPU's leaf-pair build in one batch.
    const PointSet ps = test::sample(test::oracle_path("room-with-block.json"), 2500, 4);
    BuildParams ref_bp = test::cpu_params(7, 3);
    ref_bp.construction = Construction::kLeafPairs;
    const VisibilityMap ref = build_vmap(ps, ref_bp);
    for (const Construction method : {Construction::kNodes, Construction::kLeafPairs}) {
        BuildParams bp = build_params(7, 3);
        bp.construction = method;
        bp.max_batch_pairs = 1024;
        BuildStats st;
        const VisibilityMap small = build_vmap(ps, bp, &st);
        EXPECT_GT(st.batches, 10u) << name_of(method);
        expect_ran_here(st.backend);
        EXPECT_EQ(small.link_offsets(), ref.link_offsets()) << name_of(method);
        EXPECT_TRUE(std::ranges::equal(small.link_targets(), ref.link_targets()))
            << name_of(method);
    }
}

TEST_P(VmapBuild, CountingWithoutKeepingGivesTheSameNumberOfLinks) {
    // Small batches, so links merge across jobs (the count must subtract the replaced ones).
    const PointSet ps = test::sample(test::oracle_path("room-with-block.json"), 2500, 4);
    BuildParams bp = build_params(7, 3);
    bp.max_batch_pairs = 4096;
    BuildStats kept, counted;
    const VisibilityMap ref = build_vmap(ps, bp, &kept);
    bp.keep_links = false;
    const VisibilityMap none = build_vmap(ps, bp, &counted);
    EXPECT_GT(ref.num_links(), 100u);
    EXPECT_EQ(kept.links, ref.num_links());
    EXPECT_EQ(counted.links, ref.num_links());
    EXPECT_EQ(none.num_links(), 0u);
    // A map without its links refuses to answer or to be saved, rather than say "hidden".
    EXPECT_TRUE(ref.has_links());
    EXPECT_FALSE(none.has_links());
    EXPECT_THROW(none.query(0, 1), Error);
    EXPECT_THROW(none.visible_set(0), Error);
    test::ScratchDir dir;
    EXPECT_THROW(save_vmap(dir.path("none.vmap"), none), Error);
    EXPECT_FALSE(std::filesystem::exists(dir.path("none.vmap")));
}

TEST_P(VmapBuild, LinksAreStoredAtBothEndsSorted) {
    const VisibilityMap vm = build_vmap(test::sample(test::scene_path("cornell-bunny"), 2000, 1),
                                        build_params(6, 4));
    for (int32_t n = 0; n < vm.octree().num_nodes(); ++n) {
        const auto ls = vm.links(n);
        EXPECT_TRUE(std::is_sorted(ls.begin(), ls.end()));
        for (int32_t m : ls) {
            const auto back = vm.links(m);
            EXPECT_TRUE(std::binary_search(back.begin(), back.end(), n));
        }
    }
}

TEST_P(VmapBuild, AContextMadeOnAnotherThreadWhileSamplingGivesTheSameLinks) {
    // vmap build makes the GPU's context on a thread of its own while it reads the input
    // (warm_up_gpu); the build then runs on that context from the main thread. The reference:
    // the CPU's build. On the CPU backend the warm-up does nothing.
    BuildParams bp = build_params(7, 3);
    std::jthread warm([p = bp] { warm_up_gpu(p); });
    const PointSet ps = test::sample(test::scene_path("cornell-bunny"), 2500, 4);
    warm.join();
    BuildStats st;
    const VisibilityMap vm = build_vmap(ps, bp, &st);
    expect_ran_here(st.backend);
    const VisibilityMap ref = build_vmap(ps, test::cpu_params(7, 3));
    EXPECT_GT(ref.num_links(), 100u);
    EXPECT_EQ(vm.link_offsets(), ref.link_offsets());
    EXPECT_TRUE(std::ranges::equal(vm.link_targets(), ref.link_targets()));
    // Called again, and with a device that is not there, it neither throws nor breaks a build.
    warm_up_gpu(bp);
    BuildParams absent = bp;
    absent.device = 1 << 20;
    warm_up_gpu(absent);
    EXPECT_EQ(build_vmap(ps, bp).link_offsets(), ref.link_offsets());
}

VMAP_ON_EACH_BACKEND(VmapBuild);

TEST(VmapBuild, ResultDoesNotDependOnThreadCount) {
    const PointSet ps = test::sample(test::scene_path("cornell-bunny"), 3000, 8);
    VisibilityMap many = build_vmap(ps, test::cpu_params(7, 3));
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    VisibilityMap single = build_vmap(ps, test::cpu_params(7, 3));
    EXPECT_TRUE(std::ranges::equal(single.link_targets(), many.link_targets()));
    EXPECT_EQ(single.order(), many.order());
}

TEST(VmapBuild, AbsurdParametersAreRejected) {
    const PointSet ps = test::sample(test::scene_path("cornell-empty"), 500, 1);
    auto expect = [&](BuildParams bp, const char* needle) {
        try {
            build_vmap(ps, bp, nullptr, "scene.json");
            FAIL() << needle;
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find("scene.json"), std::string::npos) << e.what();
        }
    };
    BuildParams bp = test::cpu_params(5, 4);
    bp.visibility.K = 0;
    expect(bp, "K");
    bp = test::cpu_params(5, 4);
    bp.visibility.eps = 0.7f;
    expect(bp, "eps");
    bp = test::cpu_params(5, 4);
    bp.visibility.facing_tol = -1;
    expect(bp, "facing");
    bp = test::cpu_params(40, 4);
    expect(bp, "max_height");
}

TEST(VmapBuild, UnknownBackendIsAUsageError) {
    EXPECT_THROW(parse<Backend>("tpu", "backend"), Error);
    EXPECT_STREQ(name_of(parse<Backend>("cuda", "backend")), "cuda");
}

}  // namespace
}  // namespace vmap
