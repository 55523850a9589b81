// The CUDA radiosity solver against the CPU. The refinement (gi_link_blocks per link, blocks
// summed in one order on both sides), the bounces and the final gather (gi_final_gather_point)
// run the same bodies in the same summation order with no FMA contraction and IEEE sqrt and
// division on either side, so the interaction list, the radiosity after every bounce and the
// final gather must be bit-identical, not merely close. Labelled `gpu`; without a device every
// test reports SKIPPED.
#include <gtest/gtest.h>

#include <algorithm>

#include "backend_fixture.h"
#include "test_util.h"
#include "vmap/gi.h"

namespace vmap {
namespace {

struct GiCase {
    const char* scene;
    uint64_t points;
    int height;
    float theta;
};

class GiGpuMatchesCpu : public ::testing::TestWithParam<GiCase> {};

TEST_P(GiGpuMatchesCpu, RadiosityIsBitIdenticalEveryBounce) {
    VMAP_REQUIRE_GPU();
    const GiCase c = GetParam();
    const VisibilityMap vm = build_vmap(test::sample(test::scene_path(c.scene), c.points, 4),
                                        test::cpu_params(c.height, 4));
    GiParams p;
    p.theta = c.theta;
    p.backend = Backend::kCpu;
    RadiositySolver cpu(vm, p);
    p.backend = Backend::kCuda;
    RadiositySolver gpu(vm, p);
    ASSERT_EQ(gpu.stats().backend.rfind("cuda", 0), 0u) << gpu.stats().backend;
    EXPECT_EQ(gpu.stats().interactions(), cpu.stats().interactions());
    for (int b = 0; b < 4; ++b) {
        cpu.bounce();
        gpu.bounce();
        const auto x = cpu.radiosity(), y = gpu.radiosity();
        ASSERT_EQ(x.size(), y.size());
        size_t differ = 0;
        for (size_t i = 0; i < x.size(); ++i) differ += !(x[i] == y[i]);
        EXPECT_EQ(differ, 0u) << "bounce " << b + 1 << ", relative RMS " << relative_rms(y, x);
    }
    // reset() starts over on the device too.
    gpu.reset();
    cpu.reset();
    gpu.bounce();
    cpu.bounce();
    EXPECT_EQ(relative_rms(gpu.radiosity(), cpu.radiosity()), 0.0);
}

// Counts the entries that differ (bitwise, as floats compare: no NaN is expected).
template <class T>
size_t differing(const std::vector<T>& x, const std::vector<T>& y) {
    size_t d = x.size() == y.size() ? 0 : std::max(x.size(), y.size());
    for (size_t i = 0; i < std::min(x.size(), y.size()); ++i) d += !(x[i] == y[i]);
    return d;
}

// The device's refinement gives the CPU's interaction list, entry for entry, and the device's
// final gather the CPU's, for all points and for a list of them.
void expect_same_refinement_and_gather(const VisibilityMap& vm, float theta) {
    GiParams p;
    p.theta = theta;
    p.backend = Backend::kCpu;
    RadiositySolver cpu(vm, p);
    p.backend = Backend::kCuda;
    RadiositySolver gpu(vm, p);
    ASSERT_EQ(gpu.stats().backend.rfind("cuda", 0), 0u) << gpu.stats().backend;
    std::vector<uint64_t> rc, rg;
    std::vector<uint32_t> sc, sg;
    std::vector<float> cc, cg;
    std::vector<double> ac, ag;
    cpu.interaction_list(rc, sc, cc, ac);
    gpu.interaction_list(rg, sg, cg, ag);
    EXPECT_GT(sc.size(), 0u);
    EXPECT_EQ(differing(rc, rg), 0u);
    EXPECT_EQ(differing(sc, sg), 0u);
    EXPECT_EQ(differing(cc, cg), 0u);
    EXPECT_EQ(gpu.stats().node_interactions, cpu.stats().node_interactions);
    for (int b = 0; b < 2; ++b) cpu.bounce(), gpu.bounce();
    const auto fc = cpu.final_gather(2.0f), fgpu = gpu.final_gather(2.0f);
    EXPECT_EQ(differing(fc, fgpu), 0u) << "relative RMS " << relative_rms(fgpu, fc);
    std::vector<uint32_t> some;
    for (uint32_t i = 0; i < vm.points().size(); i += 7) some.push_back(i);
    const auto pc = cpu.final_gather(1e9f, some), pg = gpu.final_gather(1e9f, some);
    EXPECT_EQ(differing(pc, pg), 0u);
    EXPECT_EQ(pg.size(), some.size());
}

TEST_P(GiGpuMatchesCpu, RefinementAndFinalGatherAreBitIdentical) {
    VMAP_REQUIRE_GPU();
    const GiCase c = GetParam();
    const VisibilityMap vm = build_vmap(test::sample(test::scene_path(c.scene), c.points, 4),
                                        test::cpu_params(c.height, 4));
    expect_same_refinement_and_gather(vm, c.theta);
}

// One point a leaf (the shipped scenes' octree setting) at the GI's default theta.
TEST(GiGpu, OnePointALeafAtTheDefaults) {
    VMAP_REQUIRE_GPU();
    const VisibilityMap vm = build_vmap(test::sample(test::scene_path("cornell-bunny"), 6000, 4),
                                        test::cpu_params(8, 1));
    expect_same_refinement_and_gather(vm, 1.0f);
}

INSTANTIATE_TEST_SUITE_P(Scenes, GiGpuMatchesCpu,
                         ::testing::Values(GiCase{"cornell-empty", 3000, 6, 1.0f},
                                           GiCase{"cornell-bunny", 6000, 8, 4.0f},
                                           GiCase{"cornell-two-models", 8000, 9, 0.5f},
                                           GiCase{"cornell-two-models", 4000, 8, 1e9f}),
                         [](const ::testing::TestParamInfo<GiCase>& i) {
                             std::string s =
                                 std::string(i.param.scene) + "_" + std::to_string(i.param.points) +
                                 "_theta" +
                                 (i.param.theta > 1000 ? std::string("huge")
                                                       : std::to_string(int(i.param.theta * 10)));
                             for (char& ch : s)
                                 if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
                             return s;
                         });

}  // namespace
}  // namespace vmap
