// Seeded area-weighted sampling of a scene (src/scene/sampling.cpp).
#include <tbb/task_arena.h>

#include <numeric>
#include <random>
#include <set>

#include "scene/elimination.h"
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

// ---- the elimination against a serial oracle --------------------------------------------------

// The rule of detail::eliminate done the plain way, one candidate at a time: W of a slot is the
// sum, in list order and in double, of the weights of its list's present members; the present
// slot of largest (W, id) goes, and every present slot whose list holds it is summed again.
std::vector<uint64_t> serial_elimination(const detail::NeighbourLists& L, uint64_t keep) {
    const uint64_t M = L.size();
    std::vector<std::vector<uint32_t>> listed_by(M);
    for (uint64_t j = 0; j < M; ++j)
        for (uint64_t e = L.start[j]; e < L.start[j + 1]; ++e) listed_by[L.nb[e]].push_back(j);
    std::vector<uint8_t> gone(M, 0);
    auto crowding = [&](uint64_t i) {
        double sum = 0;
        for (uint64_t e = L.start[i]; e < L.start[i + 1]; ++e)
            if (!gone[L.nb[e]]) sum += L.weight[e];
        return sum;
    };
    std::vector<double> W(M);
    std::vector<uint32_t> slot_of(M);
    std::set<std::pair<double, uint32_t>> by_key;  // (W, id)
    for (uint64_t i = 0; i < M; ++i) {
        W[i] = crowding(i);
        slot_of[L.id[i]] = uint32_t(i);
        by_key.insert({W[i], L.id[i]});
    }
    while (by_key.size() > keep) {
        const uint32_t i = slot_of[std::prev(by_key.end())->second];
        by_key.erase(std::prev(by_key.end()));
        gone[i] = 1;
        for (uint32_t j : listed_by[i]) {
            if (gone[j]) continue;
            by_key.erase({W[j], L.id[j]});
            W[j] = crowding(j);
            by_key.insert({W[j], L.id[j]});
        }
    }
    std::vector<uint64_t> kept;
    for (const auto& [w, id] : by_key) kept.push_back(id);
    std::sort(kept.begin(), kept.end());
    return kept;
}

// detail::eliminate in an arena of `threads` threads.
std::vector<uint64_t> eliminate_with(const detail::NeighbourLists& L, uint64_t keep, int threads) {
    tbb::task_arena arena(threads);
    std::vector<uint64_t> kept;
    arena.execute([&] { kept = detail::eliminate(L, keep); });
    return kept;
}

// How many of `want` a differs in (either way), for the failure message.
size_t differ(const std::vector<uint64_t>& a, const std::vector<uint64_t>& want) {
    std::vector<uint64_t> d;
    std::set_symmetric_difference(a.begin(), a.end(), want.begin(), want.end(),
                                  std::back_inserter(d));
    return d.size();
}

void expect_oracle_result(const detail::NeighbourLists& L, const std::string& what) {
    const uint64_t M = L.size();
    for (uint64_t keep : {M / 4, M / 2, M - M / 20, M - 3, uint64_t(1)}) {
        SCOPED_TRACE(what + ", keep " + std::to_string(keep) + " of " + std::to_string(M));
        const std::vector<uint64_t> want = serial_elimination(L, keep);
        ASSERT_EQ(want.size(), keep);
        for (int threads : {1, 2, 4}) {
            const std::vector<uint64_t> got = eliminate_with(L, keep, threads);
            ASSERT_EQ(got.size(), keep) << threads << " threads";
            ASSERT_TRUE(got == want) << threads << " threads: " << differ(got, want)
                                     << " candidates differ from the serial greedy";
        }
    }
}

// Points on planes, a sphere, two sheets 0.1 reach apart facing away from each other,
// clusters of duplicates (exact ties in W, lists saturated at 32, one-sided lists) and a
// lattice (exact distance ties); their lists from detail::same_side_neighbours as the sampler
// builds them.
TEST(SampleElimination, EqualsTheSerialGreedyOnPointSets) {
    for (uint64_t seed = 1; seed <= 6; ++seed) {
        std::mt19937_64 rng(seed);
        std::uniform_real_distribution<float> u(0, 1);
        const Vec3 up{0, 0, 1}, down{0, 0, -1};
        for (int shape = 0; shape < 5; ++shape) {
            const uint64_t M = 1500 + rng() % 2500;
            std::vector<Vec3> pos, nrm;
            for (uint64_t i = 0; i < M; ++i) {
                Vec3 p, n;
                if (shape == 0) {  // a square
                    p = {u(rng), u(rng), 0};
                    n = up;
                } else if (shape == 1) {  // a unit sphere, normals outward
                    Vec3 d;
                    do d = {2 * u(rng) - 1, 2 * u(rng) - 1, 2 * u(rng) - 1};
                    while (!(length(d) > 0.1f && length(d) <= 1));
                    n = d / length(d);
                    p = n;
                } else if (shape == 2) {  // two sheets, facing away
                    const bool top = rng() & 1;
                    p = {u(rng), u(rng), top ? 0.005f : 0.0f};
                    n = top ? up : down;
                } else if (shape == 3) {  // clusters: duplicates and tight jitter, and a plane
                    const uint64_t c = rng() % 12;
                    const Vec3 centre{float(c % 4) * 0.3f, float(c / 4) * 0.3f, 0};
                    const uint64_t kind = rng() % 3;
                    p = kind == 0   ? centre
                        : kind == 1 ? centre + Vec3{0.002f * u(rng), 0.002f * u(rng), 0}
                                    : Vec3{u(rng), u(rng), 0};
                    n = up;
                } else {  // a lattice with some points doubled
                    const uint64_t k = rng() % 900;
                    p = {float(k % 30) / 30, float(k / 30) / 30, 0};
                    n = (rng() % 8) ? up : down;
                }
                pos.push_back(p);
                nrm.push_back(n);
            }
            const double reach = shape == 1 ? 0.25 : shape == 4 ? 0.1 : 0.08;
            const double floor_d = (shape == 3 ? 0.3 : 0.6) * reach / 2;
            const detail::NeighbourLists L = detail::same_side_neighbours(pos, nrm, reach, floor_d);
            ASSERT_EQ(L.size(), M);
            if (shape == 3) {
                uint64_t full = 0;
                for (uint64_t i = 0; i < M; ++i)
                    full += L.start[i + 1] - L.start[i] == detail::NeighbourLists::kMax;
                ASSERT_GT(full, M / 4) << "the clusters fill their lists";
            }
            expect_oracle_result(
                L, "seed " + std::to_string(seed) + ", shape " + std::to_string(shape));
        }
    }
}

// Random lists: one-sided, of any length up to 32, with weights from a few values (many exact
// ties in W, broken by id) and candidate indices in random slots.
TEST(SampleElimination, EqualsTheSerialGreedyOnRandomLists) {
    for (uint64_t seed = 1; seed <= 40; ++seed) {
        std::mt19937_64 rng(seed);
        const uint64_t M = 50 + rng() % 3000;
        const uint64_t span = 2 + rng() % 60;  // neighbours among the `span` slots around
        detail::NeighbourLists L;
        L.id.resize(M);
        std::iota(L.id.begin(), L.id.end(), 0u);
        std::shuffle(L.id.begin(), L.id.end(), rng);
        L.start.assign(1, 0);
        const float values[] = {0.0f, 0.125f, 0.25f, 0.5f, 1.0f, 0.3f};
        const int distinct = 2 + int(rng() % 5);
        for (uint64_t i = 0; i < M; ++i) {
            std::vector<uint32_t> nb;
            const int want = int(rng() % (detail::NeighbourLists::kMax + 1));
            for (int tries = 0; tries < 4 * want && int(nb.size()) < want; ++tries) {
                const uint64_t j = (i + M + rng() % (2 * span + 1) - span) % M;
                if (j != i && std::find(nb.begin(), nb.end(), uint32_t(j)) == nb.end())
                    nb.push_back(uint32_t(j));
            }
            for (uint32_t j : nb) {
                L.nb.push_back(j);
                L.weight.push_back(values[rng() % distinct]);
            }
            L.start.push_back(L.nb.size());
        }
        expect_oracle_result(L, "seed " + std::to_string(seed));
    }
}

// Large enough (over 65,536 present candidates) that each phase's threshold is found by
// histograms of W's bits before nth_element (Eliminator::rank_above): weights from a few values
// (whole digits alike, ties broken by id) and from a continuum.
TEST(SampleElimination, EqualsTheSerialGreedyWhereTheThresholdIsFoundByDigits) {
    for (uint64_t seed = 1; seed <= 2; ++seed) {
        std::mt19937_64 rng(seed);
        const uint64_t M = 150000;
        detail::NeighbourLists L;
        L.id.resize(M);
        std::iota(L.id.begin(), L.id.end(), 0u);
        std::shuffle(L.id.begin(), L.id.end(), rng);
        L.start.assign(1, 0);
        std::uniform_real_distribution<float> u(0, 1);
        const float values[] = {0.125f, 0.25f, 0.5f};
        for (uint64_t i = 0; i < M; ++i) {
            const int want = 4 + int(rng() % 20);
            for (int k = 0; k < want; ++k) {
                const uint64_t j = (i + 1 + rng() % 40) % M;
                if (std::find(L.nb.begin() + int64_t(L.start.back()), L.nb.end(), uint32_t(j)) !=
                    L.nb.end())
                    continue;
                L.nb.push_back(uint32_t(j));
                L.weight.push_back(seed == 1 ? values[rng() % 3] : u(rng));
            }
            L.start.push_back(L.nb.size());
        }
        for (uint64_t keep : {M / 4, M - M / 3}) {
            SCOPED_TRACE("seed " + std::to_string(seed) + ", keep " + std::to_string(keep));
            const std::vector<uint64_t> want = serial_elimination(L, keep);
            for (int threads : {1, 4}) {
                const std::vector<uint64_t> got = eliminate_with(L, keep, threads);
                ASSERT_TRUE(got == want) << threads << " threads: " << differ(got, want)
                                         << " candidates differ from the serial greedy";
            }
        }
    }
}

TEST(SampleElimination, KeepsAllOrNone) {
    detail::NeighbourLists L;
    L.id = {2, 0, 1};
    L.start = {0, 1, 2, 3};
    L.nb = {1, 2, 0};
    L.weight = {0.5f, 0.5f, 0.5f};
    EXPECT_EQ(detail::eliminate(L, 3), (std::vector<uint64_t>{0, 1, 2}));
    EXPECT_EQ(detail::eliminate(L, 5), (std::vector<uint64_t>{0, 1, 2}));
    EXPECT_TRUE(detail::eliminate(L, 0).empty());
    // All W equal at first: ties go to the larger id.
    EXPECT_EQ(detail::eliminate(L, 2), serial_elimination(L, 2));
    EXPECT_EQ(detail::eliminate(L, 1), serial_elimination(L, 1));
}

// The sampler reports the elimination as a stage (its size first) and stops when asked to.
TEST(SceneSampling, BlueNoiseReportsProgressAndCancels) {
    Scene sc = load_scene(kScenes + "cornell-empty.json");
    sc.points = 3000;
    std::vector<ProgressInfo> seen;
    const ProgressCallback record = [&](const ProgressInfo& p) {
        seen.push_back(p);
        return true;
    };
    const PointSet with = sample_scene(sc, nullptr, record);
    ASSERT_GE(seen.size(), 2u);
    EXPECT_STREQ(seen.front().stage, "sampling (candidates removed)");
    EXPECT_EQ(seen.front().done, 0u);
    EXPECT_EQ(seen.front().total, 3 * sc.points);  // 4 candidates a sample
    EXPECT_EQ(seen.back().done, seen.back().total);
    expect_bits_equal(with, sample_scene(sc));
    const ProgressCallback stop = [](const ProgressInfo&) { return false; };
    EXPECT_THROW((void)sample_scene(sc, nullptr, stop), Cancelled);
    sc.pattern = SamplePattern::kUniform;
    seen.clear();
    (void)sample_scene(sc, nullptr, record);
    EXPECT_TRUE(seen.empty()) << "uniform samples have no stage";
}

TEST(SceneSampling, ThePatternAndTheFloorComeFromTheFile) {
    ScratchDir dir;
    auto scene = [&](const std::string& sampling, const std::string& octree) {
        return load_scene(dir.write(
            "s.json", R"({ "sampling": { "points": 100)" + sampling + R"( } )" + octree + "}"));
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
