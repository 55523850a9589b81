// Queries by position and ray shooting pruned by the V-map, against brute force.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "test_util.h"
#include "vmap/error.h"
#include "vmap/query.h"

namespace vmap {
namespace {

class RayQueryTest : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        vm_ = new VisibilityMap(
            build_vmap(test::sample(test::oracle_path("room-with-block.json"), 3000, 2),
                       test::cpu_params(7, 3)));
    }
    static void TearDownTestSuite() { delete vm_; }
    static Vec3 pos(uint32_t id) { return vm_->points().positions[vm_->inverse()[id]]; }
    static Vec3 normal(uint32_t id) { return vm_->points().normals[vm_->inverse()[id]]; }
    static VisibilityMap* vm_;
};
VisibilityMap* RayQueryTest::vm_ = nullptr;

// Random directions in the hemisphere of the point's normal (where its surface looks).
Vec3 random_dir(std::mt19937& rng, Vec3 n) {
    std::normal_distribution<float> g;
    Vec3 d{g(rng), g(rng), g(rng)};
    d = d / length(d);
    if (dot(d, n) < 0) d = -d;
    return d;
}

TEST_F(RayQueryTest, PrunedRayEqualsBruteForceOverTheVisibleSet) {
    std::mt19937 rng(11);
    std::uniform_int_distribution<uint32_t> pick(0, uint32_t(vm_->points().size() - 1));
    int hits = 0;
    for (int it = 0; it < 400; ++it) {
        const uint32_t i = pick(rng);
        const Vec3 d = random_dir(rng, normal(i));
        const RayHit a = shoot_ray(*vm_, i, d);
        const RayHit b = shoot_ray_brute(*vm_, i, d, /*visible_only=*/true);
        ASSERT_EQ(a.hit, b.hit) << i;
        if (!a.hit) continue;
        ++hits;
        ASSERT_EQ(a.distance, b.distance) << i;  // same disc test, same float result
        if (a.id != b.id) {
            ASSERT_EQ(a.distance, b.distance);  // a tie between two discs
        }
    }
    EXPECT_GT(hits, 250);  // the room is open at z = 0: some rays leave it
}

TEST_F(RayQueryTest, PrunedRayAgreesWithTheExhaustiveSearchWhereTheVMapSeesTheHit) {
    // The exhaustive nearest hit h over all points (but the origin's leaf): when h is in the
    // visible set, the pruned search (a subset holding h) must find h's distance exactly; when
    // it is not, the pruned hit can only be farther.
    std::mt19937 rng(12);
    std::uniform_int_distribution<uint32_t> pick(0, uint32_t(vm_->points().size() - 1));
    int agree = 0, farther = 0;
    for (int it = 0; it < 400; ++it) {
        const uint32_t i = pick(rng);
        const Vec3 d = random_dir(rng, normal(i));
        const RayHit all = shoot_ray_brute(*vm_, i, d, false);
        const RayHit pr = shoot_ray(*vm_, i, d);
        if (!all.hit) {
            ASSERT_FALSE(pr.hit);
            continue;
        }
        const PairVisibility v = vm_->query(i, all.id);
        if (v == PairVisibility::kVisible) {
            ASSERT_TRUE(pr.hit);
            ASSERT_EQ(pr.distance, all.distance) << i;
            ++agree;
        } else {
            ASSERT_TRUE(!pr.hit || pr.distance >= all.distance) << i;
            ++farther;
        }
    }
    EXPECT_GT(agree, 3 * farther) << "the V-map should see most first hits";
    EXPECT_GT(agree, 200);
    std::printf("first hits the V-map sees: %d, hidden to it: %d\n", agree, farther);
}

TEST_F(RayQueryTest, RayStraightUpFromTheFloorHitsTheCeilingOrTheLight) {
    // Floor points away from the block: the ray (0, 1, 0) meets the ceiling (y = H) or the
    // light just below it, about H away; a few may slip between the discs (scale 2 leaves ~2%
    // of a surface uncovered), none may hit anything else.
    const float H = 0.5488f;
    int tested = 0, hits = 0;
    for (uint32_t i = 0; i < vm_->points().size() && tested < 50; ++i) {
        const Vec3 p = pos(i);
        if (p.y != 0 || std::fabs(p.x - 0.2764f) < 0.15f || std::fabs(p.z - 0.28f) < 0.15f)
            continue;
        const RayHit h = shoot_ray(*vm_, i, {0, 1, 0});
        ++tested;
        if (!h.hit) continue;
        ++hits;
        EXPECT_NEAR(h.distance, H, 0.01f) << i;
        EXPECT_GT(pos(h.id).y, H * 0.99f) << i;
    }
    EXPECT_EQ(tested, 50);
    EXPECT_GE(hits, 45);
}

TEST_F(RayQueryTest, DirectionLengthDoesNotMatter) {
    // Only the direction counts: a length whose square over- or underflows a float is fine.
    int compared = 0;
    for (uint32_t i = 0; i < vm_->points().size() && compared < 20; i += 97) {
        const RayHit unit = shoot_ray(*vm_, i, {0.3f, 0.8f, 0.1f});
        for (const float s : {1e20f, 1e-23f}) {
            const RayHit h = shoot_ray(*vm_, i, {0.3f * s, 0.8f * s, 0.1f * s});
            ASSERT_EQ(h.hit, unit.hit) << i << " x" << s;
            if (h.hit) {
                EXPECT_EQ(h.id, unit.id) << i << " x" << s;
            }
        }
        compared += unit.hit;
    }
    EXPECT_GE(compared, 10);
}

TEST_F(RayQueryTest, NearestPointMatchesALinearScan) {
    std::mt19937 rng(13);
    std::uniform_real_distribution<float> u(-0.1f, 0.7f);
    for (int it = 0; it < 200; ++it) {
        const Vec3 q{u(rng), u(rng), u(rng)};
        const uint32_t k = nearest_point(*vm_, q);
        const float dk = length2(pos(k) - q);
        for (uint32_t j = 0; j < vm_->points().size(); ++j) ASSERT_LE(dk, length2(pos(j) - q));
    }
}

TEST_F(RayQueryTest, PairAndVisibleSetByPositionEqualTheirIdForms) {
    std::mt19937 rng(14);
    std::uniform_int_distribution<uint32_t> pick(0, uint32_t(vm_->points().size() - 1));
    for (int it = 0; it < 200; ++it) {
        const uint32_t i = pick(rng), j = pick(rng);
        // A position a hair off the surface point names that point.
        const Vec3 pi = pos(i) + normal(i) * 1e-5f, pj = pos(j) + normal(j) * 1e-5f;
        const uint32_t a = nearest_point(*vm_, pi), b = nearest_point(*vm_, pj);
        ASSERT_EQ(pos(a), pos(i));
        ASSERT_EQ(pos(b), pos(j));
        ASSERT_EQ(vm_->query(a, b), vm_->query(i, j));
        ASSERT_EQ(vm_->visible_set(a), vm_->visible_set(i));
        ASSERT_EQ(visible_count(*vm_, i), vm_->visible_set(i).size());
    }
}

TEST_F(RayQueryTest, BadQueriesAreErrors) {
    const uint32_t n = uint32_t(vm_->points().size());
    EXPECT_THROW(shoot_ray(*vm_, n, {0, 1, 0}), Error);
    EXPECT_THROW(shoot_ray(*vm_, 0, {0, 0, 0}), Error);
    EXPECT_THROW(shoot_ray(*vm_, 0, {std::nanf(""), 1, 0}), Error);
    EXPECT_THROW(shoot_ray_brute(*vm_, n, {0, 1, 0}, false), Error);
    EXPECT_THROW(nearest_point(*vm_, {INFINITY, 0, 0}), Error);
    EXPECT_THROW(nearest_point(PointSet{}, {0, 0, 0}), Error);
    EXPECT_THROW(visible_count(*vm_, n), Error);
}

}  // namespace
}  // namespace vmap
