// Scale-free geometry (Octree::build_in_unit_frame): the same cloud written in any unit gives the
// same V-map, and queries, outputs and the .vmap stay in the input's units.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "test_files.h"
#include "test_util.h"
#include "vmap/error.h"
#include "vmap/gi.h"
#include "vmap/query.h"
#include "vmap/render.h"

namespace vmap {
namespace {

using test::cpu_params;
using test::sample;
using test::scene_path;
using test::ScratchDir;
using test::slurp;

PointSet scaled(const PointSet& p, double s) {
    PointSet q = p;
    for (Vec3& v : q.positions) v = {float(v.x * s), float(v.y * s), float(v.z * s)};
    for (float& r : q.radii) r = float(r * s);
    return q;
}

class UnitFrame : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        cloud_ = new PointSet(sample(scene_path("cornell-empty"), 1500));
        unit_ = new VisibilityMap(build_vmap(*cloud_, cpu_params(5, 4)));
    }
    static void TearDownTestSuite() {
        delete unit_;
        delete cloud_;
    }
    static VisibilityMap at(double s) { return build_vmap(scaled(*cloud_, s), cpu_params(5, 4)); }
    static inline PointSet* cloud_ = nullptr;
    static inline VisibilityMap* unit_ = nullptr;
};

void expect_same_links(const VisibilityMap& a, const VisibilityMap& b) {
    ASSERT_EQ(a.octree().num_nodes(), b.octree().num_nodes());
    EXPECT_EQ(a.octree().skip(), b.octree().skip());
    EXPECT_EQ(a.order(), b.order());
    EXPECT_EQ(a.link_offsets(), b.link_offsets());
    ASSERT_EQ(a.link_targets().size(), b.link_targets().size());
    EXPECT_EQ(0, std::memcmp(a.link_targets().data(), b.link_targets().data(),
                             a.link_targets().size() * sizeof(int32_t)));
}

// Squared distances of 1e20 overflow a float: built in the input's units the map was empty.
TEST_F(UnitFrame, TheSameCloudInAnyUnitGivesTheSameVmap) {
    ASSERT_GT(unit_->num_links(), 100u);
    for (double s : {1e-6, 1e6, 1e20, 1e-30, 1e30}) {
        SCOPED_TRACE(s);
        const VisibilityMap vm = at(s);
        expect_same_links(*unit_, vm);
    }
}

// A power-of-two unit is exact: the file is byte for byte the same apart from the scale.
TEST_F(UnitFrame, PowerOfTwoUnitsGiveIdenticalFilesApartFromTheScale) {
    ScratchDir dir;
    save_vmap(dir.path("unit.vmap"), *unit_);
    const std::string want = slurp(dir.path("unit.vmap"));
    for (int k : {-20, 20, 66, -100, 120}) {
        SCOPED_TRACE(k);
        const VisibilityMap vm = at(std::ldexp(1.0, k));
        EXPECT_EQ(vm.octree().scale(), std::ldexp(unit_->octree().scale(), k));
        const std::string p = dir.path("k" + std::to_string(k) + ".vmap");
        save_vmap(p, vm);
        VisibilityMap back = load_vmap(p);
        EXPECT_EQ(back.octree().scale(), vm.octree().scale());
        test::octree_of(back).scale = unit_->octree().scale();
        save_vmap(p, back);
        EXPECT_TRUE(slurp(p) == want);
    }
}

TEST_F(UnitFrame, QueriesAndOutputsAreInTheInputsUnits) {
    const double s = 1e20;
    const PointSet big = scaled(*cloud_, s);
    const VisibilityMap vm = at(s);
    const PointSet back = points_in_input_order(vm);
    ASSERT_EQ(back.size(), big.size());
    for (size_t i = 0; i < big.size(); ++i) {
        ASSERT_EQ(back.positions[i], big.positions[i]) << i;  // a power-of-two frame: exact
        ASSERT_EQ(back.radii[i], big.radii[i]) << i;
    }
    for (uint32_t i : {3u, 500u, 1400u}) {
        EXPECT_EQ(nearest_point(vm, big.positions[i]), nearest_point(*unit_, cloud_->positions[i]));
        EXPECT_EQ(nearest_point(big, big.positions[i]), i);
        const Vec3 dir = Vec3{0, 1, 0} - cloud_->normals[i] * 0.5f;
        const RayHit a = shoot_ray(*unit_, i, dir), b = shoot_ray(vm, i, dir);
        ASSERT_EQ(a.hit, b.hit);
        if (!a.hit) continue;
        EXPECT_EQ(a.id, b.id);
        EXPECT_NEAR(b.distance / s, a.distance, 1e-6 * a.distance);
    }
}

TEST_F(UnitFrame, RadiosityIsTheSameInAnyUnitAndPowerScalesWithArea) {
    GiParams gp;
    gp.backend = Backend::kCpu;
    gp.bounces = 2;
    const std::vector<Vec3> a = solve_radiosity(*unit_, gp);
    for (double s : {1e-6, 1e6, 1e20}) {
        const VisibilityMap vm = at(s);
        const std::vector<Vec3> b = solve_radiosity(vm, gp);
        EXPECT_LT(relative_rms(b, a), 1e-5) << s;
        if (s > 1e6) continue;  // power in watts of a room 1e20 m wide is beyond a float
        const Vec3 pa = total_power(*unit_, a), pb = total_power(vm, b);
        EXPECT_NEAR(pb.x / (s * s), pa.x, 1e-4 * pa.x) << s;
    }
}

TEST(UnitFrameLimits, OnlyWhatCannotBeRepresentedIsRefused) {
    PointSet p = sample(scene_path("cornell-empty"), 300);
    // Spanning nearly the whole float range builds (the extent is taken in double).
    PointSet wide = p;
    wide.positions[0] = {-3e38f, 0, 0};
    wide.positions[1] = {3e38f, 0, 0};
    EXPECT_NO_THROW(build_vmap(wide, cpu_params(4, 4)));
    PointSet bad = p;
    bad.positions[7].y = std::numeric_limits<float>::infinity();
    test::expect_error([&] { build_vmap(bad, cpu_params(4, 4), nullptr, "c.ply"); },
                       {"c.ply", "point 7", "non-finite"});
    bad = p;
    bad.radii[5] = std::numeric_limits<float>::quiet_NaN();
    test::expect_error([&] { build_vmap(bad, cpu_params(4, 4), nullptr, "c.ply"); },
                       {"c.ply", "splat radius"});
    // One point, or all at one place: a frame from the coordinates' size.
    PointSet one;
    one.positions = {{1e30f, 2e30f, 3e30f}, {1e30f, 2e30f, 3e30f}};
    one.normals = {{0, 1, 0}, {0, 1, 0}};
    EXPECT_NO_THROW(build_vmap(one, cpu_params(4, 4)));
}

}  // namespace
}  // namespace vmap
