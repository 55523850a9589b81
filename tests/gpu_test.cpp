// The CUDA backend against the CPU backend: bit-identical leaf-pair tables, identical work
// counts, byte-identical V-maps. Labelled `gpu`; without a device every test reports SKIPPED.
#include <gtest/gtest.h>

#include <filesystem>

#include "test_files.h"
#include "test_util.h"
#include "visibility/backend.h"

namespace vmap {
namespace {

bool have_device(std::string* why) { return detail::make_cuda_backend(why) != nullptr; }

#define VMAP_REQUIRE_GPU()                                           \
    do {                                                             \
        std::string why_;                                            \
        if (!have_device(&why_)) GTEST_SKIP() << "no GPU: " << why_; \
    } while (0)

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
        EXPECT_NE(std::string(e.what()).find("--device " + std::to_string(n)), std::string::npos)
            << e.what();
    }
    const PointSet ps = test::sample(test::scene_path("cornell-bunny"), 1500);
    BuildParams bp = test::cpu_params(6, 1);
    bp.backend = "cuda";
    bp.device = n - 1;
    const VisibilityMap last = build_vmap(ps, bp);
    bp.device = 0;
    const VisibilityMap first = build_vmap(ps, bp);
    EXPECT_EQ(last.link_offsets, first.link_offsets);
    EXPECT_TRUE(std::equal(last.link_targets.begin(), last.link_targets.end(),
                           first.link_targets.begin(), first.link_targets.end()));
}

class GpuMatchesCpu : public ::testing::TestWithParam<BuildCase> {};

// Every leaf pair walked on both (construction leaf-pairs): the same bits, counts and V-map.
TEST_P(GpuMatchesCpu, VmapIsByteIdentical) {
    VMAP_REQUIRE_GPU();
    const BuildCase c = GetParam();
    const PointSet ps = test::sample(c.file(), c.points, 3);
    BuildParams bp = test::cpu_params(c.height, c.leaf_points);
    bp.construction = "leaf-pairs";
    BuildStats cs, gs;
    const VisibilityMap cpu = build_vmap(ps, bp, &cs);
    bp.backend = "cuda";
    const VisibilityMap gpu = build_vmap(ps, bp, &gs);
    EXPECT_NE(gs.backend.find("cuda"), std::string::npos) << gs.backend;
    EXPECT_EQ(gs.work.pairs, cs.work.pairs);
    EXPECT_EQ(gs.work.facing_pairs, cs.work.facing_pairs);
    EXPECT_EQ(gs.work.visible_pairs, cs.work.visible_pairs);
    EXPECT_EQ(gs.work.node_tests, cs.work.node_tests);
    EXPECT_EQ(gs.work.occluder_tests, cs.work.occluder_tests);
    EXPECT_EQ(gpu.link_offsets, cpu.link_offsets);
    EXPECT_EQ(gpu.link_targets, cpu.link_targets);
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
    bp.construction = "leaf-pairs";
    const VisibilityMap ref = build_vmap(ps, bp);
    bp.construction = "nodes";
    bp.walk_pairs = 256;
    BuildStats cs, gs;
    const VisibilityMap cpu = build_vmap(ps, bp, &cs);
    bp.backend = "cuda";
    const VisibilityMap gpu = build_vmap(ps, bp, &gs);
    EXPECT_NE(gs.backend.find("cuda"), std::string::npos) << gs.backend;
    EXPECT_EQ(gs.construction, "nodes");
    EXPECT_LT(gs.leaf_pairs_walked, gs.leaf_pairs);
    EXPECT_EQ(gs.work.pairs, cs.work.pairs);
    EXPECT_EQ(gs.work.facing_pairs, cs.work.facing_pairs);
    EXPECT_EQ(gs.work.visible_pairs, cs.work.visible_pairs);
    EXPECT_EQ(gpu.link_offsets, ref.link_offsets);
    EXPECT_EQ(gpu.link_targets, ref.link_targets);
    EXPECT_EQ(cpu.link_targets, ref.link_targets);
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

TEST(GpuBackend, RectanglesAreBitIdenticalToTheCpu) {
    VMAP_REQUIRE_GPU();
    PointSet ps = test::sample(test::scene_path("cornell-bunny"), 5000, 9);
    std::vector<uint32_t> order;
    const Octree t = Octree::build(ps, {8, 3}, order);
    const int32_t L = t.num_leaves();
    // Odd-sized rectangles, so rows end mid-word and jobs start at odd offsets.
    std::vector<detail::PairJob> jobs;
    uint64_t words = 0;
    for (int32_t r0 = 0; r0 + 37 < L / 2; r0 += 301) {
        detail::PairJob j;
        j.row0 = r0, j.rows = 37, j.col0 = L / 2 + r0 % 97, j.cols = std::min(L - j.col0, 1001);
        j.word_offset = words;
        words += detail::job_words(j);
        jobs.push_back(j);
    }
    std::string why;
    auto gpu = detail::make_cuda_backend(&why);
    auto cpu = detail::make_cpu_backend();
    VisibilityParams vp;
    gpu->prepare(t, vp, words);
    cpu->prepare(t, vp, words);
    gpu->submit(jobs, words, 1);
    cpu->submit(jobs, words, 1);
    WorkCounters gw, cw;
    const uint32_t* g = gpu->wait(1, gw);
    const uint32_t* c = cpu->wait(1, cw);
    ASSERT_EQ(std::vector<uint32_t>(g, g + words), std::vector<uint32_t>(c, c + words));
    EXPECT_EQ(gw.node_tests, cw.node_tests);
    EXPECT_GT(cw.visible_pairs, 0u);
    EXPECT_GT(gpu->peak_device_bytes(), 0u);
}

TEST(GpuBackend, AutoPicksTheGpuAndSaysSo) {
    VMAP_REQUIRE_GPU();
    BuildParams bp = test::cpu_params(5, 4);
    bp.backend = "auto";
    BuildStats st;
    build_vmap(test::sample(test::scene_path("cornell-empty"), 1000, 1), bp, &st);
    EXPECT_NE(st.backend.find("cuda"), std::string::npos) << st.backend;
}

TEST(GpuBackend, CudaRequestWithoutDeviceIsAnError) {
    std::string why;
    if (have_device(&why)) GTEST_SKIP() << "a GPU is present; the error is not reachable";
    BuildParams bp = test::cpu_params(5, 4);
    bp.backend = "cuda";
    try {
        build_vmap(test::sample(test::scene_path("cornell-empty"), 500, 1), bp);
        ADD_FAILURE() << "backend cuda ran without a device";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("backend cuda"), std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace vmap
