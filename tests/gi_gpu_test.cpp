// The CUDA radiosity bounce against the CPU: the same interaction list, the same summation order
// and no FMA contraction on either side, so the radiosity must be bit-identical after every
// bounce. Labelled `gpu`; without a device every test reports SKIPPED.
#include <gtest/gtest.h>

#include "gi/gi_device.h"
#include "test_util.h"
#include "vmap/gi.h"

namespace vmap {
namespace {

#define VMAP_REQUIRE_GPU()                                                    \
    do {                                                                      \
        std::string why_;                                                     \
        if (!detail::make_gi_cuda(&why_)) GTEST_SKIP() << "no GPU: " << why_; \
    } while (0)

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
