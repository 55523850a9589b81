// The adaptive octree: structure, statistics and bounds (docs/design.md "Octree").
#include "octree/records.h"
#include "vmap/octree.h"

#include <gtest/gtest.h>

#include <limits>

#include <cmath>
#include <numeric>
#include <random>
#include <set>

#include "octree/delta_rule.h"
#include "test_util.h"
#include "vmap/error.h"

namespace vmap {
namespace {

PointSet random_cloud(size_t n, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1, 1);
    PointSet ps;
    for (size_t i = 0; i < n; ++i) {
        ps.positions.push_back({u(rng), u(rng), u(rng)});
        Vec3 nr{u(rng), u(rng), u(rng)};
        if (length(nr) < 0.1f) nr = {0, 0, 1};
        ps.normals.push_back(nr / length(nr));
        ps.radii.push_back(0.01f);
    }
    return ps;
}

void check_structure(const Octree& t, const PointSet& ps, const OctreeParams& p) {
    const int32_t nn = t.num_nodes();
    ASSERT_GT(nn, 0);
    EXPECT_EQ(t.parent()[0], -1);
    EXPECT_EQ(t.skip()[0], nn);
    EXPECT_EQ(t.point_begin()[0], 0u);
    EXPECT_EQ(t.point_end()[0], ps.size());
    int32_t leaves = 0;
    for (int32_t n = 0; n < nn; ++n) {
        ASSERT_GT(t.skip()[n], n);
        ASSERT_LE(t.skip()[n], nn);
        const uint32_t cnt = t.point_end()[n] - t.point_begin()[n];
        EXPECT_GT(cnt, 0u) << "empty nodes are not stored";
        EXPECT_LE(t.level()[n], p.max_height);
        if (t.is_leaf(n)) {
            EXPECT_EQ(t.skip()[n], n + 1);
            EXPECT_EQ(t.node_leaf()[n], leaves) << "leaves numbered in depth-first order";
            EXPECT_EQ(t.leaf_begin()[n], leaves);
            EXPECT_EQ(t.leaf_end()[n], leaves + 1);
            ++leaves;
            // A leaf either is small enough or sits at max height.
            EXPECT_TRUE(cnt <= uint32_t(p.leaf_points) || t.level()[n] == p.max_height);
        } else {
            EXPECT_GT(cnt, uint32_t(p.leaf_points)) << "a node splits only when over leaf_points";
            EXPECT_LT(t.level()[n], p.max_height);
            // Children tile the parent's point and leaf ranges in order.
            uint32_t pb = t.point_begin()[n];
            int32_t lb = t.leaf_begin()[n];
            int kids = 0;
            t.for_each_child(n, [&](int32_t c) {
                EXPECT_EQ(t.parent()[c], n);
                EXPECT_EQ(t.level()[c], t.level()[n] + 1);
                EXPECT_EQ(t.point_begin()[c], pb);
                EXPECT_EQ(t.leaf_begin()[c], lb);
                pb = t.point_end()[c];
                lb = t.leaf_end()[c];
                ++kids;
                // The child's cell is one octant of the parent's.
                EXPECT_FLOAT_EQ(t.half_size()[c] * 2, t.half_size()[n]);
            });
            EXPECT_EQ(pb, t.point_end()[n]);
            EXPECT_EQ(lb, t.leaf_end()[n]);
            EXPECT_GE(kids, 1);
            EXPECT_LE(kids, 8);
        }
        // Every point of the node lies in its cell (up to rounding of the cell bounds).
        const Vec3 c = t.spheres()[n].center;
        const float h = t.half_size()[n] * 1.0001f + 1e-6f;
        for (uint32_t k = t.point_begin()[n]; k < t.point_end()[n]; ++k) {
            const Vec3 q = ps.positions[k];
            ASSERT_LE(std::fabs(q.x - c.x), h);
            ASSERT_LE(std::fabs(q.y - c.y), h);
            ASSERT_LE(std::fabs(q.z - c.z), h);
        }
    }
    EXPECT_EQ(leaves, t.num_leaves());
}

void check_spheres(const Octree& t, const PointSet& ps) {
    for (int32_t n = 0; n < t.num_nodes(); ++n) {
        const Sphere s = t.spheres()[n];
        // Encloses every point below it.
        for (uint32_t k = t.point_begin()[n]; k < t.point_end()[n]; ++k)
            ASSERT_LE(length(ps.positions[k] - s.center), s.radius) << "node " << n;
        if (t.is_leaf(n)) {
            const LeafDisc& d = leaf_discs(t)[t.node_leaf()[n]];
            // Encloses the occluder disc: every point of the disc is within |c - o| + Delta.
            EXPECT_LE(length(d.centroid - s.center) + d.delta, s.radius);
        } else {
            // Encloses each child's sphere (DEVIATION from the paper's plain maximum).
            t.for_each_child(n, [&](int32_t c) {
                EXPECT_LE(length(t.spheres()[c].center - s.center) + t.spheres()[c].radius, s.radius);
            });
        }
    }
}

bool inside(const Box& b, Vec3 p) {
    return p.x >= b.lo.x && p.y >= b.lo.y && p.z >= b.lo.z && p.x <= b.hi.x && p.y <= b.hi.y &&
           p.z <= b.hi.z;
}

void check_boxes(const Octree& t, const PointSet& ps) {
    ASSERT_EQ(walk_nodes(t).size(), size_t(t.num_nodes()));
    for (int32_t n = 0; n < t.num_nodes(); ++n) {
        const Box& b = t.boxes()[n];
        EXPECT_EQ(walk_nodes(t)[n].skip, t.skip()[n]);
        EXPECT_EQ(walk_nodes(t)[n].leaf, t.node_leaf()[n]);
        for (uint32_t k = t.point_begin()[n]; k < t.point_end()[n]; ++k)
            ASSERT_TRUE(inside(b, ps.positions[k])) << "node " << n;
        if (t.is_leaf(n)) {
            // Points of the occluder disc: centroid + Delta (u cos + v sin) for a basis u, v.
            const LeafDisc& d = leaf_discs(t)[t.node_leaf()[n]];
            Vec3 nr = (d.flags & kLeafNormalDegenerate) ? Vec3{0, 0, 1} : d.normal;
            Vec3 u = std::fabs(nr.x) < 0.9f ? cross(nr, {1, 0, 0}) : cross(nr, {0, 1, 0});
            u = u / length(u);
            const Vec3 v = cross(nr, u);
            for (int k = 0; k < 64; ++k) {
                const float a = 6.2831853f * k / 64;
                const Vec3 q =
                    d.centroid + (u * std::cos(a) + v * std::sin(a)) * (d.delta * 0.999f);
                ASSERT_TRUE(inside(b, q)) << "leaf node " << n << " disc point " << k;
            }
        } else {
            t.for_each_child(n, [&](int32_t c) {
                EXPECT_TRUE(inside(b, t.boxes()[c].lo) && inside(b, t.boxes()[c].hi));
            });
        }
    }
}

TEST(Octree, ContentBoxesBoundPointsDiscsAndChildren) {
    PointSet ps = test::sample(test::scene_path("cornell-bunny"), 8000);
    std::vector<uint32_t> order;
    Octree t = Octree::build(ps, {8, 3}, order);
    check_boxes(t, ps);
}

TEST(Octree, RandomCloudHasAValidPreorderStructure) {
    for (int lp : {1, 4, 16}) {
        for (int h : {1, 3, 6, 10}) {
            PointSet ps = random_cloud(3000, 11);
            const PointSet orig = ps;
            std::vector<uint32_t> order;
            const OctreeParams p{h, lp};
            Octree t = Octree::build(ps, p, order);
            check_structure(t, ps, p);
            check_spheres(t, ps);
            check_boxes(t, ps);
            // The permutation is a permutation and moves the data with it.
            std::vector<uint32_t> sorted = order;
            std::sort(sorted.begin(), sorted.end());
            for (uint32_t i = 0; i < sorted.size(); ++i) ASSERT_EQ(sorted[i], i);
            for (uint32_t k = 0; k < order.size(); ++k)
                ASSERT_EQ(ps.positions[k], orig.positions[order[k]]);
        }
    }
}

TEST(Octree, SceneOctreeIsAdaptiveWithLeavesAtManyLevels) {
    PointSet ps = test::sample(test::scene_path("cornell-bunny"), 20000);
    std::vector<uint32_t> order;
    const OctreeParams p{9, 4};
    Octree t = Octree::build(ps, p, order);
    check_structure(t, ps, p);
    check_spheres(t, ps);
    std::set<int> levels;
    for (int32_t l : t.leaf_node()) levels.insert(t.level()[l]);
    EXPECT_GE(levels.size(), 3u) << "leaves appear at several depths";
}

TEST(Octree, LeafStatisticsMatchTheirPoints) {
    PointSet ps = test::sample(test::scene_path("cornell-bunny"), 5000);
    std::vector<uint32_t> order;
    Octree t = Octree::build(ps, {7, 6}, order);
    for (int32_t l = 0; l < t.num_leaves(); ++l) {
        const int32_t n = t.leaf_node()[l];
        const LeafDisc& d = leaf_discs(t)[l];
        Vec3 c{}, nr{};
        float far = 0, splat = 0;
        const uint32_t b = t.point_begin()[n], e = t.point_end()[n];
        for (uint32_t k = b; k < e; ++k) c += ps.positions[k], nr += ps.normals[k];
        c = c / float(e - b);
        for (uint32_t k = b; k < e; ++k) {
            far = std::max(far, length(ps.positions[k] - c));
            splat = std::max(splat, ps.radii[k]);
        }
        EXPECT_NEAR(d.centroid.x, c.x, 1e-5f);
        EXPECT_NEAR(d.centroid.y, c.y, 1e-5f);
        EXPECT_NEAR(d.centroid.z, c.z, 1e-5f);
        EXPECT_NEAR(d.delta, std::max(far, detail::kDeltaSplatFloor * splat), 1e-5f);
        EXPECT_GE(d.delta, detail::kDeltaSplatFloor * splat)
            << "Delta never below the splat radius times the floor";
        if (!(d.flags & kLeafNormalDegenerate)) {
            EXPECT_NEAR(length(d.normal), 1.f, 1e-5f);
            EXPECT_GT(dot(d.normal, nr), 0.f);
        }
    }
}

TEST(Octree, OnePointLeafStillOccludesThroughItsSplat) {
    PointSet ps;
    ps.positions = {{0, 0, 0}, {1, 1, 1}};
    ps.normals = {{0, 0, 1}, {0, 0, 1}};
    ps.radii = {0.05f, 0.05f};
    std::vector<uint32_t> order;
    Octree t = Octree::build(ps, {4, 1}, order);
    ASSERT_EQ(t.num_leaves(), 2);
    for (const LeafDisc& d : leaf_discs(t)) EXPECT_FLOAT_EQ(d.delta, detail::kDeltaSplatFloor * 0.05f);
}

TEST(Octree, DeltaFloorSetsTheSmallestDisc) {
    PointSet ps;
    ps.positions = {{0, 0, 0}, {1, 1, 1}};
    ps.normals = {{0, 0, 1}, {0, 0, 1}};
    ps.radii = {0.05f, 0.05f};
    for (float floor : {0.f, 1.f, 2.f, 4.f}) {
        SCOPED_TRACE(floor);
        PointSet copy = ps;
        std::vector<uint32_t> order;
        OctreeParams p{4, 1};
        p.delta_floor = floor;
        Octree t = Octree::build(copy, p, order);
        EXPECT_EQ(t.params().delta_floor, floor);
        for (const LeafDisc& d : leaf_discs(t)) EXPECT_FLOAT_EQ(d.delta, floor * 0.05f);
    }
    for (float bad : {-0.5f, 10.5f, std::numeric_limits<float>::quiet_NaN()}) {
        OctreeParams p;
        p.delta_floor = bad;
        EXPECT_THROW(p.check("test"), Error) << bad;
    }
}

TEST(Octree, LeafWhoseNormalsCancelIsFlagged) {
    PointSet ps;
    ps.positions = {{0, 0, 0}, {0.001f, 0, 0}, {5, 5, 5}};
    ps.normals = {{0, 0, 1}, {0, 0, -1}, {0, 1, 0}};
    std::vector<uint32_t> order;
    Octree t = Octree::build(ps, {1, 2}, order);
    int flagged = 0;
    for (const LeafDisc& d : leaf_discs(t)) flagged += (d.flags & kLeafNormalDegenerate) != 0;
    EXPECT_EQ(flagged, 1);
}

// Copies of a point (a cloud exported twice) each get a radius 1/sqrt(2) smaller from the halved
// spacing; their leaf's disc is the one disc of their summed area, not the smaller one. Points
// at distinct positions keep the largest radius.
TEST(Octree, CopiesOfAPointMakeOneDiscOfTheirSummedArea) {
    PointSet ps;
    for (const Vec3 p : {Vec3{0, 0, 0}, Vec3{1, 1, 1}, Vec3{1, 0, 0}})
        for (int copy = 0; copy < 2; ++copy) {
            ps.positions.push_back(p);
            ps.normals.push_back({0, 0, 1});
            ps.radii.push_back(0.05f / std::sqrt(2.f));
        }
    ps.positions.push_back({0.01f, 0, 0});  // beside the first pair, a larger radius
    ps.normals.push_back({0, 0, 1});
    ps.radii.push_back(0.06f);
    std::vector<uint32_t> order;
    OctreeParams p{1, 1};  // leaves of a few points each: height 1
    p.delta_floor = 1;
    const Octree t = Octree::build(ps, p, order);
    ASSERT_EQ(t.num_leaves(), 3);
    std::vector<float> splats = t.leaf_splat();
    std::sort(splats.begin(), splats.end());
    EXPECT_NEAR(splats[0], 0.05f, 1e-7f);  // the pair at (1, 1, 1)
    EXPECT_NEAR(splats[1], 0.05f, 1e-7f);  // the pair at (1, 0, 0)
    EXPECT_EQ(splats[2], 0.06f);  // the pair at 0 (0.05 together) beside a 0.06 point
}

TEST(Octree, DuplicatePointsStopAtMaxHeight) {
    PointSet ps;
    for (int i = 0; i < 50; ++i) {
        ps.positions.push_back({0.5f, 0.5f, 0.5f});
        ps.normals.push_back({0, 1, 0});
    }
    ps.positions.push_back({0, 0, 0});
    ps.normals.push_back({0, 1, 0});
    std::vector<uint32_t> order;
    const OctreeParams p{6, 4};
    Octree t = Octree::build(ps, p, order);
    check_structure(t, ps, p);
    EXPECT_EQ(t.height(), 6);
}

TEST(Octree, SinglePointIsOneLeaf) {
    PointSet ps;
    ps.positions = {{1, 2, 3}};
    ps.normals = {{0, 1, 0}};
    std::vector<uint32_t> order;
    Octree t = Octree::build(ps, {8, 1}, order);
    EXPECT_EQ(t.num_nodes(), 1);
    EXPECT_EQ(t.num_leaves(), 1);
}

TEST(Octree, HugeCoordinatesStillBoundTheirPoints) {
    PointSet ps = random_cloud(500, 3);
    for (Vec3& p : ps.positions) p = p * 10.f + Vec3{1e6f, -2e6f, 3e5f};
    std::vector<uint32_t> order;
    const OctreeParams p{8, 2};
    Octree t = Octree::build(ps, p, order);
    check_spheres(t, ps);
}

TEST(Octree, LeafOfPointFindsTheLeafHoldingIt) {
    PointSet ps = random_cloud(2000, 5);
    std::vector<uint32_t> order;
    Octree t = Octree::build(ps, {7, 3}, order);
    for (uint32_t k = 0; k < ps.size(); ++k) {
        const int32_t n = t.leaf_node()[t.leaf_of_point(k)];
        ASSERT_GE(k, t.point_begin()[n]);
        ASSERT_LT(k, t.point_end()[n]);
    }
}

void expect_error(PointSet ps, OctreeParams p, const std::string& needle) {
    std::vector<uint32_t> order;
    try {
        Octree::build(ps, p, order, "cloud.ply");
        FAIL() << "expected an error containing '" << needle << "'";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("cloud.ply"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
}

TEST(Octree, CoordinatesSpanningMoreThanAFloatAreRejected) {
    PointSet ps = random_cloud(6, 2);
    ps.positions[0].x = -3e38f;
    ps.positions[1].x = 3e38f;
    expect_error(ps, {}, "span");
}

TEST(Octree, EmptyCloudIsRejected) { expect_error({}, {}, "empty"); }

TEST(Octree, NanCoordinateIsRejectedWithItsIndex) {
    PointSet ps = random_cloud(10, 1);
    ps.positions[7].y = NAN;
    expect_error(ps, {}, "point 7");
}

TEST(Octree, ZeroNormalIsRejectedWithItsIndex) {
    PointSet ps = random_cloud(10, 1);
    ps.normals[3] = {0, 0, 0};
    expect_error(ps, {}, "point 3: normal");
}

TEST(Octree, MissingNormalsAreRejected) {
    PointSet ps = random_cloud(10, 1);
    ps.normals.clear();
    expect_error(ps, {}, "normals");
}

TEST(Octree, AbsurdParametersAreRejected) {
    expect_error(random_cloud(10, 1), {0, 4}, "max_height");
    expect_error(random_cloud(10, 1), {22, 4}, "max_height");
    expect_error(random_cloud(10, 1), {8, 0}, "leaf_points");
}

}  // namespace
}  // namespace vmap
