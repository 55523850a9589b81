// Seeded area-weighted sampling of a scene (src/scene/sampling.cpp).
#include "scene_test_util.h"

namespace vmap {
namespace {

// ---- sampling ------------------------------------------------------------------------------

TEST(SceneSampling, TheSameSeedGivesIdenticalPoints) {
    Scene sc = load_scene(kScenes + "cornell-bunny.json");
    sc.points = 5000;
    expect_bits_equal(sample_scene(sc), sample_scene(sc));
    // A scene loaded anew samples the same too.
    Scene again = load_scene(kScenes + "cornell-bunny.json");
    again.points = 5000;
    expect_bits_equal(sample_scene(sc), sample_scene(again));
}

TEST(SceneSampling, ADifferentSeedGivesDifferentPoints) {
    Scene sc = load_scene(kScenes + "cornell-empty.json");
    sc.points = 2000;
    const PointSet a = sample_scene(sc);
    sc.seed = sc.seed + 1;
    const PointSet b = sample_scene(sc);
    ASSERT_EQ(a.size(), b.size());
    size_t same = 0;
    for (size_t i = 0; i < a.size(); ++i) same += a.positions[i] == b.positions[i];
    EXPECT_LT(same, a.size() / 100) << same << " of " << a.size() << " points unchanged";
}

TEST(SceneSampling, TheThreadCountDoesNotChangeThePoints) {
    Scene sc = load_scene(kScenes + "cornell-two-models.json");
    sc.points = 30000;
    PointSet one, two, all;
    {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
        one = sample_scene(sc);
    }
    {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
        two = sample_scene(sc);
    }
    all = sample_scene(sc);
    expect_bits_equal(one, two);
    expect_bits_equal(one, all);
}

TEST(SceneSampling, ThePointCountIsHonoured) {
    Scene sc = load_scene(kScenes + "cornell-empty.json");
    for (uint64_t n : {1ull, 2ull, 7ull, 1000ull, 12345ull}) {
        sc.points = n;
        const PointSet ps = sample_scene(sc);
        EXPECT_EQ(ps.size(), n);
        EXPECT_EQ(ps.normals.size(), n);
        EXPECT_EQ(ps.colors.size(), n);
        EXPECT_EQ(ps.radii.size(), n);
        EXPECT_EQ(ps.emission.size(), n);
    }
}

TEST(SceneSampling, RadiiShareTheTotalAreaEqually) {
    for (const char* name : {"cornell-empty", "cornell-bunny"}) {
        SCOPED_TRACE(name);
        Scene sc = load_scene(kScenes + std::string(name) + ".json");
        sc.points = 4000;
        const PointSet ps = sample_scene(sc);
        const double expected = std::sqrt(total_area(sc) / (M_PI * 4000.0));
        for (float r : ps.radii) ASSERT_NEAR(r, expected, 1e-6 * expected);
    }
}

TEST(SceneSampling, NormalsAreUnitLength) {
    Scene sc = load_scene(kScenes + "cornell-two-models.json");
    sc.points = 20000;
    const PointSet ps = sample_scene(sc);
    for (size_t i = 0; i < ps.size(); ++i)
        ASSERT_NEAR(length(ps.normals[i]), 1.0f, 1e-5f) << "point " << i;
}

TEST(SceneSampling, PointsLieOnTheirSurfaces) {
    Scene sc = load_scene(kScenes + "cornell-empty.json");
    sc.points = 20000;
    const PointSet ps = sample_scene(sc);
    const float light_y = find_surface(sc, "light")->mesh.vertices[0].y;
    const Vec3 white = find_surface(sc, "floor")->albedo;
    size_t counted[6] = {};
    for (size_t i = 0; i < ps.size(); ++i) {
        const Vec3 p = ps.positions[i], n = ps.normals[i];
        SCOPED_TRACE(::testing::Message()
                     << "point " << i << " at (" << p.x << ", " << p.y << ", " << p.z << ")");
        ASSERT_GE(p.x, 0.0f);
        ASSERT_LE(p.x, kW);
        ASSERT_GE(p.y, 0.0f);
        ASSERT_LE(p.y, kH);
        ASSERT_GE(p.z, 0.0f);
        ASSERT_LE(p.z, kD);
        const bool lit = !(ps.emission[i] == Vec3{0, 0, 0});
        if (lit) {  // the light
            ASSERT_NEAR(p.y, light_y, 1e-6f);
            ASSERT_LT(n.y, -0.999f);
            // The light's emission, scaled so that its points emit its power (a few percent).
            const float f = ps.emission[i].x / 17;
            ASSERT_NEAR(f, 1.0f, 0.2f);
            ASSERT_NEAR(ps.emission[i].y, 12 * f, 1e-5f);
            ASSERT_NEAR(ps.emission[i].z, 4 * f, 1e-5f);
            ASSERT_NEAR(p.x, 0.2764f, 0.065f + 1e-6f);
            ASSERT_NEAR(p.z, 0.2796f, 0.0525f + 1e-6f);
            counted[5]++;
        } else if (n.y > 0.999f) {  // floor
            ASSERT_EQ(p.y, 0.0f);
            ASSERT_EQ(ps.colors[i], white);
            counted[0]++;
        } else if (n.y < -0.999f) {  // ceiling
            ASSERT_NEAR(p.y, kH, 1e-6f);
            ASSERT_EQ(ps.colors[i], white);
            counted[1]++;
        } else if (n.z < -0.999f) {  // back
            ASSERT_NEAR(p.z, kD, 1e-6f);
            ASSERT_EQ(ps.colors[i], white);
            counted[2]++;
        } else if (n.x < -0.999f) {  // left, red, at x = width
            ASSERT_NEAR(p.x, kW, 1e-6f);
            ASSERT_EQ(ps.colors[i], find_surface(sc, "left")->albedo);
            counted[3]++;
        } else if (n.x > 0.999f) {  // right, green, at x = 0
            ASSERT_NEAR(p.x, 0.0f, 1e-6f);
            ASSERT_EQ(ps.colors[i], find_surface(sc, "right")->albedo);
            counted[4]++;
        } else {
            FAIL() << "normal (" << n.x << ", " << n.y << ", " << n.z << ") fits no wall";
        }
    }
    for (size_t k = 0; k < 6; ++k) EXPECT_GT(counted[k], 0u) << "surface " << k;
}

TEST(SceneSampling, PointsAreSpreadByArea) {
    Scene sc = load_scene(kScenes + "cornell-empty.json");
    const uint64_t n = 20000;
    sc.points = n;
    const PointSet ps = sample_scene(sc);
    const double total = total_area(sc);
    auto check = [&](const char* name, const std::function<bool(size_t)>& on) {
        SCOPED_TRACE(name);
        const double p = surface_area(*find_surface(sc, name)) / total;
        const double sigma = std::sqrt(p * (1 - p) / double(n));
        size_t k = 0;
        for (size_t i = 0; i < ps.size(); ++i) k += on(i);
        EXPECT_NEAR(double(k) / double(n), p, 4 * sigma) << k << " points";
    };
    check("floor", [&](size_t i) { return ps.normals[i].y > 0.999f; });
    check("left", [&](size_t i) { return ps.normals[i].x < -0.999f; });
    check("light", [&](size_t i) { return !(ps.emission[i] == Vec3{0, 0, 0}); });

    // Within the floor, the two halves (x < W/2 and x >= W/2) get about the same share.
    size_t floor = 0, half = 0;
    for (size_t i = 0; i < ps.size(); ++i) {
        if (ps.normals[i].y > 0.999f) {
            ++floor;
            half += ps.positions[i].x < kW / 2;
        }
    }
    EXPECT_NEAR(double(half) / double(floor), 0.5, 4 * std::sqrt(0.25 / double(floor)));
}

TEST(SceneSampling, DensityGivesCeilOfDensityTimesArea) {
    const Scene sc = load_scene(kFixtures + "density.json");
    const double area = total_area(sc);
    EXPECT_EQ(sc.points, uint64_t(std::ceil(1000.0 * area)));
    EXPECT_EQ(sc.seed, 3u);
    EXPECT_EQ(sample_scene(sc).size(), sc.points);
}

TEST(SceneSampling, DensityCountsMeshAreaToo) {
    ScratchDir dir;
    const std::string tetra = fs::absolute(kFixtures + "tetra_inside_out.off").string();
    const std::string path = dir.write(
        "density_mesh.json", R"({ "meshes": [ { "file": ")" + tetra +
                                 R"(", "size": 0.3 } ], "sampling": { "density": 2500 } })");
    const Scene sc = load_scene(path);
    ASSERT_EQ(sc.surfaces.size(), 7u);
    EXPECT_EQ(sc.points, uint64_t(std::ceil(2500.0 * total_area(sc))));
    EXPECT_GT(double(sc.points), 2500.0 * (total_area(sc) - surface_area(sc.surfaces[6])) + 10);
}


// ---- blue noise (sample elimination) --------------------------------------------------------

// The share of points whose nearest neighbour on the same side of a surface (normals less than
// 90 degrees apart) lies closer than `frac` splat radii.
double crowded_share(const PointSet& ps, float frac) {
    const float lim = frac * ps.radii[0];
    size_t crowded = 0;
    for (size_t i = 0; i < ps.size(); ++i) {
        float best = 1e30f;
        for (size_t j = 0; j < ps.size(); ++j)
            if (j != i && dot(ps.normals[i], ps.normals[j]) > 0)
                best = std::min(best, length(ps.positions[j] - ps.positions[i]));
        crowded += best < lim;
    }
    return double(crowded) / double(ps.size());
}

TEST(SceneSampling, BlueNoiseKeepsSamplesApartUniformDoesNot) {
    Scene sc = load_scene(kScenes + "cornell-empty.json");
    sc.points = 3000;
    ASSERT_EQ(sc.pattern, SamplePattern::kBlueNoise);  // the default
    const double blue = crowded_share(sample_scene(sc), 0.6f);
    sc.pattern = SamplePattern::kUniform;
    const double uniform = crowded_share(sample_scene(sc), 0.6f);
    // Independent points: P(nearest < 0.6 r) = 1 - exp(-0.36) = 30%.
    EXPECT_GT(uniform, 0.2) << uniform;
    EXPECT_LT(blue, 0.01) << blue;
}

// Every surface keeps its share of the area, the two faces of a 3 mm plate included: the
// elimination thins each side on its own.
TEST(SceneSampling, BlueNoiseKeepsEverySurfacesShare) {
    Scene sc = load_scene(kScenes + "test/test-plates.json");
    sc.points = 20000;
    std::vector<uint32_t> surf;
    const PointSet ps = sample_scene(sc, &surf);
    ASSERT_EQ(surf.size(), ps.size());
    const double total = total_area(sc);
    std::vector<size_t> count(sc.surfaces.size(), 0);
    for (uint32_t s : surf) count[s]++;
    for (size_t s = 0; s < sc.surfaces.size(); ++s) {
        SCOPED_TRACE(sc.surfaces[s].name);
        const double p = surface_area(sc.surfaces[s]) / total;
        const double sigma = std::sqrt(p * (1 - p) / double(ps.size()));
        EXPECT_NEAR(double(count[s]) / double(ps.size()), p, std::max(4 * sigma, 0.03 * p))
            << count[s] << " points";
    }
}

TEST(SceneSampling, UniformAndBlueNoiseAreBothDeterministic) {
    Scene sc = load_scene(kScenes + "cornell-bunny.json");
    sc.points = 4000;
    for (SamplePattern p : {SamplePattern::kUniform, SamplePattern::kBlueNoise}) {
        sc.pattern = p;
        PointSet one;
        {
            tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
            one = sample_scene(sc);
        }
        expect_bits_equal(one, sample_scene(sc));
    }
}

TEST(SceneSampling, ThePatternAndTheFloorComeFromTheFile) {
    ScratchDir dir;
    auto scene = [&](const std::string& sampling, const std::string& octree) {
        return load_scene(dir.write("s.json", R"({ "sampling": { "points": 100)" + sampling +
                                                  R"( } )" + octree + "}"));
    };
    const Scene blue = scene("", "");
    EXPECT_EQ(blue.pattern, SamplePattern::kBlueNoise);
    EXPECT_EQ(scene_octree(blue).delta_floor, OctreeParams::kEvenDeltaFloor);
    const Scene uni = scene(R"(, "pattern": "uniform")", "");
    EXPECT_EQ(uni.pattern, SamplePattern::kUniform);
    EXPECT_EQ(scene_octree(uni).delta_floor, OctreeParams::kDefaultDeltaFloor);
    const Scene given = scene("", R"(, "octree": { "delta_floor": 3, "max_height": 6 })");
    EXPECT_EQ(scene_octree(given).delta_floor, 3.0f);
    EXPECT_EQ(scene_octree(given).max_height, 6);
    expect_error([&] { (void)scene(R"(, "pattern": "poisson")", ""); },
                 {"sampling.pattern", "poisson", "blue-noise"});
    expect_error([&] { (void)scene("", R"(, "octree": { "delta_floor": 11 })"); },
                 {"octree.delta_floor"});
}

}  // namespace
}  // namespace vmap
