// vmap::load_input (include/vmap/input.h, src/scene/input.cpp): each kind of input, the
// overrides, and the overrides that do not apply.
#include "vmap/input.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <random>

#include "test_files.h"
#include "test_util.h"
#include "vmap/error.h"

namespace vmap {
namespace {

bool throws_naming(const InputOptions& o, const std::string& part) {
    try {
        (void)load_input(o);
    } catch (const Error& e) {
        return std::string(e.what()).find(part) != std::string::npos;
    }
    return false;
}

TEST(Input, ASceneIsSampledWithTheOverridesInPlaceOfTheScenesValues) {
    InputOptions o;
    o.path = test::scene_path("cornell-bunny");
    o.points = 700;
    o.seed = 3;
    o.max_height = 5;
    const Input in = load_input(o);
    EXPECT_EQ(in.kind, InputKind::kScene);
    EXPECT_EQ(in.points.positions, test::sample(o.path, 700, 3).positions);
    EXPECT_EQ(in.octree.max_height, 5);
    const Scene sc = load_scene(o.path);
    EXPECT_EQ(in.octree.leaf_points, sc.octree ? sc.octree->leaf_points : OctreeParams{}.leaf_points);
    EXPECT_EQ(in.name, sc.name);
    EXPECT_EQ(in.camera.has_value(), sc.camera.has_value());
    EXPECT_FALSE(in.vmap);
}

TEST(Input, ACloudIsReadAndSamplingOverridesAreAnErrorNamingTheFile) {
    test::ScratchDir dir;
    InputOptions o;
    o.path = dir.path("c.xyzn");
    {
        std::ofstream f(o.path);
        for (int i = 0; i < 50; ++i) f << i * 0.1 << " " << (i % 7) * 0.1 << " 0 0 0 1\n";
    }
    o.leaf_points = 3;
    const Input in = load_input(o);
    EXPECT_EQ(in.kind, InputKind::kCloud);
    EXPECT_EQ(in.points.size(), 50u);
    EXPECT_EQ(in.octree.leaf_points, 3);
    EXPECT_EQ(in.name, "c.xyzn");
    // No sampling known: the floor from how evenly the cloud was sampled (a grid: evenly),
    // and the build's report says so; a given floor is kept.
    EXPECT_EQ(in.octree.delta_floor, OctreeParams::kEvenDeltaFloor);
    EXPECT_TRUE(std::any_of(in.done.begin(), in.done.end(), [](const std::string& l) {
        return l.find("occluder disc floor: 2.00 splat radii") != std::string::npos &&
               l.find("sampled evenly") != std::string::npos;
    }));
    o.delta_floor = 3.f;
    EXPECT_EQ(load_input(o).octree.delta_floor, 3.f);
    o.delta_floor.reset();
    {
        std::ofstream f(o.path);
        std::mt19937 rng(9);
        std::uniform_real_distribution<float> u(0.f, 1.f);
        for (int i = 0; i < 20000; ++i) f << u(rng) << " " << u(rng) << " 0 0 0 1\n";
    }
    EXPECT_NEAR(load_input(o).octree.delta_floor, OctreeParams::kDefaultDeltaFloor, 0.06f);
    o.seed = 1;
    EXPECT_TRUE(throws_naming(o, "c.xyzn: points, seed and sampling (--points, --seed"));
    o.seed.reset();
    o.pattern = SamplePattern::kUniform;
    EXPECT_TRUE(throws_naming(o, "c.xyzn: points, seed and sampling"));
}

TEST(Input, ASceneFloorFollowsItsSamplingUnlessGiven) {
    InputOptions o;
    o.path = test::scene_path("cornell-bunny");
    o.points = 500;
    EXPECT_EQ(load_input(o).octree.delta_floor, OctreeParams::kEvenDeltaFloor);
    o.pattern = SamplePattern::kUniform;
    EXPECT_EQ(load_input(o).octree.delta_floor, OctreeParams::kDefaultDeltaFloor);
    o.delta_floor = 3.5f;
    EXPECT_EQ(load_input(o).octree.delta_floor, 3.5f);
}

TEST(Input, AVmapIsLoadedAndOctreeOverridesAreAnError) {
    test::ScratchDir dir;
    const VisibilityMap vm =
        build_vmap(test::sample(test::scene_path("cornell-bunny"), 300), test::cpu_params(4, 2));
    InputOptions o;
    o.path = dir.path("m.vmap");
    save_vmap(o.path, vm);
    const Input in = load_input(o);
    EXPECT_EQ(in.kind, InputKind::kVmap);
    ASSERT_TRUE(in.vmap);
    EXPECT_EQ(in.vmap->num_links(), vm.num_links());
    EXPECT_EQ(in.octree.max_height, 4);
    EXPECT_TRUE(in.points.positions.empty());
    o.max_height = 6;
    EXPECT_TRUE(throws_naming(o, "m.vmap: max_height, leaf_points, delta_floor and roughness"));
    o.max_height.reset();
    o.delta_floor = 2.0f;
    EXPECT_TRUE(throws_naming(o, "m.vmap: max_height, leaf_points, delta_floor and roughness"));
    o.delta_floor.reset();
    o.roughness = 0.001f;
    EXPECT_TRUE(throws_naming(o, "m.vmap: max_height, leaf_points, delta_floor and roughness"));
    o.roughness.reset();
    o.points = 10;
    EXPECT_TRUE(throws_naming(o, "not to a .vmap"));
}

}  // namespace
}  // namespace vmap
