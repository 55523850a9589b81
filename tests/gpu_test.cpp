// The CUDA backend against the CPU backend: bit-identical leaf-pair tables, identical work
// counts, byte-identical V-maps. Labelled `gpu`; without a device every test reports SKIPPED.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <random>

#include "backend_fixture.h"
#include "test_files.h"
#include "test_util.h"
#include "visibility/backend.h"
#include "visibility/node_pair.h"
#include "vmap/normals.h"

namespace vmap {
namespace {


using test::BuildCase;

// --device picks among the visible devices; one past them is an error naming the option, and
// the last one builds the same map as device 0.
TEST(GpuDevice, DeviceIndexIsCheckedAndUsed) {
    VMAP_REQUIRE_GPU();
    const int n = detail::cuda_device_count();
    ASSERT_GT(n, 0);
    std::string why;
    try {
        detail::make_cuda_backend(&why, n);
        FAIL() << "device " << n << " of " << n << " accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("device " + std::to_string(n)), std::string::npos)
            << e.what();
    }
    const PointSet ps = test::sample(test::scene_path("cornell-bunny"), 1500);
    BuildParams bp = test::cpu_params(6, 1);
    bp.backend = Backend::kCuda;
    bp.device = n - 1;
    const VisibilityMap last = build_vmap(ps, bp);
    bp.device = 0;
    const VisibilityMap first = build_vmap(ps, bp);
    EXPECT_EQ(last.link_offsets(), first.link_offsets());
    EXPECT_TRUE(std::equal(last.link_targets().begin(), last.link_targets().end(),
                           first.link_targets().begin(), first.link_targets().end()));
}

class GpuMatchesCpu : public ::testing::TestWithParam<BuildCase> {};

// Every leaf pair walked on both (construction leaf-pairs): the same bits, counts and V-map.
TEST_P(GpuMatchesCpu, VmapIsByteIdentical) {
    VMAP_REQUIRE_GPU();
    const BuildCase c = GetParam();
    const PointSet ps = test::sample(c.file(), c.points, 3);
    BuildParams bp = test::cpu_params(c.height, c.leaf_points);
    bp.construction = Construction::kLeafPairs;
    BuildStats cs, gs;
    const VisibilityMap cpu = build_vmap(ps, bp, &cs);
    bp.backend = Backend::kCuda;
    const VisibilityMap gpu = build_vmap(ps, bp, &gs);
    EXPECT_NE(gs.backend.find("cuda"), std::string::npos) << gs.backend;
    EXPECT_EQ(gs.work.pairs, cs.work.pairs);
    EXPECT_EQ(gs.work.facing_pairs, cs.work.facing_pairs);
    EXPECT_EQ(gs.work.visible_pairs, cs.work.visible_pairs);
    EXPECT_EQ(gs.work.node_tests, cs.work.node_tests);
    EXPECT_EQ(gs.work.occluder_tests, cs.work.occluder_tests);
    EXPECT_EQ(gpu.link_offsets(), cpu.link_offsets());
    EXPECT_TRUE(std::ranges::equal(gpu.link_targets(), cpu.link_targets()));
    const auto dir = std::filesystem::temp_directory_path();
    const std::string a = (dir / "vmap_gpu_test_cpu.vmap").string();
    const std::string b = (dir / "vmap_gpu_test_gpu.vmap").string();
    save_vmap(a, cpu);
    save_vmap(b, gpu);
    EXPECT_EQ(test::slurp(a), test::slurp(b));
    std::filesystem::remove(a);
    std::filesystem::remove(b);
}

// The node path on the GPU (host decisions, GPU walks of the rest) against the CPU's leaf-pair
// path and the CPU's node path. With the same rectangles the two walk the same leaf pairs; the
// CPU walks a job over its shaft's nodes only, so only the answers, not the node tests, agree.
TEST_P(GpuMatchesCpu, NodePathGivesTheSameVmap) {
    VMAP_REQUIRE_GPU();
    const BuildCase c = GetParam();
    const PointSet ps = test::sample(c.file(), c.points, 3);
    BuildParams bp = test::cpu_params(c.height, c.leaf_points);
    bp.construction = Construction::kLeafPairs;
    const VisibilityMap ref = build_vmap(ps, bp);
    bp.construction = Construction::kNodes;
    bp.walk_pairs = 256;
    BuildStats cs, gs;
    const VisibilityMap cpu = build_vmap(ps, bp, &cs);
    bp.backend = Backend::kCuda;
    const VisibilityMap gpu = build_vmap(ps, bp, &gs);
    EXPECT_NE(gs.backend.find("cuda"), std::string::npos) << gs.backend;
    EXPECT_EQ(gs.construction, "nodes");
    EXPECT_LT(gs.leaf_pairs_walked, gs.leaf_pairs);
    EXPECT_EQ(gs.work.pairs, cs.work.pairs);
    EXPECT_EQ(gs.work.facing_pairs, cs.work.facing_pairs);
    EXPECT_EQ(gs.work.visible_pairs, cs.work.visible_pairs);
    EXPECT_EQ(gpu.link_offsets(), ref.link_offsets());
    EXPECT_TRUE(std::ranges::equal(gpu.link_targets(), ref.link_targets()));
    EXPECT_TRUE(std::ranges::equal(cpu.link_targets(), ref.link_targets()));
    // The device decides exactly what the host decides.
    EXPECT_EQ(gs.node_pairs_tested, cs.node_pairs_tested);
    EXPECT_EQ(gs.shaft_node_tests, cs.shaft_node_tests);
    EXPECT_EQ(gs.leaf_pairs_walked, cs.leaf_pairs_walked);
    // The frontier in slices of a few pairs: the same map.
    bp.max_level_pairs = 5;
    const VisibilityMap sliced = build_vmap(ps, bp);
    EXPECT_TRUE(std::ranges::equal(sliced.link_targets(), ref.link_targets()));
}

INSTANTIATE_TEST_SUITE_P(Scenes, GpuMatchesCpu,
                         ::testing::Values(BuildCase{"cornell-empty", 3000, 5, 4},
                                           BuildCase{"cornell-bunny", 6000, 7, 4},
                                           BuildCase{"cornell-bunny", 8000, 9, 2},
                                           BuildCase{"cornell-two-models", 8000, 8, 4},
                                           BuildCase{"./room-with-block.json", 4000, 10, 1},
                                           BuildCase{"cornell-dragon", 12000, 10, 4}),
                         [](const ::testing::TestParamInfo<BuildCase>& i) {
                             return test::case_name(i.param, false);
                         });

// A noisy scan with its roughness (exits_at_an_end's rough-sheet rule fires): the GPU's V-map
// is the CPU's, byte for byte, on the leaf-pair path and the node path.
TEST(GpuBackend, ANoisyCloudWithItsRoughnessIsTheCpusVmap) {
    VMAP_REQUIRE_GPU();
    PointSet ps = test::sample(test::scene_path("cornell-bunny"), 6000, 3);
    std::mt19937 rng(8);
    std::normal_distribution<float> g(0.f, 0.002f);  // about a quarter of the spacing
    for (Vec3& p : ps.positions) p += Vec3{g(rng), g(rng), g(rng)};
    BuildParams bp = test::cpu_params(8, 1);
    bp.visibility.roughness = roughness_of(estimate_surface_noise(ps));
    ASSERT_GT(bp.visibility.roughness, 0.f);
    bp.construction = Construction::kLeafPairs;
    BuildStats cs, gs, rs;
    const VisibilityMap cpu = build_vmap(ps, bp, &cs);
    bp.backend = Backend::kCuda;
    const VisibilityMap gpu = build_vmap(ps, bp, &gs);
    EXPECT_NE(gs.backend.find("cuda"), std::string::npos) << gs.backend;
    EXPECT_EQ(gs.work.visible_pairs, cs.work.visible_pairs);
    EXPECT_EQ(gs.work.occluder_tests, cs.work.occluder_tests);
    EXPECT_EQ(gpu.link_offsets(), cpu.link_offsets());
    EXPECT_TRUE(std::ranges::equal(gpu.link_targets(), cpu.link_targets()));
    bp.construction = Construction::kNodes;
    const VisibilityMap nodes = build_vmap(ps, bp);
    EXPECT_TRUE(std::ranges::equal(nodes.link_targets(), cpu.link_targets()));
    // The rule fires: without the roughness fewer pairs are visible.
    bp.visibility.roughness = 0;
    bp.construction = Construction::kLeafPairs;
    (void)build_vmap(ps, bp, &rs);
    EXPECT_LT(rs.work.visible_pairs, gs.work.visible_pairs);
}

// The GPU's table and counts for `jobs` (kernel VMAP_CUDA_VARIANT = variant) against the CPU's.
void expect_same_tables(const Octree& t, const std::vector<detail::PairJob>& jobs,
                        uint64_t words, const char* variant) {
    setenv("VMAP_CUDA_VARIANT", variant, 1);
    std::string why;
    auto gpu = detail::make_cuda_backend(&why);
    unsetenv("VMAP_CUDA_VARIANT");
    auto cpu = detail::make_cpu_backend();
    VisibilityParams vp;
    gpu->prepare(t, vp, words);
    cpu->prepare(t, vp, words);
    gpu->submit(jobs, words, 1);
    cpu->submit(jobs, words, 1);
    WorkCounters gw, cw;
    const uint32_t* g = gpu->wait(1, gw);
    const uint32_t* c = cpu->wait(1, cw);
    ASSERT_EQ(std::vector<uint32_t>(g, g + words), std::vector<uint32_t>(c, c + words))
        << variant;
    EXPECT_EQ(gw.pairs, cw.pairs) << variant;
    EXPECT_EQ(gw.node_tests, cw.node_tests) << variant;
    EXPECT_EQ(gw.occluder_tests, cw.occluder_tests) << variant;
    EXPECT_GT(cw.visible_pairs, 0u);
    EXPECT_GT(gpu->peak_device_bytes(), 0u);
}

// Rectangles of leaf pairs over the octree of a scene sampled at `points` points, in one batch.
struct Rectangles {
    Octree t;
    int32_t L = 0;
    std::vector<detail::PairJob> jobs;
    uint64_t words = 0;
    Rectangles(const char* scene, int points, uint64_t seed, int leaf_points) {
        PointSet ps = test::sample(test::scene_path(scene), points, seed);
        std::vector<uint32_t> order;
        t = Octree::build(ps, {8, leaf_points}, order);
        L = t.num_leaves();
    }
    void add(int32_t row0, int32_t rows, int32_t col0, int32_t cols) {
        detail::PairJob j;
        j.row0 = row0, j.rows = rows, j.col0 = col0, j.cols = cols;
        j.word_offset = words;
        words += detail::job_words(j);
        jobs.push_back(j);
    }
    void check(const char* variant) const {  // expect_same_tables
        expect_same_tables(t, jobs, words, variant);
    }
};

TEST(GpuBackend, RectanglesAreBitIdenticalToTheCpu) {
    VMAP_REQUIRE_GPU();
    Rectangles r("cornell-bunny", 5000, 9, 3);
    // Odd-sized rectangles, so rows end mid-word and jobs start at odd offsets.
    const int32_t L = r.L;
    for (int32_t r0 = 0; r0 + 37 < L / 2; r0 += 301)
        r.add(r0, 37, L / 2 + r0 % 97, std::min(L - (L / 2 + r0 % 97), 1001));
    r.check("packet");
}

// Rectangles of every small shape, packed 32 leaf pairs to a warp across rows and jobs.
TEST(GpuBackend, SmallRectanglesPackedIntoWarpsAreBitIdenticalToTheCpu) {
    VMAP_REQUIRE_GPU();
    Rectangles r("cornell-bunny", 4000, 9, 2);
    const int32_t L = r.L;
    int k = 0;
    for (int32_t r0 = 0; r0 + 40 < L / 2; r0 += 13, ++k)
        r.add(r0, 1 + k % 7, L / 2 + (r0 * 7) % (L / 2 - 70), 1 + (k * 5) % 67);
    for (const char* variant : {"packet", "lane"}) r.check(variant);
}

// A batch large enough that the packet kernel's warps take chunks of 512 pairs (its largest),
// which end mid-row and mid-word, and queue more than 32 facing pairs from a chunk: the
// compaction of facing pairs into packets changes no bit and no count.
TEST(GpuBackend, LargeBatchOfFacingPairsInChunksIsBitIdenticalToTheCpu) {
    VMAP_REQUIRE_GPU();
    Rectangles r("cornell-two-models", 6000, 4, 1);
    const int32_t L = r.L;
    ASSERT_GT(int64_t(L / 2) * (L - L / 2), int64_t(132) * 32 * 512);  // chunks of 512 on an H100
    r.add(0, L / 2 - 3, L / 2 - 3, L - (L / 2 - 3));
    r.add(L / 2 - 3, 3, L / 2, 77);
    r.check("packet");
}

// decide_node_pair on the device against the host, pair by pair, counts included.
TEST(GpuBackend, NodeDecisionsOnTheDeviceAreTheHosts) {
    VMAP_REQUIRE_GPU();
    PointSet ps = test::sample(test::scene_path("cornell-two-models"), 5000, 5);
    std::vector<uint32_t> order;
    const Octree t = Octree::build(ps, {8, 2}, order);
    const auto nb = detail::node_bounds(t);
    VisibilityParams vp;
    const detail::NodePairContext c{octree_view(t),      nb.nodes.data(), nb.cones.data(),
                                    t.skip().data(), vp,              detail::node_pair_margin(t.boxes()[0])};
    std::vector<detail::NodePairRef> pairs;
    for (int32_t a = 0; a < t.num_nodes(); a += 3)
        for (int32_t b = t.skip()[a]; b < t.num_nodes(); b += 17) pairs.push_back({a, b});
    std::vector<uint8_t> host(pairs.size()), dev(pairs.size(), 99);
    struct {
        uint64_t shaft_node_tests = 0;
    } wc;
    for (size_t i = 0; i < pairs.size(); ++i)
        if (detail::worth_deciding(c, pairs[i].a, pairs[i].b))
            host[i] = uint8_t(detail::decide_node_pair(c, pairs[i].a, pairs[i].b, &wc));
    std::string why;
    auto gpu = detail::make_cuda_backend(&why);
    gpu->prepare(t, vp, 1024);
    gpu->set_node_context(&c);
    uint64_t shaft = 0;
    ASSERT_TRUE(gpu->decide(pairs, dev.data(), &shaft));
    EXPECT_EQ(dev, host);
    EXPECT_EQ(shaft, wc.shaft_node_tests);
    uint64_t decided = 0;
    for (uint8_t d : host) decided += d != 0;
    EXPECT_GT(decided, pairs.size() / 10);
}

TEST(GpuBackend, AutoPicksTheGpuAndSaysSo) {
    VMAP_REQUIRE_GPU();
    BuildParams bp = test::cpu_params(5, 4);
    bp.backend = Backend::kAuto;
    BuildStats st;
    build_vmap(test::sample(test::scene_path("cornell-empty"), 1000, 1), bp, &st);
    EXPECT_NE(st.backend.find("cuda"), std::string::npos) << st.backend;
}

TEST(GpuBackend, CudaRequestWithoutDeviceIsAnError) {
    if (test::why_unusable(Backend::kCuda).empty())
        GTEST_SKIP() << "a GPU is present; the error is not reachable";
    BuildParams bp = test::cpu_params(5, 4);
    bp.backend = Backend::kCuda;
    try {
        build_vmap(test::sample(test::scene_path("cornell-empty"), 500, 1), bp);
        ADD_FAILURE() << "backend cuda ran without a device";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("backend cuda"), std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace vmap
