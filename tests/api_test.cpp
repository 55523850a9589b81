// The library as a program uses it: threads, progress and cancellation through the callback,
// the backend request, batch queries against single ones, the data folder, the version, and the
// .npy reader behind `vmap query --pairs`.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <atomic>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <thread>

#include "test_util.h"
#include "util/progress.h"
#include "visibility/backend.h"
#include "vmap/error.h"
#include "vmap/npy.h"
#include "vmap/query.h"
#include "vmap/version.h"

namespace vmap {
namespace {

const VisibilityMap& small_map() {
    static const VisibilityMap vm = build_vmap(
        test::sample(test::scene_path("cornell-empty"), 1500, 2), test::cpu_params(5, 4));
    return vm;
}

TEST(Api, OneThreadBuildsTheSameLinksAsAllCores) {
    BuildParams bp = test::cpu_params(5, 4);
    bp.threads = 1;
    BuildStats st;
    const VisibilityMap one =
        build_vmap(test::sample(test::scene_path("cornell-empty"), 1500, 2), bp, &st);
    EXPECT_NE(st.backend.find("(1 thread)"), std::string::npos) << st.backend;
    EXPECT_EQ(one.link_offsets(), small_map().link_offsets());
    EXPECT_TRUE(std::equal(one.link_targets().begin(), one.link_targets().end(),
                           small_map().link_targets().begin(), small_map().link_targets().end()));
}

TEST(Api, ThreadCountOutOfRangeIsRejectedNamingTheParameter) {
    BuildParams bp = test::cpu_params(4, 4);
    bp.threads = -1;
    try {
        build_vmap(test::sample(test::scene_path("cornell-empty"), 300, 1), bp);
        ADD_FAILURE() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("threads -1"), std::string::npos) << e.what();
    }
}

TEST(Api, ProgressStartsAtZeroRisesAndEndsAtTheLeafPairCount) {
    BuildParams bp = test::cpu_params(5, 4);
    bp.max_batch_pairs = 4096;  // several batches
    std::mutex mu;
    std::vector<ProgressInfo> seen;
    bp.progress = [&](const ProgressInfo& p) {
        std::lock_guard lock(mu);
        seen.push_back(p);
        return true;
    };
    BuildStats st;
    build_vmap(test::sample(test::scene_path("cornell-empty"), 1500, 2), bp, &st);
    ASSERT_GE(seen.size(), 2u);
    EXPECT_EQ(seen.front().done, 0u);
    EXPECT_GT(seen.front().estimate_seconds, 0);
    EXPECT_STREQ(seen.front().stage, "leaf pairs");
    EXPECT_EQ(seen.back().done, seen.back().total);
    // Every leaf pair, whether decided at node level or walked.
    EXPECT_EQ(seen.back().total, st.leaf_pairs);
    for (size_t k = 1; k < seen.size(); ++k) EXPECT_LE(seen[k - 1].done, seen[k].done);
}

TEST(Api, ProgressCallbackCancelsTheBuild) {
    // A build of seconds (60,000 points, one a leaf: about 1.8e9 leaf pairs; 20,000 finished
    // between two reports on the GPU machine's 16 AVX-512 cores), cancelled at the second
    // report (reports come at most ~10 a second): it stops early with Cancelled. A smaller
    // build can finish between two reports, which is no cancellation to test.
    BuildParams bp = test::cpu_params(8, 1);
    std::atomic<int> calls{0};
    bp.progress = [&](const ProgressInfo&) { return ++calls < 2; };
    const auto points = test::sample(test::scene_path("cornell-empty"), 60000, 2);
    EXPECT_THROW(build_vmap(points, bp), Cancelled);
    EXPECT_GE(calls.load(), 2);
    // Cancelled at the first report too, before any batch is evaluated.
    calls = 1;
    EXPECT_THROW(build_vmap(points, bp), Cancelled);
    EXPECT_EQ(calls.load(), 2);
}

TEST(Api, ACancellingCallbackIsNotCalledAgain) {
    // The work may report on its way to its next cancellation check (a slow or loaded host:
    // CI at stop 46 saw a third call); the callback that said stop hears nothing more.
    int calls = 0;
    const ProgressCallback cb = [&](const ProgressInfo&) {
        ++calls;
        return false;
    };
    detail::Progress p("test", 10, &cb);
    EXPECT_EQ(calls, 1);
    EXPECT_TRUE(p.cancelled());
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
    p.add(5);
    p.set(8);
    p.finish();
    EXPECT_EQ(calls, 1);
    EXPECT_THROW(p.throw_if_cancelled(), Cancelled);
}

TEST(Api, CudaWithoutAUsableDeviceIsAnErrorAndAutoFallsBackWithANote) {
    std::string why;
    if (detail::make_cuda_backend(&why)) GTEST_SKIP() << "a GPU is present";
    BuildParams bp = test::cpu_params(4, 4);
    bp.backend = Backend::kCuda;
    const PointSet pts = test::sample(test::scene_path("cornell-empty"), 400, 1);
    try {
        build_vmap(pts, bp);
        ADD_FAILURE() << "backend cuda ran without a device";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("backend cuda"), std::string::npos) << e.what();
    }
    bp.backend = Backend::kAuto;
    std::string note;
    bp.progress = [&](const ProgressInfo& p) {
        if (p.done == 0) note = p.note;
        return true;
    };
    BuildStats st;
    build_vmap(pts, bp, &st);
    EXPECT_NE(note.find("no usable GPU"), std::string::npos) << note;
    EXPECT_EQ(st.note, note);
}

// The benchmarks' entry points (vmap/visibility_map.h): the CUDA backend's name as the backend
// gives it, or the reason there is none; the CPU's leaf-pair rate on a sample.
TEST(Api, CudaBackendNameIsTheBackendsOwnOrEmptyWithTheReason) {
    std::string why, why_public;
    const auto backend = detail::make_cuda_backend(&why);
    const std::string name = cuda_backend_name(&why_public);
    if (backend) {
        EXPECT_EQ(name, backend->name());
    } else {
        EXPECT_EQ(name, "");
        EXPECT_EQ(why_public, why);
        EXPECT_FALSE(why.empty());
    }
}

TEST(Api, SampledCpuPairRateIsPositiveAndSmallTreesAreNotSampled) {
    PointSet pts = test::sample(test::scene_path("cornell-empty"), 4000, 1);
    std::vector<uint32_t> order;
    const Octree big = Octree::build(pts, {7, 4}, order);
    ASSERT_GE(big.num_leaves(), 64);
    const double rate = sampled_cpu_pair_rate(big, VisibilityParams{}, 20000);
    EXPECT_TRUE(std::isfinite(rate) && rate > 0) << rate;
    PointSet few = test::sample(test::scene_path("cornell-empty"), 100, 1);
    const Octree small = Octree::build(few, {3, 4}, order);
    ASSERT_LT(small.num_leaves(), 64);
    EXPECT_EQ(sampled_cpu_pair_rate(small, VisibilityParams{}, 20000), 1e9);
}

TEST(Api, BatchQueriesAgreeWithSingleOnes) {
    const VisibilityMap& vm = small_map();
    std::vector<uint32_t> pairs;
    for (uint32_t k = 0; k < 3000; ++k)
        pairs.insert(pairs.end(), {(k * 7919) % 1500, (k * 104729 + 3) % 1500});
    std::vector<uint8_t> ans(pairs.size() / 2);
    query_pairs(vm, pairs, ans);
    for (size_t k = 0; k < ans.size(); ++k)
        ASSERT_EQ(ans[k], uint8_t(vm.query(pairs[2 * k], pairs[2 * k + 1]))) << k;
    const std::vector<uint32_t> ids = {0, 17, 1499, 17};
    const VisibleSets s = visible_sets(vm, ids);
    ASSERT_EQ(s.offsets.size(), ids.size() + 1);
    for (size_t k = 0; k < ids.size(); ++k)
        EXPECT_EQ(std::vector<uint32_t>(s.targets.begin() + s.offsets[k],
                                        s.targets.begin() + s.offsets[k + 1]),
                  vm.visible_set(ids[k]));
}

TEST(Api, BatchQueryWithAnIdOutOfRangeNamesThePairAndAnswersNothing) {
    const VisibilityMap& vm = small_map();
    const std::vector<uint32_t> pairs = {0, 1, 2, 1500};
    std::vector<uint8_t> ans(2, 7);
    try {
        query_pairs(vm, pairs, ans);
        ADD_FAILURE() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("pair 1"), std::string::npos) << e.what();
    }
    EXPECT_EQ(ans, std::vector<uint8_t>(2, 7));
    std::vector<uint8_t> short_out(1);
    EXPECT_THROW(query_pairs(vm, std::vector<uint32_t>{0, 1, 2, 3}, short_out), Error);
    EXPECT_THROW(visible_sets(vm, std::vector<uint32_t>{1500}), Error);
}

TEST(Api, DataDirHoldsTheScenesAndHonoursTheEnvironment) {
    const std::string d = data_dir();
    EXPECT_TRUE(std::filesystem::exists(d + "/scenes/cornell-bunny.json")) << d;
    EXPECT_EQ(default_scene_path(), d + "/scenes/cornell-bunny.json");
    ASSERT_EQ(setenv("VMAP_DATA_DIR", "/nonexistent-vmap-data", 1), 0);
    try {
        (void)data_dir();
        ADD_FAILURE() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("VMAP_DATA_DIR=/nonexistent"), std::string::npos);
    }
    ASSERT_EQ(setenv("VMAP_DATA_DIR", d.c_str(), 1), 0);
    EXPECT_EQ(data_dir(), d);
    unsetenv("VMAP_DATA_DIR");
}

TEST(Api, VersionAndCommitAreSet) {
    EXPECT_STREQ(version(), "0.1.0");
    EXPECT_GT(std::strlen(commit()), 0u);
}

std::string npy(const std::string& descr, const std::string& shape, const std::string& body,
                bool fortran = false) {
    std::string h = "{'descr': '" + descr + "', 'fortran_order': " + (fortran ? "True" : "False") +
                    ", 'shape': (" + shape + "), }";
    h.append((10 + h.size() + 1 + 63) / 64 * 64 - 10 - h.size() - 1, ' ');
    h += '\n';
    std::string out = "\x93NUMPY\x01";
    out += '\0';
    out += char(h.size() & 0xff);
    out += char(h.size() >> 8);
    return out + h + body;
}

std::string le(std::initializer_list<uint64_t> v, int bytes, bool big = false) {
    std::string s;
    for (uint64_t x : v)
        for (int k = 0; k < bytes; ++k) s += char((x >> (8 * (big ? bytes - 1 - k : k))) & 0xff);
    return s;
}

TEST(Npy, ReadsPairsOfEveryIntegerLayout) {
    using vmap::read_npy_pairs;
    const std::vector<uint32_t> want = {1, 2, 3, 40000};
    EXPECT_EQ(read_npy_pairs(npy("<i8", "2, 2", le({1, 2, 3, 40000}, 8)), "a"), want);
    EXPECT_EQ(read_npy_pairs(npy(">i4", "2, 2", le({1, 2, 3, 40000}, 4, true)), "a"), want);
    EXPECT_EQ(read_npy_pairs(npy("<u4", "2,2", le({1, 2, 3, 40000}, 4)), "a"), want);
    // Fortran order: the first column, then the second.
    EXPECT_EQ(read_npy_pairs(npy("<i2", "2, 2", le({1, 3, 2, 300}, 2), true), "a"),
              (std::vector<uint32_t>{1, 2, 3, 300}));
    EXPECT_TRUE(read_npy_pairs(npy("<i8", "0, 2", ""), "a").empty());
}

TEST(Npy, BadFilesNameTheFileAndTheField) {
    using vmap::read_npy_pairs;
    auto fails = [](const std::string& data, const std::string& what) {
        try {
            read_npy_pairs(data, "p.npy");
            ADD_FAILURE() << "no error for " << what;
        } catch (const Error& e) {
            const std::string m = e.what();
            EXPECT_NE(m.find("p.npy"), std::string::npos) << m;
            EXPECT_NE(m.find(what), std::string::npos) << m;
        }
    };
    fails("PK\x03\x04 not numpy", "magic");
    fails(npy("<f8", "2, 2", le({1, 2, 3, 4}, 8)), "integer dtype");
    fails(npy("<i8", "2, 3", le({1, 2, 3, 4, 5, 6}, 8)), "(M, 2)");
    fails(npy("<i8", "4,", le({1, 2, 3, 4}, 8)), "(M, 2)");
    fails(npy("<i8", "2, 2", le({1, 2, 3}, 8)), "truncated");
    fails(npy("<i8", "1, 2", le({1, uint64_t(-5)}, 8)), "out of range");
    fails(npy("<u8", "1, 2", le({1, uint64_t(1) << 33}, 8)), "out of range");
    fails(npy("<i8", "1, 2", le({1, 2}, 8)).substr(0, 40), "truncated header");
}

}  // namespace
}  // namespace vmap
