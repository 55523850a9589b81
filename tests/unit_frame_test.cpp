// Scale-free geometry (Octree::build_in_unit_frame): the same cloud written in any unit gives the
// same V-map, and queries, outputs and the .vmap stay in the input's units.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "test_files.h"
#include "test_util.h"
#include "vmap/error.h"
#include "vmap/gi.h"
#include "vmap/io.h"
#include "vmap/query.h"
#include "vmap/render.h"
#include "vmap/scene.h"

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

// A georeferenced scan: the cornell room 4 million units from its file's zero, where a float
// is 0.25-0.5 apart. The file holds doubles.
constexpr std::array<double, 3> kFar = {512345.0, 4123456.0, 210.0};

TEST_F(UnitFrame, ACloudFarFromItsFilesZeroIsReadAroundItself) {
    ScratchDir dir;
    // The room on a grid of 2^-24 (every coordinate then exact in double 4e6 out, so the file
    // holds exactly the room moved).
    PointSet home = *cloud_;
    for (Vec3& v : home.positions)
        v = {std::ldexp(std::round(std::ldexp(v.x, 24)), -24),
             std::ldexp(std::round(std::ldexp(v.y, 24)), -24),
             std::ldexp(std::round(std::ldexp(v.z, 24)), -24)};
    PointSet far = home;
    far.origin = kFar;  // write_ply adds it back, in double
    const std::string path = dir.path("far.ply");
    write_ply(path, far);
    // Read as floats, the room collapses onto a few float steps.
    const ModelData raw = read_model(path);
    float worst = 0;
    for (size_t i = 0; i < raw.points.size(); ++i)
        worst = std::max(worst, std::fabs(float(double(raw.points.positions[i].y) - kFar[1]) -
                                          home.positions[i].y));
    EXPECT_GT(worst, 0.05f);
    ASSERT_TRUE(far_origin(raw.points.positions).has_value());
    // Read around itself: the room's own floats (its points are exact in double out there), and
    // the V-map of the room read at home.
    std::vector<std::string> done;
    const PointSet back = load_point_cloud(path, {}, &done);
    EXPECT_EQ(back.origin, kFar);  // the centre to a whole unit (the room is 0.55 wide)
    ASSERT_EQ(back.size(), home.size());
    for (size_t i = 0; i < back.size(); ++i) ASSERT_EQ(back.positions[i], home.positions[i]) << i;
    ASSERT_FALSE(done.empty());
    EXPECT_NE(done[0].find("coordinates: relative to (512345, 4123456, 210)"), std::string::npos)
        << done[0];
    const VisibilityMap vm = build_vmap(back, cpu_params(5, 4));
    ASSERT_GT(vm.num_links(), 100u);
    expect_same_links(build_vmap(home, cpu_params(5, 4)), vm);
    // The .vmap keeps the origin, and outputs go back to the file's coordinates.
    save_vmap(dir.path("far.vmap"), vm);
    const VisibilityMap loaded = load_vmap(dir.path("far.vmap"));
    EXPECT_EQ(loaded.points().origin, kFar);
    const PointSet out = points_in_input_order(loaded);
    EXPECT_EQ(out.origin, kFar);
    write_ply(dir.path("out.ply"), out);
    EXPECT_EQ(slurp(dir.path("out.ply")), slurp(path));
    // A map without one writes the file it always did: no origin field.
    save_vmap(dir.path("home.vmap"), *unit_);
    EXPECT_EQ(load_vmap(dir.path("home.vmap")).points().origin, (std::array<double, 3>{0, 0, 0}));
}

// A scene file's frame is the file's: a far cloud in it goes back there (in float, as before),
// so that its clouds and meshes stay together.
TEST_F(UnitFrame, AFarCloudInASceneFileStaysInTheFilesFrame) {
    ScratchDir dir;
    PointSet far = *cloud_;
    far.origin = kFar;
    write_ply(dir.path("far.ply"), far);
    const Scene sc = load_scene(dir.write("s.json", R"({"room": null, "clouds": [{"file": "far.ply"}]})"));
    ASSERT_EQ(sc.clouds.size(), 1u);
    const PointSet& c = sc.clouds[0];
    EXPECT_EQ(c.origin, (std::array<double, 3>{0, 0, 0}));
    ASSERT_EQ(c.size(), cloud_->size());
    for (size_t i = 0; i < c.size(); ++i)
        ASSERT_NEAR(c.positions[i].y, cloud_->positions[i].y + kFar[1], 0.5) << i;
}

TEST_F(UnitFrame, FarPointListsAndViewpointsAreTheFilesCoordinates) {
    ScratchDir dir;
    std::string text;
    for (const Vec3& p : cloud_->positions)
        text += fmt::format("{:.9f} {:.9f} {:.9f}\n", p.x + kFar[0], p.y + kFar[1], p.z + kFar[2]);
    const std::string path = dir.write("far.xyz", text);
    CloudOptions o;
    o.viewpoint = std::array<double, 3>{kFar[0] + 0.27, kFar[1] + 0.27, kFar[2] + 0.27};
    const PointSet back = load_point_cloud(path, o);
    EXPECT_EQ(back.origin, kFar);
    ASSERT_EQ(back.size(), cloud_->size());
    const Vec3 inside{0.27f, 0.27f, 0.27f};
    for (size_t i = 0; i < back.size(); ++i) {
        ASSERT_NEAR(back.positions[i].x, cloud_->positions[i].x, 1e-6) << i;
        ASSERT_NEAR(back.positions[i].z, cloud_->positions[i].z, 1e-6) << i;
        // Toward the viewpoint in the room's middle, which the file's coordinates name.
        ASSERT_GT(dot(back.normals[i], inside - back.positions[i]), 0) << i;
    }
}

TEST(UnitFrameLimits, OnlyCloudsFarForTheirSizeAreMoved) {
    const PointSet p = sample(scene_path("cornell-empty"), 300);
    EXPECT_FALSE(far_origin(p.positions).has_value());  // at home
    PointSet near = p;
    for (Vec3& v : near.positions) v = v + Vec3{100, 0, 0};  // 180 room widths out: still exact enough
    EXPECT_FALSE(far_origin(near.positions).has_value());
    PointSet out = p;
    for (Vec3& v : out.positions) v = v + Vec3{0, 0, -1000};
    const auto o = far_origin(out.positions);
    ASSERT_TRUE(o.has_value());
    EXPECT_EQ(*o, (std::array<double, 3>{0, 0, -1000}));
    EXPECT_FALSE(far_origin({}).has_value());
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
