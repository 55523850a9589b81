// The leaf-pair predicate (paper §5; docs/design.md "Leaf-pair visibility").
#include <gtest/gtest.h>

#include <random>

#include "octree/records.h"
#include "test_util.h"
#include "visibility/leaf_pair.h"

namespace vmap {
namespace {

using detail::is_actual_occluder;
using detail::leaf_pair_visible;
using detail::segment_meets_sphere;

TEST(SegmentSphere, AgreesWithDenseSamplingOfTheSegment) {
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(-1, 1);
    int hits = 0, misses = 0;
    for (int it = 0; it < 20000; ++it) {
        const Vec3 p{u(rng), u(rng), u(rng)}, q{u(rng), u(rng), u(rng)};
        const Sphere s{{u(rng), u(rng), u(rng)}, 0.3f * (u(rng) + 1)};
        const Vec3 d = q - p;
        // Distance from the centre to the segment, in double, by a fine search and refinement.
        double best = 1e30;
        for (int k = 0; k <= 2000; ++k) {
            const double t = k / 2000.0;
            const double x = p.x + t * d.x - s.center.x, y = p.y + t * d.y - s.center.y,
                         z = p.z + t * d.z - s.center.z;
            best = std::min(best, std::sqrt(x * x + y * y + z * z));
        }
        const bool got = segment_meets_sphere(p, d, length2(d), s);
        // Skip razor-thin cases the sampling cannot settle.
        if (std::fabs(best - s.radius) < 2e-3) continue;
        EXPECT_EQ(got, best < s.radius) << it;
        (got ? hits : misses)++;
    }
    EXPECT_GT(hits, 1000);
    EXPECT_GT(misses, 1000);
}

// Fig. 7 of the paper: p = origin, q = (1, 0, 0).
struct Fig7 : ::testing::Test {
    VisibilityParams vp;
    Vec3 p{0, 0, 0}, d{1, 0, 0};
    LeafDisc disc(Vec3 c, Vec3 n, float delta) {
        LeafDisc x;
        x.centroid = c;
        x.normal = n / length(n);
        x.delta = delta;
        return x;
    }
};

TEST_F(Fig7, PlaneCuttingTheSegmentNearItsCentroidOccludes) {
    EXPECT_TRUE(is_actual_occluder(p, d, 1, disc({0.5f, 0.05f, 0}, {1, 0.2f, 0}, 0.1f), vp));
}
TEST_F(Fig7, PlaneCutOutsideTheSegmentIsRejected) {  // x1
    EXPECT_FALSE(is_actual_occluder(p, d, 1, disc({1.3f, 0, 0}, {1, 0, 0}, 0.5f), vp));
    EXPECT_FALSE(is_actual_occluder(p, d, 1, disc({-0.2f, 0, 0}, {1, 0, 0}, 0.5f), vp));
}
TEST_F(Fig7, CrossingFartherThanDeltaIsRejected) {  // x4
    EXPECT_FALSE(is_actual_occluder(p, d, 1, disc({0.5f, 0.3f, 0}, {1, 0, 0}, 0.2f), vp));
    EXPECT_TRUE(is_actual_occluder(p, d, 1, disc({0.5f, 0.3f, 0}, {1, 0, 0}, 0.31f), vp));
}
TEST_F(Fig7, PlaneParallelToTheSegmentIsRejected) {  // x5
    EXPECT_FALSE(is_actual_occluder(p, d, 1, disc({0.5f, 0.01f, 0}, {0, 1, 0}, 0.5f), vp));
}
TEST_F(Fig7, CrossingAtTheEndpointsIsNotAnOcclusion) {
    // Neighbours on the same surface as p: their plane passes through p (t = 0 < eps).
    EXPECT_FALSE(is_actual_occluder(p, d, 1, disc({0, 0.02f, 0}, {1, 0, 0}, 0.1f), vp));
    EXPECT_FALSE(is_actual_occluder(p, d, 1, disc({1, 0.02f, 0}, {1, 0, 0}, 0.1f), vp));
}
TEST_F(Fig7, LeafWithoutAPlaneOccludesWithinItsSphere) {
    LeafDisc x = disc({0.5f, 0.05f, 0}, {1, 0, 0}, 0.1f);
    x.flags = kLeafNormalDegenerate;
    x.normal = {0, 0, 0};
    EXPECT_TRUE(is_actual_occluder(p, d, 1, x, vp));
    x.centroid.y = 0.2f;
    EXPECT_FALSE(is_actual_occluder(p, d, 1, x, vp));
}

// A convex neighbour of end a: its centroid just behind a's tangent plane, its disc tilted so it
// reaches into the segment's first stretch. It cuts the segment as a disc, but no surface
// wholly behind a's plane can lie on a segment in front of it.
struct EndPlanes : ::testing::Test {
    VisibilityParams vp;
    LeafDisc a, b;
    Vec3 d;
    LeafDisc disc(Vec3 c, Vec3 n, float delta) {
        LeafDisc x;
        x.centroid = c;
        x.normal = n / length(n);
        x.delta = delta;
        return x;
    }
    void SetUp() override {
        a = disc({0, 0, 0}, {0, 1, 0}, 0.05f);
        b = disc({1, 0.1f, 0}, {-1, 0, 0}, 0.05f);
        d = b.centroid - a.centroid;
        ASSERT_TRUE(detail::leaves_face(a, b, d, length(d), vp));
    }
    bool counts(const LeafDisc& x) {
        return detail::counts_as_occluder(detail::pair_segment(a, b, vp), x, vp);
    }
};

TEST_F(EndPlanes, NeighbourBehindAnEndsTangentPlaneDoesNotCount) {
    const LeafDisc x = disc({0.1f, -0.004f, 0}, {-0.3f, 1, 0}, 0.08f);
    EXPECT_TRUE(is_actual_occluder(a.centroid, d, length(d), x, vp));  // as a disc, it cuts
    EXPECT_FALSE(counts(x));
}
TEST_F(EndPlanes, SurfaceInFrontOfBothEndsCounts) {
    const LeafDisc x = disc({0.1f, 0.004f, 0}, {-0.3f, 1, 0}, 0.08f);
    EXPECT_TRUE(is_actual_occluder(a.centroid, d, length(d), x, vp));
    EXPECT_TRUE(counts(x));
}
TEST_F(EndPlanes, BehindTheFarEndsPlaneDoesNotCountEither) {
    // Just behind b's plane (x > 1), tilted toward the segment's last stretch.
    const LeafDisc x = disc({1.004f, 0.08f, 0}, {1, 3, 0}, 0.08f);
    EXPECT_TRUE(is_actual_occluder(a.centroid, d, length(d), x, vp));
    EXPECT_FALSE(counts(x));
}
TEST_F(EndPlanes, AnEndWithoutANormalCullsNothing) {
    const LeafDisc x = disc({0.1f, -0.004f, 0}, {-0.3f, 1, 0}, 0.08f);
    a.flags = kLeafNormalDegenerate;
    a.normal = {0, 0, 0};
    EXPECT_TRUE(counts(x));
}

// The near-end exit rule (exits_at_an_end): a leaf whose plane the segment cuts within half
// the end's disc radius of that end, coming out of it (the end behind its plane), is the end's
// own surface; one the segment goes into, or one cut farther out, still counts. a sits at the
// origin with Delta 0.05 (half: 0.025) and the segment leaves along d = (1, 0.1, 0).
TEST_F(EndPlanes, CrossedFromBehindRightAtAnEndDoesNotCount) {
    // Centroid in front of a's plane (y > 0), a behind its plane: n . (a - c) < 0. Its plane
    // cuts the segment at about 0.012 from a, inside the disc.
    const LeafDisc x = disc({0.02f, 0.004f, 0}, {1, -0.3f, 0}, 0.05f);
    ASSERT_TRUE(detail::in_front_of_ends(detail::pair_segment(a, b, vp), x));
    ASSERT_LT(dot(x.normal, a.centroid - x.centroid), 0.f);
    EXPECT_TRUE(is_actual_occluder(a.centroid, d, length(d), x, vp));
    EXPECT_FALSE(counts(x));
    // The same leaf facing the other way: the segment goes into it, so it counts.
    LeafDisc in = x;
    in.normal = -x.normal;
    EXPECT_TRUE(counts(in));
}
TEST_F(EndPlanes, CrossedFromBehindFartherOutCounts) {
    // The same geometry moved out to about 0.05 from a: more than half of a's Delta (0.025).
    const LeafDisc x = disc({0.06f, 0.01f, 0}, {1, -0.3f, 0}, 0.05f);
    ASSERT_LT(dot(x.normal, a.centroid - x.centroid), 0.f);
    EXPECT_TRUE(counts(x));
    // A larger end disc reaches it: now it is the end's own surface.
    a.delta = 0.2f;
    EXPECT_FALSE(counts(x));
}
TEST_F(EndPlanes, TheExitRuleAppliesAtTheFarEndToo) {
    // Near b (centroid (1, 0.1, 0), normal -x): a leaf just in front of b's plane with b
    // behind its own plane, cut about 0.02 from b (b's Delta 0.05).
    const LeafDisc x = disc({0.98f, 0.1f, 0.f}, {-1, 0.2f, 0}, 0.05f);
    const detail::PairSegment s = detail::pair_segment(a, b, vp);
    ASSERT_TRUE(detail::in_front_of_ends(s, x));
    ASSERT_LT(dot(x.normal, b.centroid - x.centroid), 0.f);
    EXPECT_TRUE(is_actual_occluder(a.centroid, d, length(d), x, vp));
    EXPECT_FALSE(counts(x));
    b.flags = kLeafNormalDegenerate;  // an end without a plane drops nothing
    b.normal = {0, 0, 0};
    EXPECT_TRUE(counts(x));
}

TEST(Facing, BothNormalsMustFaceTheOther) {
    VisibilityParams vp;
    LeafDisc a, b;
    a.normal = {0, 1, 0};
    b.normal = {0, -1, 0};
    const Vec3 d{0, 1, 0};
    EXPECT_TRUE(detail::leaves_face(a, b, d, 1, vp));
    b.normal = {0, 1, 0};
    EXPECT_FALSE(detail::leaves_face(a, b, d, 1, vp));
    // Coplanar leaves (d in the tangent plane) do not face each other.
    b.normal = {0, 1, 0};
    EXPECT_FALSE(detail::leaves_face(a, b, {1, 0, 0}, 1, vp));
}

// The traversal (sphere pruning, early exit at K) against testing every leaf.
bool visible_without_pruning(const OctreeView& t, int32_t a, int32_t b,
                             const VisibilityParams& vp) {
    const LeafDisc la = t.leaves[a], lb = t.leaves[b];
    const Vec3 d = lb.centroid - la.centroid;
    const float len = sqrtf(length2(d));
    if (!(len > 0.f) || !detail::leaves_face(la, lb, d, len, vp)) return false;
    int occ = 0;
    for (int32_t l = 0; l < t.num_leaves; ++l)
        if (l != a && l != b &&
            detail::counts_as_occluder(detail::pair_segment(la, lb, vp), t.leaves[l], vp))
            ++occ;
    return occ < vp.K;
}

class TraversalOracle : public ::testing::TestWithParam<std::tuple<const char*, int, int>> {};

TEST_P(TraversalOracle, SpherePruningNeverDropsAnOccluder) {
    const auto [scene, height, k] = GetParam();
    PointSet ps = test::sample(test::scene_path(scene), 3000, 5);
    std::vector<uint32_t> order;
    Octree t = Octree::build(ps, {height, 3}, order);
    VisibilityParams vp;
    vp.K = k;
    const OctreeView v = octree_view(t);
    std::mt19937 rng(9);
    std::uniform_int_distribution<int32_t> pick(0, v.num_leaves - 1);
    int visible = 0, hidden = 0;
    for (int it = 0; it < 4000; ++it) {
        int32_t a = pick(rng), b = pick(rng);
        if (a == b) continue;
        if (a > b) std::swap(a, b);
        const bool got = leaf_pair_visible<false>(v, a, b, vp, static_cast<WorkCounters*>(nullptr));
        ASSERT_EQ(got, visible_without_pruning(v, a, b, vp)) << a << " " << b;
        (got ? visible : hidden)++;
    }
    EXPECT_GT(visible, 100);
    EXPECT_GT(hidden, 100);
}

INSTANTIATE_TEST_SUITE_P(Scenes, TraversalOracle,
                         ::testing::Values(std::make_tuple("cornell-bunny", 6, 1),
                                           std::make_tuple("cornell-bunny", 8, 2),
                                           std::make_tuple("cornell-two-models", 7, 3)));

TEST(Counting, CountedAndUncountedPredicatesAgree) {
    PointSet ps = test::sample(test::scene_path("cornell-bunny"), 2000, 2);
    std::vector<uint32_t> order;
    Octree t = Octree::build(ps, {7, 4}, order);
    const OctreeView v = octree_view(t);
    VisibilityParams vp;
    WorkCounters wc;
    for (int32_t a = 0; a < 50; ++a)
        for (int32_t b = a + 1; b < v.num_leaves; b += 7)
            ASSERT_EQ(leaf_pair_visible<true>(v, a, b, vp, &wc),
                      leaf_pair_visible<false>(v, a, b, vp, static_cast<WorkCounters*>(nullptr)));
    EXPECT_GT(wc.node_tests, wc.facing_pairs);
}

}  // namespace
}  // namespace vmap
