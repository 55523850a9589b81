// The leaf-pair predicate (paper §5; docs/design.md "Leaf-pair visibility").
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "backend_fixture.h"
#include "octree/records.h"
#include "test_util.h"
#include "visibility/leaf_pair.h"
#include "visibility/packet_walk.h"
#include "visibility/predicate_cases.h"
#include "vmap/normals.h"

namespace vmap {
namespace {

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

LeafDisc disc(Vec3 c, Vec3 n, float delta) {
    LeafDisc x;
    x.centroid = c;
    x.normal = n / length(n);
    x.delta = delta;
    return x;
}

// The predicate's pieces asked on the fixture's backend (visibility/predicate_cases.h).
class OnBackend : public test::OnEachBackend {
  protected:
    bool ask(test::PredicateCase c) const {
        return test::answers_on(backend(), std::span(&c, 1))[0] != 0;
    }
    // is_actual_occluder(p, d, len, x, vp)
    bool occludes(Vec3 p, Vec3 d, float len, const LeafDisc& x, const VisibilityParams& vp) const {
        test::PredicateCase c;
        c.what = test::Predicate::kActualOccluder;
        c.p = p, c.d = d, c.len = len, c.x = x, c.vp = vp;
        return ask(c);
    }
    // leaves_face(a, b, d, len, vp)
    bool face(const LeafDisc& a, const LeafDisc& b, Vec3 d, float len,
              const VisibilityParams& vp) const {
        test::PredicateCase c;
        c.what = test::Predicate::kLeavesFace;
        c.a = a, c.b = b, c.d = d, c.len = len, c.vp = vp;
        return ask(c);
    }
    // counts_as_occluder(pair_segment(a, b, vp), x, vp), or in_front_of_ends when `front`.
    bool counts(const LeafDisc& a, const LeafDisc& b, const LeafDisc& x,
                const VisibilityParams& vp, bool front = false) const {
        test::PredicateCase c;
        c.what = front ? test::Predicate::kInFrontOfEnds : test::Predicate::kCountsAsOccluder;
        c.a = a, c.b = b, c.x = x, c.vp = vp;
        return ask(c);
    }
};

// Fig. 7 of the paper: p = origin, q = (1, 0, 0).
struct Fig7 : OnBackend {
    VisibilityParams vp;
    Vec3 p{0, 0, 0}, d{1, 0, 0};
    bool occludes(const LeafDisc& x) const { return OnBackend::occludes(p, d, 1, x, vp); }
};

TEST_P(Fig7, PlaneCuttingTheSegmentNearItsCentroidOccludes) {
    EXPECT_TRUE(occludes(disc({0.5f, 0.05f, 0}, {1, 0.2f, 0}, 0.1f)));
}
TEST_P(Fig7, PlaneCutOutsideTheSegmentIsRejected) {  // x1
    EXPECT_FALSE(occludes(disc({1.3f, 0, 0}, {1, 0, 0}, 0.5f)));
    EXPECT_FALSE(occludes(disc({-0.2f, 0, 0}, {1, 0, 0}, 0.5f)));
}
TEST_P(Fig7, CrossingFartherThanDeltaIsRejected) {  // x4
    EXPECT_FALSE(occludes(disc({0.5f, 0.3f, 0}, {1, 0, 0}, 0.2f)));
    EXPECT_TRUE(occludes(disc({0.5f, 0.3f, 0}, {1, 0, 0}, 0.31f)));
}
TEST_P(Fig7, PlaneParallelToTheSegmentIsRejected) {  // x5
    EXPECT_FALSE(occludes(disc({0.5f, 0.01f, 0}, {0, 1, 0}, 0.5f)));
}
TEST_P(Fig7, CrossingAtTheEndpointsIsNotAnOcclusion) {
    // Neighbours on the same surface as p: their plane passes through p (t = 0 < eps).
    EXPECT_FALSE(occludes(disc({0, 0.02f, 0}, {1, 0, 0}, 0.1f)));
    EXPECT_FALSE(occludes(disc({1, 0.02f, 0}, {1, 0, 0}, 0.1f)));
}
TEST_P(Fig7, LeafWithoutAPlaneOccludesWithinItsSphere) {
    LeafDisc x = disc({0.5f, 0.05f, 0}, {1, 0, 0}, 0.1f);
    x.flags = kLeafNormalDegenerate;
    x.normal = {0, 0, 0};
    EXPECT_TRUE(occludes(x));
    x.centroid.y = 0.2f;
    EXPECT_FALSE(occludes(x));
}

VMAP_ON_EACH_BACKEND(Fig7);

// The cores (VisibilityParams::core, occluder_weight): a crossing within core x Delta of a
// disc's centre counts K occluders, one farther out (still on the disc) counts one. Ends a at
// the origin and b at (1, 0, 0), facing each other; an occluder across the segment at x = 0.5,
// its disc of radius 0.1 centred `off` above the segment's line.
struct Cores : OnBackend {
    VisibilityParams vp;
    LeafDisc a = disc({0, 0, 0}, {1, 0, 0}, 0.05f), b = disc({1, 0, 0}, {-1, 0, 0}, 0.05f);
    int weight(float off) const {
        test::PredicateCase c;
        c.what = test::Predicate::kOccluderWeight;
        c.a = a, c.b = b, c.x = disc({0.5f, off, 0}, {1, 0, 0}, 0.1f), c.vp = vp;
        return test::answers_on(backend(), std::span(&c, 1))[0];
    }
};

TEST_P(Cores, ACrossingInTheCoreCountsKAndOneOnTheRimCountsOne) {
    vp.core = 0.5f;  // the core: within 0.05 of the centre
    EXPECT_EQ(weight(0.f), vp.K);
    EXPECT_EQ(weight(0.049f), vp.K);
    EXPECT_EQ(weight(0.051f), 1);
    EXPECT_EQ(weight(0.099f), 1);
    EXPECT_EQ(weight(0.101f), 0);  // off the disc
    vp.K = 3;
    EXPECT_EQ(weight(0.02f), 3);
    EXPECT_EQ(weight(0.07f), 1);
}
TEST_P(Cores, WithoutCoresEveryCrossingCountsOne) {
    vp.core = 0.f;
    EXPECT_EQ(weight(0.f), 1);
    EXPECT_EQ(weight(0.099f), 1);
    EXPECT_EQ(weight(0.101f), 0);
}
TEST_P(Cores, ARoughSheetOrKOneHasNoCores) {
    vp.core = 0.5f;
    vp.roughness = 1e-3f;  // a scan's noise: no crossing is sure
    EXPECT_EQ(weight(0.f), 1);
    vp.roughness = 0.f;
    vp.K = 1;  // every crossing counts K already
    EXPECT_EQ(weight(0.f), 1);
    EXPECT_EQ(weight(0.099f), 1);
}
TEST_P(Cores, ACoreOfTheWholeDiscCountsEveryCrossingK) {
    vp.core = 1.f;
    EXPECT_EQ(weight(0.099f), vp.K);
    EXPECT_EQ(weight(0.101f), 0);
}
TEST_P(Cores, AnOccluderThatDoesNotCountWeighsNothingInItsCore) {
    vp.core = 0.5f;
    // a turned away from b: the occluder lies behind a's tangent plane (in_front_of_ends)
    a = disc({0, 0, 0}, {-1, 0, 0}, 0.05f);
    EXPECT_EQ(weight(0.f), 0);
}

VMAP_ON_EACH_BACKEND(Cores);

// A convex neighbour of end a: its centroid just behind a's tangent plane, its disc tilted so it
// reaches into the segment's first stretch. It cuts the segment as a disc, but no surface
// wholly behind a's plane can lie on a segment in front of it.
struct EndPlanes : OnBackend {
    VisibilityParams vp;
    LeafDisc a, b;
    Vec3 d;
    void SetUp() override {
        OnBackend::SetUp();
        if (IsSkipped()) return;
        a = disc({0, 0, 0}, {0, 1, 0}, 0.05f);
        b = disc({1, 0.1f, 0}, {-1, 0, 0}, 0.05f);
        d = b.centroid - a.centroid;
        ASSERT_TRUE(face(a, b, d, length(d), vp));
    }
    bool counts(const LeafDisc& x) const { return OnBackend::counts(a, b, x, vp); }
    bool in_front_of_ends(const LeafDisc& x) const { return OnBackend::counts(a, b, x, vp, true); }
    // As a disc, x cuts the segment from a to b.
    bool cuts(const LeafDisc& x) const { return occludes(a.centroid, d, length(d), x, vp); }
};

TEST_P(EndPlanes, NeighbourBehindAnEndsTangentPlaneDoesNotCount) {
    const LeafDisc x = disc({0.1f, -0.004f, 0}, {-0.3f, 1, 0}, 0.08f);
    EXPECT_TRUE(cuts(x));  // as a disc, it cuts
    EXPECT_FALSE(counts(x));
}
TEST_P(EndPlanes, SurfaceInFrontOfBothEndsCounts) {
    const LeafDisc x = disc({0.1f, 0.004f, 0}, {-0.3f, 1, 0}, 0.08f);
    EXPECT_TRUE(cuts(x));
    EXPECT_TRUE(counts(x));
}
TEST_P(EndPlanes, BehindTheFarEndsPlaneDoesNotCountEither) {
    // Just behind b's plane (x > 1), tilted toward the segment's last stretch.
    const LeafDisc x = disc({1.004f, 0.08f, 0}, {1, 3, 0}, 0.08f);
    EXPECT_TRUE(cuts(x));
    EXPECT_FALSE(counts(x));
}
TEST_P(EndPlanes, AnEndWithoutANormalCullsNothing) {
    const LeafDisc x = disc({0.1f, -0.004f, 0}, {-0.3f, 1, 0}, 0.08f);
    a.flags = kLeafNormalDegenerate;
    a.normal = {0, 0, 0};
    EXPECT_TRUE(counts(x));
}

// The near-end exit rule (exits_at_an_end): a leaf whose plane the segment cuts within half
// the end's disc radius of that end, coming out of it (the end behind its plane), is the end's
// own surface; one the segment goes into, or one cut farther out, still counts. a sits at the
// origin with Delta 0.05 (half: 0.025) and the segment leaves along d = (1, 0.1, 0).
TEST_P(EndPlanes, CrossedFromBehindRightAtAnEndDoesNotCount) {
    // Centroid in front of a's plane (y > 0), a behind its plane: n . (a - c) < 0. Its plane
    // cuts the segment at about 0.012 from a, inside the disc.
    const LeafDisc x = disc({0.02f, 0.004f, 0}, {1, -0.3f, 0}, 0.05f);
    ASSERT_TRUE(in_front_of_ends(x));
    ASSERT_LT(dot(x.normal, a.centroid - x.centroid), 0.f);
    EXPECT_TRUE(cuts(x));
    EXPECT_FALSE(counts(x));
    // The same leaf facing the other way: the segment goes into it, so it counts.
    LeafDisc in = x;
    in.normal = -x.normal;
    EXPECT_TRUE(counts(in));
}
TEST_P(EndPlanes, CrossedFromBehindFartherOutCounts) {
    // The same geometry moved out to about 0.05 from a: more than half of a's Delta (0.025).
    const LeafDisc x = disc({0.06f, 0.01f, 0}, {1, -0.3f, 0}, 0.05f);
    ASSERT_LT(dot(x.normal, a.centroid - x.centroid), 0.f);
    EXPECT_TRUE(counts(x));
    // A larger end disc reaches it: now it is the end's own surface.
    a.delta = 0.2f;
    EXPECT_FALSE(counts(x));
}
TEST_P(EndPlanes, TheExitRuleAppliesAtTheFarEndToo) {
    // Near b (centroid (1, 0.1, 0), normal -x): a leaf just in front of b's plane with b
    // behind its own plane, cut about 0.02 from b (b's Delta 0.05).
    const LeafDisc x = disc({0.98f, 0.1f, 0.f}, {-1, 0.2f, 0}, 0.05f);
    ASSERT_TRUE(in_front_of_ends(x));
    ASSERT_LT(dot(x.normal, b.centroid - x.centroid), 0.f);
    EXPECT_TRUE(cuts(x));
    EXPECT_FALSE(counts(x));
    b.flags = kLeafNormalDegenerate;  // an end without a plane drops nothing
    b.normal = {0, 0, 0};
    EXPECT_TRUE(counts(x));
}

// A rough sheet (VisibilityParams::roughness, a scan's noise): a neighbour of a's own sheet
// (the same normal) raised 0.01 above a, which the segment, rising at 0.1, leaves through its
// disc about 0.1 from a: far beyond half of a's disc radius (0.025), so without roughness it
// counts; with a roughness above the step it is the sheet's noise and does not.
TEST_P(EndPlanes, ABumpOfAnEndsRoughSheetDoesNotCount) {
    const LeafDisc x = disc({0.11f, 0.01f, 0}, {0, 1, 0}, 0.05f);
    ASSERT_TRUE(in_front_of_ends(x));
    ASSERT_LT(dot(x.normal, a.centroid - x.centroid), 0.f);
    EXPECT_TRUE(cuts(x));
    EXPECT_TRUE(counts(x));
    vp.roughness = 0.02f;
    EXPECT_FALSE(counts(x));
    vp.roughness = 0.005f;  // a step higher than the roughness is a real one
    EXPECT_TRUE(counts(x));
    // The same bump the segment goes into (its normal turned down) is no exit: it counts.
    vp.roughness = 0.02f;
    LeafDisc in = x;
    in.normal = -x.normal;
    EXPECT_TRUE(counts(in));
}
TEST_P(EndPlanes, ARoughSheetsRuleNeedsTheEndsOwnNormal) {
    vp.roughness = 0.1f;  // every step below: the normals decide
    // 35 degrees from a's normal: its own sheet, tilted by the noise.
    const LeafDisc near = disc({0.11f, 0.01f, 0}, {0.7f, 1, 0}, 0.05f);
    ASSERT_TRUE(cuts(near));
    ASSERT_LT(dot(near.normal, a.centroid - near.centroid), 0.f);
    EXPECT_FALSE(counts(near));
    // 39 degrees: another surface (a crease's other face, an object's far side) still counts.
    const LeafDisc off = disc({0.11f, 0.01f, 0}, {0.8f, 1, 0}, 0.05f);
    ASSERT_TRUE(cuts(off));
    ASSERT_LT(dot(off.normal, a.centroid - off.centroid), 0.f);
    EXPECT_TRUE(counts(off));
}
TEST_P(EndPlanes, ARoughSheetsRuleAppliesAtTheFarEnd) {
    // b on a ceiling-like sheet (normal nearly -y) that the segment reaches at 8.6 degrees; a
    // bump of its sheet 0.01 in front of b, cut about 0.067 from b (b's Delta 0.05).
    b.normal = Vec3{-0.05f, -1, 0} / length(Vec3{-0.05f, -1, 0});
    const LeafDisc x = disc({0.9332f, 0.0933f, 0}, b.normal, 0.05f);
    ASSERT_TRUE(in_front_of_ends(x));
    ASSERT_TRUE(cuts(x));
    ASSERT_LT(dot(x.normal, b.centroid - x.centroid), 0.f);
    EXPECT_TRUE(counts(x));
    vp.roughness = 0.02f;
    EXPECT_FALSE(counts(x));
}

// The end windows (VisibilityParams::end_window): a crossing within end_window x Delta_end of
// the nearer end does not count, whichever way the leaf faces; the window is in the end's own
// disc radii. a's Delta is 0.05; x is a surface the segment goes into (it counts with no
// window), cut about 0.059 from a.
TEST_P(EndPlanes, AnEndWindowDropsACrossingInsideIt) {
    const LeafDisc x = disc({0.06f, 0.01f, 0}, {-1, 0.3f, 0}, 0.05f);
    ASSERT_TRUE(in_front_of_ends(x));
    EXPECT_TRUE(counts(x));
    vp.end_window = 1;  // 0.05: the crossing lies beyond it
    EXPECT_TRUE(counts(x));
    vp.end_window = 2;  // 0.1: inside
    EXPECT_FALSE(counts(x));
    a.delta = 0.02f;  // a smaller end disc, a narrower window (0.04)
    EXPECT_TRUE(counts(x));
}
TEST_P(EndPlanes, AnEndWindowAtTheFarEndUsesThatEndsDisc) {
    // The plane x = 0.94 cuts the segment about 0.06 from b (b's Delta 0.05).
    const LeafDisc x = disc({0.94f, 0.098f, 0}, {1, 0, 0}, 0.05f);
    ASSERT_TRUE(in_front_of_ends(x));
    vp.end_window = 1;
    EXPECT_TRUE(counts(x));
    vp.end_window = 1.5f;  // 0.075
    EXPECT_FALSE(counts(x));
    b.delta = 0.03f;  // 0.045 at b; a's larger disc does not widen b's window
    a.delta = 0.5f;
    EXPECT_TRUE(counts(x));
}
TEST_P(EndPlanes, AnEndWindowLeavesTheMiddleOfTheSegment) {
    const LeafDisc x = disc({0.5f, 0.05f, 0}, {1, 0.2f, 0}, 0.1f);
    for (float w : {0.f, 2.f, 8.f}) {
        vp.end_window = w;
        EXPECT_TRUE(counts(x)) << w;
    }
    vp.end_window = 11;  // 0.55 from each end: the whole segment
    EXPECT_FALSE(counts(x));
}

VMAP_ON_EACH_BACKEND(EndPlanes);

class Facing : public OnBackend {};

TEST_P(Facing, BothNormalsMustFaceTheOther) {
    VisibilityParams vp;
    LeafDisc a, b;
    a.normal = {0, 1, 0};
    b.normal = {0, -1, 0};
    const Vec3 d{0, 1, 0};
    EXPECT_TRUE(face(a, b, d, 1, vp));
    b.normal = {0, 1, 0};
    EXPECT_FALSE(face(a, b, d, 1, vp));
    // Coplanar leaves (d in the tangent plane) do not face each other.
    b.normal = {0, 1, 0};
    EXPECT_FALSE(face(a, b, {1, 0, 0}, 1, vp));
}

VMAP_ON_EACH_BACKEND(Facing);

// slab_meets_box_regular (the GPU's packet walk where no lane's direction has a component under
// 1e-30 in magnitude) answers as slab_meets_box on such segments, on each backend: random
// segments and boxes, flat boxes (a wall patch's), boxes whose faces pass exactly through the
// segment's first or last point, and direction components from 1e-29 to 1e3 in magnitude.
class Slab : public OnBackend {};

TEST_P(Slab, TheTestWithoutPerAxisChecksAnswersAsSlabMeetsBox) {
    std::mt19937 rng(17);
    std::uniform_real_distribution<float> u(-1, 1);
    std::vector<test::PredicateCase> cases;
    std::vector<uint8_t> want;
    for (int it = 0; it < 40000; ++it) {
        test::PredicateCase c;
        c.what = test::Predicate::kSlabRegular;
        c.p = {u(rng), u(rng), u(rng)};
        Vec3 d{u(rng), u(rng), u(rng)};
        float* dc[3] = {&d.x, &d.y, &d.z};
        if (it % 4 == 1) *dc[rng() % 3] = std::ldexp(u(rng) >= 0 ? 1.f : -1.f, -96 + int(rng() % 30));
        if (it % 8 == 3) *dc[rng() % 3] *= 1000.f;
        if (detail::has_tiny_component(d)) continue;
        c.d = d;
        c.t0 = 0.01f * 0.999f, c.t1 = 1.f - 0.01f * 0.999f;
        // Half of the boxes about a point of the segment's line, so that about half meet it.
        const Vec3 at = it % 2 ? c.p + d * (0.5f + 0.7f * u(rng)) : Vec3{u(rng), u(rng), u(rng)};
        const Vec3 half{0.2f * (u(rng) + 1), 0.2f * (u(rng) + 1), 0.2f * (u(rng) + 1)};
        Vec3 lo = at - half + Vec3{0.1f * u(rng), 0.1f * u(rng), 0.1f * u(rng)}, hi = lo + half * 2.f;
        if (it % 5 == 2) hi.y = lo.y;  // flat
        if (it % 7 == 4) {             // a face through the sub-segment's first or last point
            const Vec3 e = c.p + d * (rng() % 2 ? c.t0 : c.t1);
            float* l[3] = {&lo.x, &lo.y, &lo.z};
            const float ec[3] = {e.x, e.y, e.z};
            const int k = int(rng() % 3);
            *l[k] = ec[k];
        }
        c.box = Box{lo, hi};
        cases.push_back(c);
        want.push_back(detail::slab_meets_box(detail::slab_ray(c.p, c.d, c.t0, c.t1), c.box, 0.f));
    }
    const std::vector<uint8_t> got = test::answers_on(backend(), cases);
    ASSERT_EQ(got.size(), want.size());
    size_t hits = 0, differ = 0;
    for (size_t i = 0; i < got.size(); ++i) hits += want[i], differ += got[i] != want[i];
    EXPECT_EQ(differ, 0u);
    EXPECT_GT(hits, 2000u);
    EXPECT_GT(got.size() - hits, 2000u);
}

VMAP_ON_EACH_BACKEND(Slab);

// The traversal (sphere pruning, early exit at K) against testing every leaf.
bool visible_without_pruning(const OctreeView& t, int32_t a, int32_t b,
                             const VisibilityParams& vp) {
    const LeafDisc la = t.leaves[a], lb = t.leaves[b];
    const Vec3 d = lb.centroid - la.centroid;
    const float len = sqrtf(length2(d));
    if (!(len > 0.f) || !detail::leaves_face(la, lb, d, len, vp)) return false;
    int occ = 0;  // each leaf's weight: 1, or K crossed in its core (occluder_weight)
    for (int32_t l = 0; l < t.num_leaves; ++l)
        if (l != a && l != b)
            occ += detail::occluder_weight(detail::pair_segment(la, lb, vp), t.leaves[l], vp);
    return occ < vp.K;
}

// The backend's answers for leaf pairs (a < b each), one 1 x 1 rectangle a pair, in one batch;
// its work added to *wc.
std::vector<bool> visible_on(detail::Backend& backend, const Octree& t, const VisibilityParams& vp,
                             const std::vector<std::pair<int32_t, int32_t>>& pairs,
                             WorkCounters* wc) {
    std::vector<detail::PairJob> jobs(pairs.size());
    for (size_t k = 0; k < pairs.size(); ++k) {
        jobs[k].row0 = pairs[k].first, jobs[k].rows = 1;
        jobs[k].col0 = pairs[k].second, jobs[k].cols = 1;
        jobs[k].word_offset = k;
    }
    backend.prepare(t, vp, std::max<uint64_t>(1, pairs.size()));
    backend.submit(jobs, pairs.size(), 0);
    const uint32_t* bits = backend.wait(0, *wc);
    std::vector<bool> out(pairs.size());
    for (size_t k = 0; k < pairs.size(); ++k) out[k] = bits[k] & 1u;
    return out;
}

// Random leaf pairs, a < b.
std::vector<std::pair<int32_t, int32_t>> random_pairs(int32_t num_leaves, int n, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_int_distribution<int32_t> pick(0, num_leaves - 1);
    std::vector<std::pair<int32_t, int32_t>> pairs;
    for (int it = 0; it < n; ++it) {
        int32_t a = pick(rng), b = pick(rng);
        if (a == b) continue;
        pairs.push_back({std::min(a, b), std::max(a, b)});
    }
    return pairs;
}

class TraversalOracle : public test::OnEachBackendWith<std::tuple<const char*, int, int>> {
  protected:
    void check_against_no_pruning(float window) const;
};

// The backend's walk (on the GPU: the default kernel) and the host's leaf_pair_visible against
// testing every leaf; without end windows and with (the walk's sub-segment then narrower).
TEST_P(TraversalOracle, SpherePruningNeverDropsAnOccluder) {
    for (float window : {0.f, 2.f}) {
        SCOPED_TRACE(window);
        check_against_no_pruning(window);
        if (HasFatalFailure()) return;
    }
}

void TraversalOracle::check_against_no_pruning(float window) const {
    const auto [scene, height, k] = param();
    PointSet ps = test::sample(test::scene_path(scene), 3000, 5);
    std::vector<uint32_t> order;
    Octree t = Octree::build(ps, {height, 3}, order);
    VisibilityParams vp;
    vp.K = k;
    vp.end_window = window;
    const OctreeView v = octree_view(t);
    const auto pairs = random_pairs(v.num_leaves, 4000, 9);
    WorkCounters wc;
    const std::vector<bool> got = visible_on(*leaf_pair_backend(), t, vp, pairs, &wc);
    int visible = 0, hidden = 0;
    for (size_t i = 0; i < pairs.size(); ++i) {
        const auto [a, b] = pairs[i];
        const bool want = visible_without_pruning(v, a, b, vp);
        ASSERT_EQ(got[i], want) << "backend, leaves " << a << " " << b;
        ASSERT_EQ(leaf_pair_visible<false>(v, a, b, vp, static_cast<WorkCounters*>(nullptr)), want)
            << "host, leaves " << a << " " << b;
        (got[i] ? visible : hidden)++;
    }
    EXPECT_EQ(wc.pairs, pairs.size());
    EXPECT_EQ(wc.visible_pairs, uint64_t(visible));
    EXPECT_GT(visible, 100);
    EXPECT_GT(hidden, 100);
}

VMAP_ON_EACH_BACKEND_WITH(TraversalOracle,
                          ::testing::Values(std::make_tuple("cornell-bunny", 6, 1),
                                            std::make_tuple("cornell-bunny", 8, 2),
                                            std::make_tuple("cornell-two-models", 7, 3)),
                          [](const std::tuple<const char*, int, int>& c) {
                              return std::string(std::get<0>(c)) + "_h" +
                                     std::to_string(std::get<1>(c)) + "_K" +
                                     std::to_string(std::get<2>(c));
                          });

// A random scene for the packet walk: points on a few planes (some axis-aligned, with
// coordinates on a coarse grid, so that many segments have an exactly zero direction component
// and walk alone: segments between two facing plates on a grid, whose boxes' faces lie on the
// segments' lines), on a sphere, on both sides of a thin wall, and pairs of points with opposite
// normals at one place (flagged leaves).
// The scene's points moved by Gaussian noise (0.01 per axis: a sixth of the splats), as a
// scan's: the roughness rule of exits_at_an_end fires on them (with VisibilityParams::roughness
// kNoisyRoughness, 3 sqrt 2 sigma).
constexpr float kNoisyRoughness = 0.0424f;
PointSet noisy(PointSet ps, uint32_t seed) {
    std::mt19937 rng(seed * 31 + 7);
    std::normal_distribution<float> g(0.f, 0.01f);
    for (Vec3& p : ps.positions) p += Vec3{g(rng), g(rng), g(rng)};
    return ps;
}

PointSet random_scene(uint32_t seed, int n) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    PointSet ps;
    for (int i = 0; i < n; ++i) {
        const int kind = int(rng() % 6);
        Vec3 p{u(rng), u(rng), u(rng)}, nrm{0, 0, 0};
        float radius = 0.06f;
        if (kind == 5) {  // facing plates z = +-0.8 on a grid of 1/4, splats of radius 0
            const bool top = rng() % 2;
            p = {std::round(p.x * 4) / 4, std::round(p.y * 4) / 4, top ? 0.8f : -0.8f};
            nrm = {0, 0, top ? -1.f : 1.f};
            radius = 0;
        } else if (kind == 0) {  // the wall x = 0.25 on a grid of 1/8, both sides
            p = {0.25f, std::round(p.y * 8) / 8, std::round(p.z * 8) / 8};
            nrm = {rng() % 2 ? 1.f : -1.f, 0, 0};
        } else if (kind == 1) {  // the floor y = -1, normal up
            p.y = -1.f;
            nrm = {0, 1, 0};
        } else if (kind == 2) {  // a sphere of radius 0.3 about (-0.4, 0.2, 0.1)
            const Vec3 c{-0.4f, 0.2f, 0.1f};
            const float l = sqrtf(length2(p));
            nrm = l > 0 ? p * (1.f / l) : Vec3{0, 0, 1};
            p = c + nrm * 0.3f;
        } else if (kind == 3) {  // a tilted plate
            p.z = 0.5f * p.x - 0.3f;
            nrm = Vec3{-0.5f, 0, 1} * (1.f / sqrtf(1.25f));
        } else {  // two points at one place, opposite normals: a leaf whose normals cancel
            nrm = {0, 0, 1};
            ps.positions.push_back(p);
            ps.normals.push_back({0, 0, -1});
            ps.radii.push_back(0.06f);
        }
        ps.positions.push_back(p);
        ps.normals.push_back(nrm);
        ps.radii.push_back(radius);  // splats: a leaf of one point is a disc
    }
    return ps;
}

// Every pair of a tree through SegmentPacket<W> with lane loop `isa` (packets of consecutive pairs
// in row-major order, spanning rows) against leaf_pair_visible: the same answers and the same
// facing pairs, node tests and occluder tests.
template <int W>
void packet_matches_pairs(const OctreeView& v, const VisibilityParams& vp, int isa, int* alone) {
    WorkCounters want, got;
    detail::SegmentPacket<W> pk;
    int32_t pa[W], pb[W];
    int count = 0;
    uint32_t expect = 0;
    auto flush = [&] {
        uint32_t mask = 0;
        if (pk.load(v, pa, pb, count, vp, &got)) mask = pk.walk(v, vp, &got, isa);
        ASSERT_EQ(mask, expect) << "first pair " << pa[0] << " " << pb[0];
        count = 0, expect = 0;
    };
    for (int32_t a = 0; a < v.num_leaves; ++a)
        for (int32_t b = a + 1; b < v.num_leaves; ++b) {
            const LeafDisc& la = v.leaves[a];
            const Vec3 d = v.leaves[b].centroid - la.centroid;
            *alone += d.x == 0.f || d.y == 0.f || d.z == 0.f;
            if (leaf_pair_visible<true>(v, a, b, vp, &want)) expect |= 1u << count;
            pa[count] = a, pb[count] = b;
            if (++count == W) flush();
        }
    flush();
    EXPECT_EQ(got.facing_pairs, want.facing_pairs);
    EXPECT_EQ(got.node_tests, want.node_tests);
    EXPECT_EQ(got.occluder_tests, want.occluder_tests);
    EXPECT_GT(want.occluder_tests, 0u) << v.num_leaves << " leaves, " << want.facing_pairs
                                       << " facing, " << want.node_tests << " node tests";
}

TEST(PacketWalk, AgreesWithTheLeafPairWalkOnEveryPairOfRandomScenes) {
    int alone = 0, flagged = 0;
    for (uint32_t seed = 1; seed <= 16; ++seed) {
        // The last four scenes noisy, with a roughness (a scan's rough sheets).
        const bool rough = seed > 12;
        PointSet ps = random_scene(seed, 100 + int(seed) * 12);
        if (rough) ps = noisy(std::move(ps), seed);
        std::vector<uint32_t> order;
        const Octree t = Octree::build(ps, {int(5 + seed % 4), int(1 + seed % 3)}, order);
        VisibilityParams vp;
        vp.K = int(1 + seed % 3);
        vp.roughness = rough ? kNoisyRoughness : 0.f;
        const OctreeView v = octree_view(t);
        for (int32_t l = 0; l < v.num_leaves; ++l)
            flagged += (v.leaves[l].flags & kLeafNormalDegenerate) != 0;
        SCOPED_TRACE(seed);
        // Without and with end windows (the vector occluder test of the AVX-512 loop takes
        // every rule of counts_as_occluder, as the AVX2 loop's does); every lane loop this CPU
        // runs (SSE2, AVX2, AVX-512), and a packet not a power of 2.
        for (float window : {0.f, 2.f}) {
            vp.end_window = window;
            vp.eps = window > 0 ? 0.005f : 0.01f;
            for (int isa = 0; isa <= detail::SegmentPacket<32>::best_isa(); ++isa)
                packet_matches_pairs<32>(v, vp, isa, &alone);
            packet_matches_pairs<7>(v, vp, 0, &alone);
        }
    }
    EXPECT_GT(alone, 100);  // pairs with a zero direction component, which walk alone
    EXPECT_GT(flagged, 10);
}

// What the roughness is for: a floor and a wall of an empty room see each other everywhere.
// Sampled exactly, nearly every floor-wall pair is visible; with noise of a quarter spacing the
// floor's neighbours, raised by the noise, hide the pairs leaving at shallow angles; with the
// roughness of that noise (3 sqrt 2 sigma) they are visible again. The noisy pairs' counts
// also rule out a roughness the packets would ignore (the vector loop against the scalar walk).
TEST(RoughSheets, NoiseHidesShallowPairsAndTheRoughnessGivesThemBack) {
    std::mt19937 rng(17);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    const int floor_n = 4000, wall_n = 2000;
    const float r = std::sqrt(1.f / (float(M_PI) * floor_n));  // a sample's share of the floor
    const float sigma = 0.25f * std::sqrt(float(M_PI)) * r;    // a quarter sample spacing
    PointSet exact;
    for (int i = 0; i < floor_n + wall_n; ++i) {
        const bool floor = i < floor_n;
        exact.positions.push_back(floor ? Vec3{u(rng), 0, u(rng)} : Vec3{u(rng), 0.5f * u(rng), 1});
        exact.normals.push_back(floor ? Vec3{0, 1, 0} : Vec3{0, 0, -1});
        exact.radii.push_back(r);
    }
    PointSet rough = exact;
    std::normal_distribution<float> g(0.f, sigma);
    for (Vec3& p : rough.positions) p += Vec3{g(rng), g(rng), g(rng)};
    // Floor-wall point pairs, the same for each cloud.
    std::vector<std::pair<uint32_t, uint32_t>> pairs;
    for (int k = 0; k < 3000; ++k)
        pairs.push_back({uint32_t(rng() % floor_n), uint32_t(floor_n + rng() % wall_n)});
    auto visible_share = [&](PointSet ps, float roughness, bool packets) {
        std::vector<uint32_t> order;
        const Octree t = Octree::build(ps, {12, 1}, order);
        std::vector<uint32_t> at(order.size());
        for (uint32_t k = 0; k < order.size(); ++k) at[order[k]] = k;
        VisibilityParams vp;
        vp.roughness = roughness;
        const OctreeView v = octree_view(t);
        int visible = 0;
        for (const auto& [i, j] : pairs) {
            int32_t a = t.leaf_of_point(at[i]), b = t.leaf_of_point(at[j]);
            if (a > b) std::swap(a, b);
            WorkCounters wc;
            bool vis = detail::leaf_pair_visible<true>(v, a, b, vp, &wc);
            if (packets) {
                detail::SegmentPacket<32> pk;
                const bool live = pk.load(v, &a, &b, 1, vp, &wc) != 0;
                EXPECT_EQ(live && pk.walk(v, vp, &wc) != 0u, vis) << i << " " << j;
            }
            visible += vis;
        }
        return double(visible) / double(pairs.size());
    };
    const double exact_share = visible_share(exact, 0, false);
    const double noisy_share = visible_share(rough, 0, false);
    const double rough_share = visible_share(rough, float(kRoughnessSigmas) * sigma, true);
    EXPECT_GT(exact_share, 0.97);
    EXPECT_LT(noisy_share, exact_share - 0.05) << noisy_share;
    EXPECT_GT(rough_share, exact_share - 0.02) << noisy_share;
}

// The CPU backend's path into the packets: facing_mask over up to 16 columns of a row and
// facing_rows over 8 columns of two rows (the leaves by field), then packets of facing pairs
// only through load_faced, with every lane loop the CPU has (scalar, AVX2, AVX-512). Every pair
// of random trees, with and without end windows: the same facing pairs as pair_faces, and the
// answers, node tests and occluder tests of leaf_pair_visible.
TEST(PacketWalk, FacedPacketsAgreeWithTheLeafPairWalkOnEveryPairOfRandomScenes) {
    uint64_t faced = 0;
    for (uint32_t seed = 21; seed <= 34; ++seed) {
        const bool rough = seed > 30;  // noisy, with a roughness
        PointSet ps = random_scene(seed, 100 + int(seed) * 10);
        if (rough) ps = noisy(std::move(ps), seed);
        std::vector<uint32_t> order;
        const Octree t = Octree::build(ps, {int(5 + seed % 4), int(1 + seed % 3)}, order);
        const OctreeView v = octree_view(t);
        const detail::LeafColumns lc(v);
        SCOPED_TRACE(seed);
        for (float window : {0.f, 2.f}) {
            VisibilityParams vp;
            vp.K = int(1 + seed % 3);
            vp.end_window = window;
            vp.roughness = rough ? kNoisyRoughness : 0.f;
            // Every lane loop this CPU has (scalar, AVX2, AVX-512), each with its own counters.
            const int isas = detail::SegmentPacket<32>::best_isa() + 1;
            WorkCounters want, got[3];
            detail::SegmentPacket<32> pk;
            int32_t pa[32], pb[32];
            int count = 0;
            uint32_t expect = 0;
            auto flush = [&] {
                for (int isa = 0; isa < isas; ++isa) {
                    const uint32_t mask = pk.load_faced(v, pa, pb, count, vp, &got[isa], isa)
                                              ? pk.walk(v, vp, &got[isa], isa)
                                              : 0u;
                    ASSERT_EQ(mask, expect)
                        << "first pair " << pa[0] << " " << pb[0] << ", isa " << isa;
                }
                count = 0, expect = 0;
            };
            for (int32_t a = 0; a < v.num_leaves; ++a)
                for (int32_t b0 = a + 1; b0 < v.num_leaves; b0 += 16) {
                    const int n = std::min(16, v.num_leaves - b0 - int(a % 3));
                    if (n <= 0) continue;
                    const uint32_t m = detail::facing_mask(v, lc, a, b0, n, vp);
                    // Two rows at once (the backend's form), 8 columns: a and another row.
                    const int32_t a1 = int32_t((a * 7 + 3) % v.num_leaves);
                    const int n8 = std::min(n, 8);
                    const uint32_t m2 = detail::facing_rows(v, lc, a, a1, b0, n8, vp);
                    ASSERT_EQ(m2 & 0xffu, m & ((1u << n8) - 1)) << "rows " << a << " " << a1;
                    for (int i = 0; i < n8; ++i)
                        ASSERT_EQ(bool(m2 >> (8 + i) & 1u),
                                  a1 != b0 + i &&
                                      detail::pair_faces(v.leaves[a1], v.leaves[b0 + i], vp))
                            << "pair " << a1 << " " << b0 + i;
                    for (int i = 0; i < n; ++i) {
                        const int32_t b = b0 + i;
                        const bool faces = detail::pair_faces(v.leaves[a], v.leaves[b], vp);
                        ASSERT_EQ(bool(m >> i & 1u), faces) << "pair " << a << " " << b;
                        const bool vis = leaf_pair_visible<true>(v, a, b, vp, &want);
                        if (!faces) {
                            ASSERT_FALSE(vis);
                            continue;
                        }
                        if (vis) expect |= 1u << count;
                        pa[count] = a, pb[count] = b;
                        if (++count == 32) flush();
                    }
                }
            if (count > 0) flush();
            for (int isa = 0; isa < isas; ++isa) {
                EXPECT_EQ(got[isa].facing_pairs, want.facing_pairs) << "isa " << isa;
                EXPECT_EQ(got[isa].node_tests, want.node_tests) << "isa " << isa;
                EXPECT_EQ(got[isa].occluder_tests, want.occluder_tests) << "isa " << isa;
            }
            faced += want.facing_pairs;
        }
    }
    EXPECT_GT(faced, 100000u);
}

// A segment with a zero direction component that runs in a box's face (p.x == lo.x): the
// slab test takes that axis apart (no inverse), and so must the packet.
TEST(PacketWalk, SegmentInABoxFaceIsWalkedLikeTheLeafPairWalk) {
    std::vector<LeafDisc> leaves(3);
    leaves[0].centroid = {0, 0, 0}, leaves[0].normal = {0, 0, 1};
    leaves[1].centroid = {0, 0, 1}, leaves[1].normal = {0, 0, -1};
    leaves[2].centroid = {0, 0, 0.5f}, leaves[2].normal = {0, 0, 1}, leaves[2].delta = 0.1f;
    std::vector<WalkNode> walk(4);
    walk[0].lo = {0, -1, -1}, walk[0].hi = {1, 1, 2}, walk[0].skip = 4;  // the root
    for (int i = 0; i < 3; ++i) {
        const Vec3 c = leaves[size_t(i)].centroid;
        walk[size_t(i) + 1].lo = {0, c.y - 0.1f, c.z - 0.1f};
        walk[size_t(i) + 1].hi = {0.1f, c.y + 0.1f, c.z + 0.1f};
        walk[size_t(i) + 1].skip = i + 2;
        walk[size_t(i) + 1].leaf = i;
    }
    const OctreeView v{walk.data(), leaves.data(), 4, 3};
    VisibilityParams vp;
    vp.K = 1;
    WorkCounters want, got;
    ASSERT_FALSE(leaf_pair_visible<true>(v, 0, 1, vp, &want));  // the middle leaf hides it
    detail::SegmentPacket<4> pk;
    const int32_t a[2] = {0, 2}, b[2] = {1, 1};
    ASSERT_TRUE(pk.load(v, a, b, 2, vp, &got));
    ASSERT_TRUE(leaf_pair_visible<true>(v, 2, 1, vp, &want));
    EXPECT_EQ(pk.walk(v, vp, &got), 2u);
    EXPECT_EQ(got.node_tests, want.node_tests);
    EXPECT_EQ(got.occluder_tests, want.occluder_tests);
}

// The counting cases' tree (2000 bunny samples, height 7, 4 points a leaf) and leaf pairs.
Octree counting_tree() {
    PointSet ps = test::sample(test::scene_path("cornell-bunny"), 2000, 2);
    std::vector<uint32_t> order;
    return Octree::build(ps, {7, 4}, order);
}
std::vector<std::pair<int32_t, int32_t>> counting_pairs(int32_t num_leaves) {
    std::vector<std::pair<int32_t, int32_t>> pairs;
    for (int32_t a = 0; a < 50; ++a)
        for (int32_t b = a + 1; b < num_leaves; b += 7) pairs.push_back({a, b});
    return pairs;
}

TEST(Counting, CountedAndUncountedPredicatesAgree) {
    const Octree t = counting_tree();
    const OctreeView v = octree_view(t);
    VisibilityParams vp;
    WorkCounters wc;
    for (const auto& [a, b] : counting_pairs(v.num_leaves))
        ASSERT_EQ(leaf_pair_visible<true>(v, a, b, vp, &wc),
                  leaf_pair_visible<false>(v, a, b, vp, static_cast<WorkCounters*>(nullptr)));
    EXPECT_GT(wc.node_tests, wc.facing_pairs);
}

// The backend's work counts for a batch of pairs are the counted predicate's, pair by pair
// summed, and its answers the uncounted one's.
class Counting : public test::OnEachBackend {};

TEST_P(Counting, BackendCountsTheCountedPredicatesWork) {
    const Octree t = counting_tree();
    const OctreeView v = octree_view(t);
    VisibilityParams vp;
    const auto pairs = counting_pairs(v.num_leaves);
    WorkCounters want, got;
    const std::vector<bool> vis = visible_on(*leaf_pair_backend(), t, vp, pairs, &got);
    for (size_t i = 0; i < pairs.size(); ++i) {
        const auto [a, b] = pairs[i];
        leaf_pair_visible<true>(v, a, b, vp, &want);
        ASSERT_EQ(vis[i], leaf_pair_visible<false>(v, a, b, vp,
                                                   static_cast<WorkCounters*>(nullptr)))
            << a << " " << b;
    }
    EXPECT_EQ(got.pairs, pairs.size());
    EXPECT_EQ(got.facing_pairs, want.facing_pairs);
    EXPECT_EQ(got.node_tests, want.node_tests);
    EXPECT_EQ(got.occluder_tests, want.occluder_tests);
    EXPECT_GT(got.node_tests, got.facing_pairs);
}

VMAP_ON_EACH_BACKEND(Counting);

}  // namespace
}  // namespace vmap
