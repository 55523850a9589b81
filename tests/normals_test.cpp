// Normal estimation on seeded random samples of shapes whose true normals are known.

#include "vmap/normals.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "test_files.h"
#include "test_util.h"
#include "vmap/build_checks.h"
#include "vmap/error.h"
#include "vmap/io.h"
#include "vmap/render.h"
#include "vmap/scene.h"
#include "vmap/vmap.h"

namespace vmap {
namespace {

constexpr float kPi = 3.14159265358979f;

// Unit-length and finite, whatever else the test checks.
void expect_unit_normals(const PointSet& ps) {
    ASSERT_EQ(ps.normals.size(), ps.positions.size());
    for (size_t i = 0; i < ps.normals.size(); ++i) {
        ASSERT_TRUE(is_finite(ps.normals[i])) << "point " << i;
        ASSERT_NEAR(length(ps.normals[i]), 1.0f, 1e-5f) << "point " << i;
    }
}

Vec3 normalized(Vec3 v) { return v / length(v); }

float angle_deg(Vec3 a, Vec3 b) {
    const float c = std::fmin(1.0f, std::fmax(-1.0f, dot(normalized(a), normalized(b))));
    return std::acos(c) * 180.0f / kPi;
}

Vec3 random_unit(std::mt19937& rng) {
    std::normal_distribution<float> g(0.0f, 1.0f);
    for (;;) {
        const Vec3 v{g(rng), g(rng), g(rng)};
        if (length2(v) > 1e-6f) return normalized(v);
    }
}

void add_sphere(PointSet& ps, Vec3 centre, float radius, size_t n, std::mt19937& rng) {
    for (size_t i = 0; i < n; ++i) ps.positions.push_back(centre + radius * random_unit(rng));
}

PointSet sphere(Vec3 centre, float radius, size_t n, uint32_t seed) {
    std::mt19937 rng(seed);
    PointSet ps;
    add_sphere(ps, centre, radius, n, rng);
    return ps;
}

// Surface of the box [-h, h] (component-wise), sampled uniformly by area.
PointSet box_surface(Vec3 h, size_t n, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    const float areas[3] = {h.y * h.z, h.x * h.z, h.x * h.y};  // faces normal to x, y, z
    std::discrete_distribution<int> face(
        {areas[0], areas[0], areas[1], areas[1], areas[2], areas[2]});
    PointSet ps;
    for (size_t i = 0; i < n; ++i) {
        const int f = face(rng);
        const int axis = f / 2;
        const float side = (f % 2) ? 1.0f : -1.0f;
        Vec3 p{u(rng) * h.x, u(rng) * h.y, u(rng) * h.z};
        if (axis == 0) p.x = side * h.x;
        if (axis == 1) p.y = side * h.y;
        if (axis == 2) p.z = side * h.z;
        ps.positions.push_back(p);
    }
    return ps;
}

std::string error_of(PointSet ps, const NormalEstimationParams& params = {},
                     const char* source = "cloud.ply") {
    try {
        estimate_normals(ps, params, source);
    } catch (const Error& e) {
        return e.what();
    }
    return "(no error)";
}

bool starts_with(const std::string& s, const std::string& head) { return s.rfind(head, 0) == 0; }

// Checks that normals [begin, end) are the outward radii of a sphere about `centre`: none may
// point inward, and the angle to the radius stays within the given mean and maximum (degrees).
// Random samples make some k-NN neighbourhoods lopsided, so the worst case is a few times the
// mean.
void expect_radial(const PointSet& ps, Vec3 centre, size_t begin, size_t end, float mean_limit,
                   float max_limit) {
    size_t inward = 0;
    double sum = 0;
    float worst = 0;
    for (size_t i = begin; i < end; ++i) {
        const Vec3 radial = ps.positions[i] - centre;
        if (!(dot(ps.normals[i], radial) > 0)) ++inward;
        const float a = angle_deg(ps.normals[i], radial);
        sum += a;
        worst = std::fmax(worst, a);
    }
    EXPECT_EQ(inward, 0u) << "of points " << begin << ".." << end;
    EXPECT_LT(sum / double(end - begin), mean_limit) << "mean angle error, degrees";
    EXPECT_LT(worst, max_limit) << "largest angle error, degrees";
}

TEST(Normals, PlaneNormalsAreTheAxisWithOneSign) {
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    PointSet ps;
    for (int i = 0; i < 3000; ++i) ps.positions.push_back({u(rng), u(rng), 0.25f});
    estimate_normals(ps);
    expect_unit_normals(ps);
    const float sign = ps.normals[0].z > 0 ? 1.0f : -1.0f;
    for (size_t i = 0; i < ps.size(); ++i) {
        ASSERT_GT(sign * ps.normals[i].z, 0.9999f) << "point " << i;
    }
}

TEST(Normals, TiltedNoisyPlaneNormalsAgree) {
    std::mt19937 rng(2);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    std::normal_distribution<float> noise(0.0f, 0.001f);
    const Vec3 axis = normalized({1, 2, 3});
    const Vec3 e1 = normalized(cross(axis, {1, 0, 0}));
    const Vec3 e2 = cross(axis, e1);
    PointSet ps;
    for (int i = 0; i < 4000; ++i) {
        // Separate statements: the order of calls within one expression is unspecified.
        const float a = u(rng), b = u(rng), off = noise(rng);
        ps.positions.push_back(Vec3{5, -3, 7} + a * e1 + b * e2 + off * axis);
    }
    estimate_normals(ps);
    expect_unit_normals(ps);
    const float sign = dot(ps.normals[0], axis) > 0 ? 1.0f : -1.0f;
    for (size_t i = 0; i < ps.size(); ++i) {
        ASSERT_GT(sign * dot(ps.normals[i], axis), std::cos(10.0f * kPi / 180.0f)) << "point " << i;
    }
}

TEST(Normals, FineSamplingFarFromTheOriginIsASurface) {
    // 1 mm spacing 1 km from the origin: float rounding (0.06 mm there) must not be mistaken
    // for collinear neighbourhoods.
    std::mt19937 rng(17);
    std::uniform_real_distribution<float> u(0.0f, 0.05f);
    const Vec3 axis = normalized({0, 1, 1});
    PointSet ps;
    for (int i = 0; i < 2500; ++i) {
        const float a = u(rng), b = u(rng);
        ps.positions.push_back(Vec3{1000, 1000, -1000} + Vec3{a, b, -b});
    }
    estimate_normals(ps);
    expect_unit_normals(ps);
    const float sign = dot(ps.normals[0], axis) > 0 ? 1.0f : -1.0f;
    for (size_t i = 0; i < ps.size(); ++i) {
        ASSERT_LT(angle_deg(sign * ps.normals[i], axis), 15.0f) << "point " << i;
    }
}

TEST(Normals, SphereNormalsPointOutward) {
    const Vec3 c{0.5f, -1.0f, 2.0f};
    PointSet ps = sphere(c, 1.5f, 20000, 3);
    estimate_normals(ps);
    expect_unit_normals(ps);
    expect_radial(ps, c, 0, ps.size(), 1.0f, 5.0f);
}

TEST(Normals, SphereWithLargerNeighbourhoodsStaysOutward) {
    const Vec3 c{0, 0, 0};
    PointSet ps = sphere(c, 1.0f, 20000, 4);
    NormalEstimationParams params;
    params.k = 30;
    estimate_normals(ps, params);
    expect_unit_normals(ps);
    expect_radial(ps, c, 0, ps.size(), 1.0f, 5.0f);
}

// Box with half-extents h, sampled uniformly over its surface; returns the outward normal of
// the face each sample lies on.
std::vector<Vec3> face_normals(const PointSet& ps, Vec3 h) {
    std::vector<Vec3> out;
    for (const Vec3& p : ps.positions) {
        Vec3 n{0, 0, 0};
        if (std::fabs(p.x) == h.x) n = {p.x > 0 ? 1.0f : -1.0f, 0, 0};
        if (std::fabs(p.y) == h.y) n = {0, p.y > 0 ? 1.0f : -1.0f, 0};
        if (std::fabs(p.z) == h.z) n = {0, 0, p.z > 0 ? 1.0f : -1.0f};
        out.push_back(n);
    }
    return out;
}

bool near_an_edge(Vec3 p, Vec3 h, float margin) {
    int close = 0;  // coordinates at or near their face; two make an edge
    close += h.x - std::fabs(p.x) < margin;
    close += h.y - std::fabs(p.y) < margin;
    close += h.z - std::fabs(p.z) < margin;
    return close >= 2;
}

TEST(Normals, BoxNormalsPointOutwardAndFacesHaveAxisNormals) {
    const Vec3 h{1.0f, 0.6f, 0.8f};
    PointSet ps = box_surface(h, 20000, 5);
    estimate_normals(ps);
    expect_unit_normals(ps);
    const std::vector<Vec3> face = face_normals(ps, h);
    const float margin = 0.1f;  // k = 12 neighbourhoods here are about 0.05 across
    size_t inside_faces = 0, inward = 0;
    for (size_t i = 0; i < ps.size(); ++i) {
        ASSERT_NE(length(face[i]), 0.0f);
        if (!(dot(ps.normals[i], ps.positions[i]) > 0)) ++inward;
        if (near_an_edge(ps.positions[i], h, margin)) continue;
        ++inside_faces;
        ASSERT_GT(dot(ps.normals[i], face[i]), std::cos(2.0f * kPi / 180.0f)) << "point " << i;
    }
    EXPECT_GT(inside_faces, ps.size() / 2);
    // A handful of samples right at an edge get an unlucky neighbourhood whose plane fit runs
    // along the edge, half way between the faces; their sign is then a coin toss (7 of 20000
    // with the free-space rule). Everything else must point out.
    EXPECT_LE(inward, ps.size() / 2000);
}

TEST(Normals, BoxNormalsAllPointOutwardWithLargerNeighbourhoods) {
    const Vec3 h{1.0f, 0.6f, 0.8f};
    PointSet ps = box_surface(h, 20000, 5);
    NormalEstimationParams params;
    params.k = 20;
    estimate_normals(ps, params);
    expect_unit_normals(ps);
    const std::vector<Vec3> face = face_normals(ps, h);
    for (size_t i = 0; i < ps.size(); ++i) {
        ASSERT_GT(dot(ps.normals[i], ps.positions[i]), 0.0f) << "point " << i;
        // Right at an edge (within 0.4 of the 27 mm spacing) the fit may take either face's plane.
        if (!near_an_edge(ps.positions[i], h, 0.01f)) {
            ASSERT_GT(dot(ps.normals[i], face[i]), 0.0f) << "point " << i;
        }
    }
}

TEST(Normals, TwoSeparateSpheresAreBothOrientedOutward) {
    std::mt19937 rng(6);
    PointSet ps;
    const Vec3 c1{-3, 0, 0}, c2{2, 1, 0.5f};
    add_sphere(ps, c1, 1.0f, 12000, rng);
    add_sphere(ps, c2, 0.7f, 8000, rng);
    estimate_normals(ps);
    expect_unit_normals(ps);
    expect_radial(ps, c1, 0, 12000, 1.0f, 5.0f);
    expect_radial(ps, c2, 12000, 20000, 1.0f, 5.0f);
}

TEST(Normals, ABallInsideASphereIsARoomWithAnObject) {
    // The region between the spheres lies two levels from the outside with the ball's inside
    // below it and is the larger: free space, as a room's air around an object. So the outer
    // sphere faces inward (a room's walls) and the inner one outward.
    PointSet ps = sphere({0, 0, 0}, 2.0f, 20000, 7);
    std::mt19937 rng(8);
    add_sphere(ps, {0, 0, 0}, 1.0f, 8000, rng);
    OrientationReport rep;
    estimate_normals(ps, {}, "nested", &rep);
    expect_unit_normals(ps);
    for (size_t i = 0; i < 20000; ++i) ps.normals[i] = -ps.normals[i];
    expect_radial(ps, {0, 0, 0}, 0, ps.size(), 1.0f, 5.0f);
    EXPECT_NE(rep.method.find("room"), std::string::npos) << rep.method;
}

TEST(Normals, DuplicatePointsAreFine) {
    // Every third sample twice: neighbourhoods hold fewer distinct points, so fits are a little
    // noisier, but nothing breaks.
    const Vec3 c{1, 2, 3};
    PointSet ps = sphere(c, 1.0f, 10000, 9);
    for (size_t i = 0; i < 10000; i += 3) ps.positions.push_back(ps.positions[i]);
    estimate_normals(ps);
    expect_unit_normals(ps);
    expect_radial(ps, c, 0, ps.size(), 1.5f, 6.0f);
}

TEST(Normals, CoincidentClusterTakesItsNeighboursNormal) {
    // 40 copies of one sample: each copy's 12 nearest neighbours are all copies, so it has no
    // plane of its own, but its neighbours on the sphere link it to the tree.
    const Vec3 c{0, 0, 0};
    PointSet ps = sphere(c, 1.0f, 10000, 10);
    const Vec3 spot = ps.positions[17];
    for (int i = 0; i < 40; ++i) ps.positions.push_back(spot);
    estimate_normals(ps);
    expect_unit_normals(ps);
    expect_radial(ps, c, 0, 10000, 1.0f, 6.0f);
    for (size_t i = 10000; i < ps.size(); ++i) {
        EXPECT_GT(dot(ps.normals[i], spot - c), 0.99f) << "copy " << i;
    }
}

TEST(Normals, IsolatedCoincidentPointsPointAwayFromTheCentroid) {
    // Every sample repeated 15 times with k = 12: no point has a plane and every cluster of
    // copies is its own component, so all fall back to the away-from-centroid direction.
    const Vec3 c{0, 0, 0};
    const PointSet base = sphere(c, 1.0f, 200, 11);
    PointSet ps;
    for (const Vec3& p : base.positions)
        for (int r = 0; r < 15; ++r) ps.positions.push_back(p);
    estimate_normals(ps);
    expect_unit_normals(ps);
    Vec3 centroid{0, 0, 0};
    for (const Vec3& p : base.positions) centroid += p / 200.0f;
    for (size_t i = 0; i < ps.size(); ++i) {
        ASSERT_LT(angle_deg(ps.normals[i], ps.positions[i] - centroid), 0.1f) << "point " << i;
    }
}

TEST(Normals, FewPointsAndSmallK) {
    PointSet ps;
    ps.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    estimate_normals(ps);  // k larger than the cloud
    expect_unit_normals(ps);
    for (const Vec3& n : ps.normals) EXPECT_NEAR(std::fabs(n.z), 1.0f, 1e-6f);
    EXPECT_EQ(ps.normals[0], ps.normals[1]);
    EXPECT_EQ(ps.normals[0], ps.normals[2]);
}

TEST(Normals, ExistingNormalsAreReplaced) {
    PointSet ps = sphere({0, 0, 0}, 1.0f, 500, 12);
    ps.normals.assign(ps.size(), Vec3{0, 0, 0});
    estimate_normals(ps);
    expect_unit_normals(ps);
}

TEST(Normals, ResultDoesNotDependOnThreadCount) {
    PointSet base = box_surface({1.0f, 0.5f, 0.7f}, 30000, 13);
    std::mt19937 rng(14);
    add_sphere(base, {4, 0, 0}, 1.0f, 20000, rng);
    std::vector<Vec3> first;
    for (const int threads : {1, 2, 8}) {
        // The global limit alone only caps the default arena, which has as many slots as the
        // machine has cores; an arena of its own makes 8 threads really run on a small machine.
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
        tbb::task_arena arena(threads);
        PointSet ps = base;
        arena.execute([&] { estimate_normals(ps); });
        if (first.empty()) {
            first = ps.normals;
            continue;
        }
        ASSERT_EQ(ps.normals.size(), first.size());
        for (size_t i = 0; i < first.size(); ++i) {
            ASSERT_EQ(ps.normals[i], first[i])
                << "point " << i << " with " << threads << " threads";
        }
    }
}

TEST(Normals, TooFewPointsIsAnError) {
    PointSet ps;
    ps.positions = {{0, 0, 0}, {1, 0, 0}};
    EXPECT_EQ(error_of(ps), "cloud.ply: normal estimation needs at least 3 points, got 2");
    EXPECT_EQ(error_of(PointSet{}), "cloud.ply: normal estimation needs at least 3 points, got 0");
}

TEST(Normals, NonFiniteCoordinateIsAnErrorNamingThePoint) {
    PointSet ps = sphere({0, 0, 0}, 1.0f, 100, 15);
    ps.positions[42].y = std::numeric_limits<float>::quiet_NaN();
    std::string msg = error_of(ps);
    EXPECT_TRUE(starts_with(msg, "cloud.ply: ")) << msg;
    EXPECT_NE(msg.find("point 42 "), std::string::npos) << msg;
    EXPECT_NE(msg.find("non-finite"), std::string::npos) << msg;

    ps.positions[42].y = 0;
    ps.positions[7].z = -std::numeric_limits<float>::infinity();
    msg = error_of(ps, {}, "scan.xyz");
    EXPECT_TRUE(starts_with(msg, "scan.xyz: ")) << msg;
    EXPECT_NE(msg.find("point 7 "), std::string::npos) << msg;
}

TEST(Normals, CoincidentPointsAreAnError) {
    PointSet ps;
    ps.positions.assign(50, Vec3{1, 2, 3});
    const std::string msg = error_of(ps);
    EXPECT_TRUE(starts_with(msg, "cloud.ply: ")) << msg;
    EXPECT_NE(msg.find("coincide"), std::string::npos) << msg;
    EXPECT_NE(msg.find("no plane"), std::string::npos) << msg;
    EXPECT_NE(msg.find("supply normals"), std::string::npos) << msg;
}

TEST(Normals, CollinearPointsAreAnError) {
    PointSet ps;
    const Vec3 dir = normalized({1, -2, 0.5f});
    for (int i = 0; i < 100; ++i)
        ps.positions.push_back(Vec3{10, 20, 30} + (0.37f * float(i)) * dir);
    ps.positions.push_back(ps.positions[5]);  // a duplicate changes nothing
    const std::string msg = error_of(ps);
    EXPECT_TRUE(starts_with(msg, "cloud.ply: ")) << msg;
    EXPECT_NE(msg.find("collinear"), std::string::npos) << msg;
    EXPECT_NE(msg.find("no plane"), std::string::npos) << msg;
    EXPECT_NE(msg.find("supply normals"), std::string::npos) << msg;

    // On an axis-aligned line, where the coordinates hold no rounding at all.
    PointSet axis_line;
    for (int i = 0; i < 10; ++i) axis_line.positions.push_back({float(i), 0, 0});
    EXPECT_NE(error_of(axis_line).find("collinear"), std::string::npos);

    // One point off the line makes a plane.
    ps.positions.push_back(Vec3{10, 20, 31});
    EXPECT_EQ(error_of(ps), "(no error)");
}

TEST(Normals, BadNeighbourCountIsAnError) {
    const PointSet ps = sphere({0, 0, 0}, 1.0f, 100, 16);
    for (const size_t k : {size_t(0), size_t(2), size_t(1001), size_t(1) << 40}) {
        NormalEstimationParams params;
        params.k = k;
        const std::string msg = error_of(ps, params, "bunny.ply");
        EXPECT_TRUE(starts_with(msg, "bunny.ply: ")) << msg;
        EXPECT_NE(msg.find("k "), std::string::npos) << msg;
        EXPECT_NE(msg.find(std::to_string(k)), std::string::npos) << msg;
    }
    NormalEstimationParams params;
    params.k = 3;
    EXPECT_EQ(error_of(ps, params), "(no error)");
}

// ---- orientation: rooms, objects, thin parts, viewpoints -------------------------------------

// Uniform samples of the rectangle corner + u a + v b (u, v in [0, 1]) with normal n.
void add_rect(PointSet& ps, std::vector<Vec3>& truth, Vec3 corner, Vec3 a, Vec3 b, Vec3 n,
              size_t count, std::mt19937& rng) {
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    for (size_t i = 0; i < count; ++i) {
        ps.positions.push_back(corner + a * u(rng) + b * u(rng));
        truth.push_back(n);
    }
}

// A unit-cube room seen from inside: floor, ceiling, four walls (the front z = 0 left open
// when `open`), true normals facing into the room. About n points a square metre.
PointSet room(bool open, std::vector<Vec3>& truth, uint32_t seed, size_t n = 1500) {
    std::mt19937 rng(seed);
    PointSet ps;
    add_rect(ps, truth, {0, 0, 0}, {1, 0, 0}, {0, 0, 1}, {0, 1, 0}, n, rng);   // floor
    add_rect(ps, truth, {0, 1, 0}, {1, 0, 0}, {0, 0, 1}, {0, -1, 0}, n, rng);  // ceiling
    add_rect(ps, truth, {0, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 0}, n, rng);   // x = 0
    add_rect(ps, truth, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {-1, 0, 0}, n, rng);  // x = 1
    add_rect(ps, truth, {0, 0, 1}, {1, 0, 0}, {0, 1, 0}, {0, 0, -1}, n, rng);  // back
    if (!open) add_rect(ps, truth, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, n, rng);
    return ps;
}

void add_ball(PointSet& ps, std::vector<Vec3>& truth, Vec3 c, float r, size_t n, uint32_t seed) {
    std::mt19937 rng(seed);
    for (size_t i = 0; i < n; ++i) {
        const Vec3 d = random_unit(rng);
        ps.positions.push_back(c + r * d);
        truth.push_back(d);
    }
}

// Share of points [begin, end) whose normal has the sign of the true one.
double share_right(const PointSet& ps, const std::vector<Vec3>& truth, size_t begin, size_t end) {
    size_t right = 0;
    for (size_t i = begin; i < end; ++i) right += dot(ps.normals[i], truth[i]) > 0;
    return double(right) / double(end - begin);
}

TEST(Orientation, OpenRoomScannedFromInsideFacesInward) {
    std::vector<Vec3> truth;
    PointSet ps = room(true, truth, 21);
    estimate_normals(ps);
    expect_unit_normals(ps);
    EXPECT_GT(share_right(ps, truth, 0, ps.size()), 0.995);
}

// A scan's shadows: a table top scanned from above only (a bare sheet of points; the scanner on
// a tripod beside it, higher), and the floor and walls less what the table hid from the
// scanner. Rays from the sheet's lower, unseen side slip through those holes; they count as
// meeting nothing seen (as behind a wall), not as travelling into open space, so the sheet faces
// up, toward the scanner. (Escaping through the holes into open space, the lower side won.)
TEST(Orientation, ASheetScannedFromOneSideFacesAwayFromItsShadow) {
    std::mt19937 rng(41);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    const Vec3 scanner{0.15f, 0.7f, 0.45f};
    const float table = 0.4f;
    auto shadowed = [&](Vec3 p) {
        if (!(p.y < table)) return false;
        const Vec3 q = scanner + (p - scanner) * ((scanner.y - table) / (scanner.y - p.y));
        return q.x > 0.3f && q.x < 0.7f && q.z > 0.3f && q.z < 0.7f;
    };
    PointSet ps;
    std::vector<Vec3> truth;
    auto add = [&](Vec3 p, Vec3 n) {
        if (shadowed(p)) return;
        ps.positions.push_back(p);
        truth.push_back(n);
    };
    for (size_t i = 0; i < 3000; ++i) {
        add({u(rng), 0, u(rng)}, {0, 1, 0});   // floor
        add({u(rng), 1, u(rng)}, {0, -1, 0});  // ceiling
        add({0, u(rng), u(rng)}, {1, 0, 0});   // x = 0
        add({1, u(rng), u(rng)}, {-1, 0, 0});
        add({u(rng), u(rng), 1}, {0, 0, -1});  // back; the front z = 0 is open
    }
    const size_t sheet = ps.size();
    for (size_t i = 0; i < 1200; ++i)
        add({0.3f + 0.4f * u(rng), table, 0.3f + 0.4f * u(rng)}, {0, 1, 0});
    estimate_normals(ps);
    EXPECT_GT(share_right(ps, truth, sheet, ps.size()), 0.95);
    EXPECT_GT(share_right(ps, truth, 0, sheet), 0.99);  // the room stays right
}

// What a scanner on a tripod records: beams on an equal-angle grid (elevation and azimuth in
// steps of `step` degrees) from `at`, each keeping its first hit among the room's walls
// (x, y in [0, 1], the back z = 1; the front z = 0 open; only with `walls`) and a trough: half
// a cylinder along x (radius 0.15, axis at y = 0.35, z = 0.7, x in [0.2, 0.8]), its open side
// toward the scanner, so that the scanner sees only its concave inside. truth: the side hit,
// toward the scanner. trough_begin: where the trough's points start (they come last).
struct Scanned {
    PointSet points;
    std::vector<Vec3> truth;
    size_t trough_begin = 0;
};

// Calls f(d) for each beam direction of an equal-angle scanner turning about y, `step` degrees
// apart in elevation (poles left out) and azimuth.
template <class F>
void for_each_beam(float step, F&& f) {
    constexpr float kPi = 3.14159265f;
    const int rows = int(180 / step), cols = int(360 / step);
    for (int i = 1; i < rows; ++i) {
        const float el = (-90 + step * float(i)) * kPi / 180;
        for (int j = 0; j < cols; ++j) {
            const float az = step * float(j) * kPi / 180;
            f(Vec3{std::cos(el) * std::cos(az), std::sin(el), std::cos(el) * std::sin(az)});
        }
    }
}

Scanned scan_trough(Vec3 at, float step, bool walls) {
    constexpr float r = 0.15f, yc = 0.35f, zc = 0.7f;
    Scanned out;
    std::vector<Vec3> tp, tn;
    for_each_beam(step, [&](Vec3 d) {
        float best = std::numeric_limits<float>::max();
        Vec3 n{};
        bool trough = false;
        if (walls) {
            const float o[3] = {at.x, at.y, at.z}, v[3] = {d.x, d.y, d.z};
            for (int a = 0; a < 3; ++a)
                for (const float plane : {0.0f, 1.0f}) {
                    if (a == 2 && plane == 0) continue;  // the open front
                    const float t = v[a] != 0 ? (plane - o[a]) / v[a] : -1;
                    const Vec3 p = at + d * t;
                    const float e = 1e-4f;  // the walls end at the room's edges
                    if (!(t > 0 && t < best) || p.x < -e || p.x > 1 + e || p.y < -e ||
                        p.y > 1 + e || p.z < -e || p.z > 1 + e)
                        continue;
                    best = t;
                    n = {a == 0 ? (plane == 0 ? 1.f : -1.f) : 0.f,
                         a == 1 ? (plane == 0 ? 1.f : -1.f) : 0.f, a == 2 ? -1.f : 0.f};
                }
        }
        // (at.y + t d.y - yc)^2 + (at.z + t d.z - zc)^2 = r^2
        const float py = at.y - yc, pz = at.z - zc;
        const float qa = d.y * d.y + d.z * d.z, qb = 2 * (py * d.y + pz * d.z),
                    qc = py * py + pz * pz - r * r, disc = qb * qb - 4 * qa * qc;
        if (qa > 0 && disc >= 0)
            for (const float sg : {-1.0f, 1.0f}) {
                const float t = (-qb + sg * std::sqrt(disc)) / (2 * qa);
                const Vec3 p = at + d * t;
                if (!(t > 0 && t < best) || p.x < 0.2f || p.x > 0.8f || p.z < zc) continue;
                best = t;
                n = Vec3{0, yc - p.y, zc - p.z} / r;  // the inside, which the scanner sees
                trough = true;
            }
        if (best == std::numeric_limits<float>::max()) return;
        const Vec3 p = at + d * best;
        (trough ? tp : out.points.positions).push_back(p);
        (trough ? tn : out.truth).push_back(n);
    });
    out.trough_begin = out.points.size();
    out.points.positions.insert(out.points.positions.end(), tp.begin(), tp.end());
    out.truth.insert(out.truth.end(), tn.begin(), tn.end());
    return out;
}

// A scan from inside a room: the place that sees the most points stands in for the scanner
// (whose position the file does not give), and a sheet scanned from one side takes the side
// that place sees. The trough's concave inside, which the shape rule (face away from what the
// sheet wraps around) turns outward: none of it right without the view.
TEST(Orientation, AScanFromInsideARoomFacesWhereItsScannerStood) {
    Scanned scan = scan_trough({0.5f, 0.6f, 0.3f}, 1.5f, true);
    ASSERT_GT(scan.points.size() - scan.trough_begin, 500u);
    OrientationReport rep;
    estimate_normals(scan.points, {}, "scan", &rep);
    EXPECT_GT(rep.by_view, scan.points.size() / 2);
    EXPECT_NE(rep.method.find("a scan from inside a room"), std::string::npos) << rep.method;
    // In the room, in front of the trough's opening (it sees the inside).
    ASSERT_TRUE(rep.scanner.has_value());
    EXPECT_TRUE(rep.scanner->x > 0 && rep.scanner->x < 1 && rep.scanner->y > 0 &&
                rep.scanner->y < 1 && rep.scanner->z < 0.7f)
        << rep.scanner->x << " " << rep.scanner->y << " " << rep.scanner->z;
    EXPECT_GT(share_right(scan.points, scan.truth, scan.trough_begin, scan.points.size()), 0.95);
    EXPECT_GT(share_right(scan.points, scan.truth, 0, scan.trough_begin), 0.99);
    // The view's search counts and chooses the same on one thread.
    PointSet one = scan.points;
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    tbb::task_arena arena(1);
    arena.execute([&] { estimate_normals(one); });
    for (size_t i = 0; i < one.size(); ++i) ASSERT_EQ(one.normals[i], scan.points.normals[i]) << i;
}

// An equal-angle scan (turning about y, steps of `step` degrees) from `at` of a lone bowl: the
// far half (z >= 0.7) of a sphere of radius 0.15 about (0.5, 0.35, 0.7), its inside seen.
Scanned scan_bowl(Vec3 at, float step) {
    constexpr float r = 0.15f;
    const Vec3 c{0.5f, 0.35f, 0.7f};
    Scanned out;
    for_each_beam(step, [&](Vec3 d) {
        const Vec3 o = at - c;
        const float qb = 2 * dot(o, d), qc = dot(o, o) - r * r, disc = qb * qb - 4 * qc;
        if (disc < 0) return;
        for (const float sg : {-1.0f, 1.0f}) {
            const float t = (-qb + sg * std::sqrt(disc)) / 2;
            const Vec3 p = at + d * t;
            if (!(t > 0) || p.z < c.z) continue;
            out.points.positions.push_back(p);
            out.truth.push_back((c - p) / r);  // the inside, which the scanner sees
            break;
        }
    });
    return out;
}

// A scan of a lone object from one side: no room fixes where the scanner stood, but the
// spacing does (an equal-angle scanner's patch grows with range and slant, shrinks toward the
// poles of its turning axis). The trough's concave inside, which the shape rule turns outward.
TEST(Orientation, ALoneScanFacesWhereItsSpacingShowsItsScannerStood) {
    const Vec3 at{0.5f, 0.6f, 0.3f};
    Scanned scan = scan_bowl(at, 0.5f);
    ASSERT_GT(scan.points.size(), 500u);
    OrientationReport rep;
    estimate_normals(scan.points, {}, "lone scan", &rep);
    EXPECT_GT(share_right(scan.points, scan.truth, 0, scan.points.size()), 0.95);
    EXPECT_NE(rep.method.find("by the points' spacing (turning axis: y)"), std::string::npos)
        << rep.method;
    ASSERT_EQ(rep.scanners.size(), 1u) << rep.method;
    EXPECT_LT(length(rep.scanners[0] - at), 0.01f)
        << rep.scanners[0].x << " " << rep.scanners[0].y << " " << rep.scanners[0].z;
}

// The same with a scan's noise (a quarter of the beams' spacing on the bowl, per axis): the radii
// scatter as well, the residuals' peak widens with the measured noise, and the place is still
// found.
TEST(Orientation, ANoisyLoneScanStillShowsWhereItsScannerStood) {
    const Vec3 at{0.5f, 0.6f, 0.3f};
    Scanned scan = scan_bowl(at, 0.5f);
    std::mt19937 rng(9);
    std::normal_distribution<float> g(0.0f, 0.25f * 0.45f * 0.5f * 3.14159265f / 180);
    for (Vec3& p : scan.points.positions) p = p + Vec3{g(rng), g(rng), g(rng)};
    OrientationReport rep;
    estimate_normals(scan.points, {}, "noisy lone scan", &rep);
    EXPECT_GT(share_right(scan.points, scan.truth, 0, scan.points.size()), 0.95);
    ASSERT_EQ(rep.scanners.size(), 1u) << rep.method;
    EXPECT_LT(length(rep.scanners[0] - at), 0.05f)
        << rep.scanners[0].x << " " << rep.scanners[0].y << " " << rep.scanners[0].z;
}

// Not a scan from inside a room: the trough scanned without a room around it (the most-seen
// place does not fix where its scanner stood: a sheet looks the same from either side; only
// the spacing may), and the room and the trough sampled at random (a sampler's spacing, which
// follows no place's range and slant). Neither the view nor a scanner signs the samples.
TEST(Orientation, OnlyAScanFromInsideARoomIsSignedByWhereItsScannerStood) {
    Scanned scan = scan_trough({0.5f, 0.6f, 0.3f}, 1.5f, false);
    ASSERT_GT(scan.points.size(), 500u);
    OrientationReport rep;
    estimate_normals(scan.points, {}, "lone scan", &rep);
    EXPECT_FALSE(rep.scanner.has_value()) << rep.method;

    std::vector<Vec3> truth;
    PointSet even = room(true, truth, 43, 3000);
    std::mt19937 rng(44);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    for (int i = 0; i < 2000; ++i) {
        const float a = 3.14159265f * u(rng), x = 0.2f + 0.6f * u(rng);
        even.positions.push_back({x, 0.35f + 0.15f * std::cos(a), 0.7f + 0.15f * std::sin(a)});
        truth.push_back({0, std::cos(a), std::sin(a)});  // the winding: outward
    }
    estimate_normals(even, {}, "samples", &rep);
    EXPECT_EQ(rep.by_view, 0u) << rep.method;
    EXPECT_TRUE(rep.scanners.empty()) << rep.method;
}

TEST(Orientation, AFewPointsOutsideTheRoomDoNotTurnItsWalls) {
    // A small speck of points beyond a corner of an open room (a stray return past a window, a
    // registration outlier) pushes the cloud's bounds out on three sides. The walls there no
    // longer lay on the bounds, their outer sides' rays travelled to the far bounds and won,
    // and they turned outward (ceiling, back and side wall 1-3% right). The room's box now
    // stops at its outermost walls when only a few points lie beyond them (wall_box).
    std::vector<Vec3> truth;
    PointSet ps = room(true, truth, 23);
    const size_t walls = ps.size();
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(1.2f, 1.23f);
    for (int i = 0; i < 40; ++i) {  // 0.5% of the points, 20 cm past the corner (1, 1, 1)
        ps.positions.push_back({u(rng), u(rng), u(rng)});
        truth.push_back({1, 0, 0});
    }
    estimate_normals(ps);
    EXPECT_GT(share_right(ps, truth, 0, walls), 0.99);
}

TEST(Orientation, TurnedRoomStillFacesInward) {
    // A scan is not aligned with the axes: the rays' bounding box follows the walls' normals.
    std::vector<Vec3> truth;
    PointSet ps = room(true, truth, 37);
    const float a = 0.5f, b = 0.35f;  // radians about y, then about x
    auto turn = [&](Vec3 v) {
        const Vec3 w{std::cos(a) * v.x + std::sin(a) * v.z, v.y,
                     -std::sin(a) * v.x + std::cos(a) * v.z};
        return Vec3{w.x, std::cos(b) * w.y - std::sin(b) * w.z,
                    std::sin(b) * w.y + std::cos(b) * w.z};
    };
    for (Vec3& p : ps.positions) p = turn(p);
    for (Vec3& n : truth) n = turn(n);
    estimate_normals(ps);
    EXPECT_GT(share_right(ps, truth, 0, ps.size()), 0.995);
}

TEST(Orientation, RoomResultDoesNotDependOnThreadCount) {
    // An open room with a ball: the voxel regions, the rays and the neighbour votes all run.
    std::vector<Vec3> truth;
    PointSet base = room(true, truth, 38);
    add_ball(base, truth, {0.5f, 0.25f, 0.6f}, 0.2f, 2000, 39);
    std::vector<Vec3> first;
    for (const int threads : {1, 8}) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
        tbb::task_arena arena(threads);
        PointSet ps = base;
        arena.execute([&] {
            estimate_normals(ps);
            estimate_radii(ps);
        });
        if (first.empty()) {
            first = ps.normals;
            first.insert(first.end(), ps.radii.size(), Vec3{});
            for (size_t i = 0; i < ps.radii.size(); ++i) first[ps.size() + i].x = ps.radii[i];
            continue;
        }
        for (size_t i = 0; i < ps.size(); ++i) {
            ASSERT_EQ(ps.normals[i], first[i]) << "point " << i;
            ASSERT_EQ(ps.radii[i], first[ps.size() + i].x) << "point " << i;
        }
    }
}

TEST(Orientation, ClosedRoomWithABallFacesIntoTheRoomAndTheBallOutward) {
    std::vector<Vec3> truth;
    PointSet ps = room(false, truth, 22);
    const size_t walls = ps.size();
    add_ball(ps, truth, {0.5f, 0.3f, 0.5f}, 0.15f, 1500, 23);
    OrientationReport rep;
    estimate_normals(ps, {}, "room", &rep);
    EXPECT_GT(share_right(ps, truth, 0, walls), 0.995);
    EXPECT_GT(share_right(ps, truth, walls, ps.size()), 0.99);
    EXPECT_NE(rep.method.find("room"), std::string::npos) << rep.method;
    EXPECT_GT(rep.by_space, ps.size() / 2);
}

// A hollow ball: a closed outer wall facing out and, nested inside it with a gap thinner than
// the voxel grid's cell (5-25 mm against about 26 mm), an inner wall facing into the cavity. The
// voxel probes walk through the gap, so the cavity first counted as solid and the whole inner
// wall faced the gap (test-open-hollow's inner shell: 0% right); the rays settle most of it.
TEST(Orientation, AHollowBallsInnerWallFacesItsCavity) {
    std::vector<Vec3> truth;
    PointSet ps = room(true, truth, 27);
    const size_t walls = ps.size();
    add_ball(ps, truth, {0.5f, 0.3f, 0.5f}, 0.2f, 2500, 28);
    const size_t outer = ps.size();
    add_ball(ps, truth, {0.5f, 0.31f, 0.5f}, 0.185f, 2200, 29);
    for (size_t i = outer; i < ps.size(); ++i) truth[i] = -truth[i];
    OrientationReport rep;
    estimate_normals(ps, {}, "hollow", &rep);
    EXPECT_GT(share_right(ps, truth, 0, walls), 0.99);
    EXPECT_GT(share_right(ps, truth, walls, outer), 0.99);
    // 81% at this commit, 0.5% without the stacked-verdict rule: the spread of the votes from
    // the outer wall across the gap keeps some of the rest.
    EXPECT_GT(share_right(ps, truth, outer, ps.size()), 0.75);
    EXPECT_NE(rep.method.find("inner wall"), std::string::npos) << rep.method;
}

TEST(Orientation, ObjectStandingInAnOpenRoomFacesOutward) {
    std::vector<Vec3> truth;
    PointSet ps = room(true, truth, 24);
    const size_t walls = ps.size();
    add_ball(ps, truth, {0.5f, 0.25f, 0.6f}, 0.2f, 2000, 25);
    estimate_normals(ps);
    EXPECT_GT(share_right(ps, truth, 0, walls), 0.99);
    EXPECT_GT(share_right(ps, truth, walls, ps.size()), 0.99);
}

TEST(Orientation, LoneClosedObjectFacesOutwardByFreeSpace) {
    std::vector<Vec3> truth;
    PointSet ps;
    add_ball(ps, truth, {3, 2, 1}, 0.5f, 6000, 26);
    OrientationReport rep;
    estimate_normals(ps, {}, "ball", &rep);
    EXPECT_EQ(share_right(ps, truth, 0, ps.size()), 1.0);
    EXPECT_NE(rep.method.find("outward"), std::string::npos) << rep.method;
    EXPECT_EQ(rep.by_space, ps.size());
}

TEST(Orientation, ThinPlateInARoomHasBothFacesOutward) {
    // A 3 mm plate (0.4 x 0.3 m) floating in the room, its faces sampled with a spacing of
    // about 8 mm: closer than that, so the plane fits mix them.
    std::vector<Vec3> truth;
    PointSet ps = room(true, truth, 27);
    const size_t walls = ps.size();
    std::mt19937 rng(28);
    add_rect(ps, truth, {0.3f, 0.4f, 0.3f}, {0.4f, 0, 0}, {0, 0, 0.3f}, {0, -1, 0}, 1600, rng);
    add_rect(ps, truth, {0.3f, 0.403f, 0.3f}, {0.4f, 0, 0}, {0, 0, 0.3f}, {0, 1, 0}, 1600, rng);
    estimate_normals(ps);
    EXPECT_GT(share_right(ps, truth, 0, walls), 0.99);
    EXPECT_GT(share_right(ps, truth, walls, ps.size()), 0.95);
}

TEST(Orientation, AWallBehindAnObjectAFewMillimetresAwayFacesTheRoom) {
    // A ball 3 mm in front of the x = 0 wall: the gap is far below one grid cell, so the probe
    // from the wall into the room crosses occupied cells into the ball's solid. The free side
    // beyond the wall is only the padding outside the bounding box, which is no evidence; the
    // wall there faces the room (the ball) as the rest of it does.
    std::vector<Vec3> truth;
    PointSet ps = room(true, truth, 30);
    const size_t walls = ps.size();
    const Vec3 c{0.153f, 0.5f, 0.5f};
    add_ball(ps, truth, c, 0.15f, 1500, 31);
    estimate_normals(ps);
    size_t near = 0, right = 0;
    for (size_t i = 0; i < walls; ++i) {
        const Vec3 p = ps.positions[i];
        if (p.x > 1e-6f || length(p - Vec3{0, c.y, c.z}) > 0.08f) continue;
        ++near;
        right += dot(ps.normals[i], truth[i]) > 0;
    }
    ASSERT_GT(near, 15u);
    EXPECT_GT(double(right) / double(near), 0.6) << right << " of " << near;  // was 1 of 32
    EXPECT_GT(share_right(ps, truth, walls, ps.size()), 0.97);
}

// An open room with a ball 3 mm from the x = 0 wall, and two balls on the floor touching each
// other: three seeds, so that a rule does not pass by the luck of one sample.
struct CloseBalls {
    PointSet ps;
    std::vector<Vec3> truth;
    size_t walls = 0, near_wall = 0;  // [0, walls) the room, [walls, near_wall) that ball
};

CloseBalls close_balls(uint32_t seed) {
    CloseBalls s;
    s.ps = room(true, s.truth, seed);
    s.walls = s.ps.size();
    add_ball(s.ps, s.truth, {0.153f, 0.3f, 0.5f}, 0.15f, 1500, seed + 100);
    s.near_wall = s.ps.size();
    add_ball(s.ps, s.truth, {0.6f, 0.12f, 0.5f}, 0.12f, 1000, seed + 200);
    add_ball(s.ps, s.truth, {0.6f, 0.12f, 0.74f}, 0.12f, 1000, seed + 300);
    estimate_normals(s.ps);
    return s;
}

TEST(Orientation, ABallAFewMillimetresFromAWallFacesOutwardAllRound) {
    // The rays of the ball's points facing the wall meet the wall at once on both sides; alone
    // they chose wrongly for 0.4-0.7% of the ball (by seed). Votes spread along the ball's
    // surface, weighted by confidence, outvote them.
    for (const uint32_t seed : {40u, 41u, 42u}) {
        const CloseBalls s = close_balls(seed);
        EXPECT_GT(share_right(s.ps, s.truth, 0, s.walls), 0.995) << "seed " << seed;
        EXPECT_GT(share_right(s.ps, s.truth, s.walls, s.near_wall), 0.998) << "seed " << seed;
    }
}

TEST(Orientation, TwoBallsTouchingOnTheFloorFaceOutwardNearTheContacts) {
    // Near the contacts (ball to ball, ball to floor) rays see surface close on both sides.
    // Point by point 4.0% of the two balls went wrong (over these seeds); spread, 1.9%.
    size_t right = 0, all = 0;
    for (const uint32_t seed : {40u, 41u, 42u}) {
        const CloseBalls s = close_balls(seed);
        for (size_t i = s.near_wall; i < s.ps.size(); ++i)
            right += dot(s.ps.normals[i], s.truth[i]) > 0;
        all += s.ps.size() - s.near_wall;
    }
    EXPECT_GT(double(right) / double(all), 0.972) << right << " of " << all;
}

// An open box (a 0.25 m cube without its lid) standing on the floor of an open room, 0.125 m
// from the x = 0 wall, sampled as densely as the room (4000 points a square metre); with
// `thickness` > 0 each wall is a closed plate of that thickness (an outer and an inner face).
// The walls' true normals are the modeller's: away from the box's centre, and for the inner
// faces of thick walls into the box. [walls_begin, walls_end): the box's walls, bottom left
// out (it lies on the floor, hidden either way).
struct OpenBox {
    PointSet ps;
    std::vector<Vec3> truth;
    size_t walls_begin = 0, walls_end = 0;
    size_t inner_begin = 0;  // the inner faces, when thick: [inner_begin, walls_end)
};

OpenBox open_box_in_room(uint32_t seed, float thickness = 0) {
    OpenBox b;
    b.ps = room(true, b.truth, seed, 4000);
    b.walls_begin = b.ps.size();
    std::mt19937 rng(seed + 1);
    auto walls = [&](Vec3 lo, float a, float sign) {
        const size_t n = size_t(4000 * a * a);
        add_rect(b.ps, b.truth, lo, {a, 0, 0}, {0, a, 0}, {0, 0, -sign}, n, rng);
        add_rect(b.ps, b.truth, lo + Vec3{0, 0, a}, {a, 0, 0}, {0, a, 0}, {0, 0, sign}, n, rng);
        add_rect(b.ps, b.truth, lo, {0, 0, a}, {0, a, 0}, {-sign, 0, 0}, n, rng);
        add_rect(b.ps, b.truth, lo + Vec3{a, 0, 0}, {0, 0, a}, {0, a, 0}, {sign, 0, 0}, n, rng);
    };
    const float a = 0.25f;
    walls({0.125f, 0, 0.375f}, a, 1);
    b.inner_begin = b.ps.size();
    if (thickness > 0) walls({0.125f + thickness, 0, 0.375f + thickness}, a - 2 * thickness, -1);
    b.walls_end = b.ps.size();
    add_rect(b.ps, b.truth, {0.125f, 0, 0.375f}, {a, 0, 0}, {0, 0, a}, {0, -1, 0},
             size_t(4000 * a * a), rng);
    return b;
}

TEST(Orientation, AnOpenBoxNearAWallFacesAwayFromItsCentre) {
    // Both sides of each wall are free space (the room's air reaches inside over the walls),
    // so the voxels cannot decide; the rays did, and wrongly for the walls facing -x and +z:
    // inside, rays escape through the open top and count as travelling far, outside they meet
    // the room's wall. The walls now form one sheet that wraps around its centre, and face
    // away from it. The result does not depend on the number of threads.
    for (const uint32_t seed : {50u, 51u}) {
        OpenBox b = open_box_in_room(seed);
        std::vector<Vec3> first;
        for (const int threads : {1, 8}) {
            tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
            tbb::task_arena arena(threads);
            PointSet ps = b.ps;
            arena.execute([&] { estimate_normals(ps); });
            if (first.empty()) {
                first = ps.normals;
                EXPECT_GT(share_right(ps, b.truth, 0, b.walls_begin), 0.99) << "seed " << seed;
                // Was 47-50%. What stays wrong is the strip within a spacing of the floor, where
                // the walls meet the floor's (and the bottom's) points: the crease, decided as
                // before.
                EXPECT_GT(share_right(ps, b.truth, b.walls_begin, b.walls_end), 0.93)
                    << "seed " << seed;
                continue;
            }
            for (size_t i = 0; i < ps.size(); ++i) ASSERT_EQ(ps.normals[i], first[i]) << i;
        }
    }
}

TEST(Orientation, AThinWalledOpenBoxKeepsItsInnerFacesFacingIn) {
    // Walls 1 cm thick (closed plates, thinner than the voxel probe's reach): both sides of
    // each face are free by the voxels too, but the other face lies right behind every point,
    // so the sheet is a thin part and not an open sheet: the rays keep deciding, and the inner
    // faces face into the box, against the direction away from its centre.
    OpenBox b = open_box_in_room(52, 0.01f);
    estimate_normals(b.ps);
    EXPECT_GT(share_right(b.ps, b.truth, b.walls_begin, b.inner_begin), 0.9);
    EXPECT_GT(share_right(b.ps, b.truth, b.inner_begin, b.walls_end), 0.9);
}

TEST(Orientation, ViewpointOrientsEveryNormalTowardIt) {
    std::vector<Vec3> truth;
    PointSet ps = room(false, truth, 29);
    NormalEstimationParams params;
    params.orientation = Orientation::kViewpoint;
    params.viewpoint = {0.5f, 0.5f, 0.5f};
    OrientationReport rep;
    estimate_normals(ps, params, "room", &rep);
    for (size_t i = 0; i < ps.size(); ++i)
        ASSERT_GT(dot(ps.normals[i], params.viewpoint - ps.positions[i]), 0) << "point " << i;
    EXPECT_NE(rep.method.find("viewpoint"), std::string::npos);
    // From outside the room the walls face out instead.
    params.viewpoint = {0.5f, 0.5f, -3.0f};
    estimate_normals(ps, params);
    for (size_t i = 0; i < ps.size(); ++i)
        ASSERT_GT(dot(ps.normals[i], params.viewpoint - ps.positions[i]), 0) << "point " << i;
}

TEST(Orientation, InwardAndOutwardFollowTheCentroid) {
    std::vector<Vec3> truth;
    PointSet ps = room(false, truth, 30);
    NormalEstimationParams params;
    params.orientation = Orientation::kOutward;
    estimate_normals(ps, params);
    EXPECT_LT(share_right(ps, truth, 0, ps.size()), 0.005);  // a room's walls all face out
    params.orientation = Orientation::kInward;
    orient_normals(ps, params);
    EXPECT_GT(share_right(ps, truth, 0, ps.size()), 0.995);
}

TEST(Orientation, OrientNormalsKeepsTheAxesAndSetsTheSigns) {
    std::vector<Vec3> truth;
    PointSet ps = room(true, truth, 31);
    std::mt19937 rng(32);
    ps.normals = truth;
    for (size_t i = 0; i < ps.size(); ++i)
        if (rng() % 2) ps.normals[i] = -2.0f * ps.normals[i];  // random signs, not unit length
    orient_normals(ps);
    for (size_t i = 0; i < ps.size(); ++i)
        ASSERT_NEAR(std::fabs(dot(ps.normals[i], truth[i])), i % 1 ? 1.0f : length(ps.normals[i]),
                    1e-5f);
    EXPECT_GT(share_right(ps, truth, 0, ps.size()), 0.995);
}

TEST(Orientation, SensorPositionsOrientEachNormal) {
    std::vector<Vec3> truth;
    PointSet ps = room(false, truth, 33);
    ps.normals = truth;
    std::vector<Vec3> sensors(ps.size());
    for (size_t i = 0; i < ps.size(); ++i)
        sensors[i] = ps.positions[i] + (i % 2 ? 1.0f : -1.0f) * truth[i];
    orient_toward(ps, sensors);
    for (size_t i = 0; i < ps.size(); ++i)
        ASSERT_GT(dot(ps.normals[i], sensors[i] - ps.positions[i]), 0) << "point " << i;
    sensors.pop_back();
    EXPECT_THROW(orient_toward(ps, sensors, "scan.ply"), Error);
}

TEST(Orientation, OrientingWithoutNormalsIsAnError) {
    PointSet ps = sphere({0, 0, 0}, 1.0f, 100, 34);
    try {
        orient_normals(ps, {}, "scan.ply");
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_TRUE(starts_with(e.what(), "scan.ply: ")) << e.what();
    }
}

TEST(Orientation, ConsistencyCheckSeesRandomSigns) {
    std::vector<Vec3> truth;
    PointSet ps = room(true, truth, 35);
    ps.normals = truth;
    EXPECT_LT(normal_inconsistency(ps), 0.001);
    std::mt19937 rng(36);
    for (Vec3& n : ps.normals)
        if (rng() % 2) n = -n;
    EXPECT_GT(normal_inconsistency(ps), 0.3);
    // A fifth of the points probed reads the share every point gives, to a few hundredths.
    const double all = normal_inconsistency(ps, 8, 0), fifth = normal_inconsistency(ps, 8, ps.size() / 5);
    EXPECT_GT(all, 0.3);
    EXPECT_NEAR(fifth, all, 0.03);
    EXPECT_NE(fifth, all);  // a different set of probes
}

// ---- splat radii ---------------------------------------------------------------------------

// Unsigned angle (degrees) between the estimated and the true normal axes of points
// [begin, end), at quantile q.
float axis_error(const PointSet& ps, const std::vector<Vec3>& truth, double q, size_t begin = 0,
                 size_t end = SIZE_MAX) {
    end = std::min(end, ps.size());
    std::vector<float> a;
    for (size_t i = begin; i < end; ++i) {
        const float c = std::fabs(dot(ps.normals[i], normalized(truth[i])));
        a.push_back(std::acos(std::fmin(1.0f, c)) * 180.0f / kPi);
    }
    const size_t at = size_t(q * double(a.size() - 1));
    std::nth_element(a.begin(), a.begin() + std::ptrdiff_t(at), a.end());
    return a[at];
}

NormalEstimationParams axes_only() {
    NormalEstimationParams p;
    p.orientation = Orientation::kOutward;  // the axes do not depend on it; the fastest
    return p;
}

TEST(Fit, BoxEdgesKeepTheirFacesNormals) {
    // Near an edge the k nearest reach onto the other face; the fit there must keep to its own.
    const Vec3 h{1.0f, 0.6f, 0.8f};
    PointSet ps = box_surface(h, 20000, 5);
    estimate_normals(ps, axes_only());
    const std::vector<Vec3> face = face_normals(ps, h);
    PointSet edge;
    std::vector<Vec3> edge_truth;
    for (size_t i = 0; i < ps.size(); ++i)
        if (near_an_edge(ps.positions[i], h, 0.05f)) {  // about two spacings
            edge.positions.push_back(ps.positions[i]);
            edge.normals.push_back(ps.normals[i]);
            edge_truth.push_back(face[i]);
        }
    ASSERT_GT(edge.size(), 1000u);
    // One plain fit of the 12 nearest: 17 degrees (half the points lean toward the other face).
    EXPECT_LT(axis_error(edge, edge_truth, 0.5), 2.0f);
    // The sheet fits: 0.45. Points within a fraction of a spacing of the edge keep a fit
    // between the faces (p90 59 degrees, 47 before): both faces pass their test equally.
}

// The crease pass (NormalEstimationParams::creases): right at a box's edges, where the k nearest
// reach onto the other face and every fit leans, a point takes the plane through it that holds
// the most of its neighbours; away from the edges nothing changes.
TEST(Fit, PointsRightAtABoxsEdgesTakeTheirOwnFacesPlane) {
    const Vec3 h{1.0f, 0.6f, 0.8f};
    const PointSet box = box_surface(h, 20000, 5);
    NormalEstimationParams without = axes_only();
    without.creases = false;
    PointSet a = box, b = box;
    estimate_normals(a, axes_only());
    estimate_normals(b, without);
    const std::vector<Vec3> face = face_normals(box, h);
    PointSet edge_a, edge_b;
    std::vector<Vec3> truth;
    size_t far_changed = 0;
    for (size_t i = 0; i < box.size(); ++i) {
        // From a tenth to half a spacing off an edge. Nearer, both faces' planes through the
        // point hold their own face within the tolerance, and the larger share wins.
        if (near_an_edge(box.positions[i], h, 0.015f) &&
            !near_an_edge(box.positions[i], h, 0.003f)) {
            edge_a.positions.push_back(a.positions[i]);
            edge_a.normals.push_back(a.normals[i]);
            edge_b.positions.push_back(b.positions[i]);
            edge_b.normals.push_back(b.normals[i]);
            truth.push_back(face[i]);
        } else if (!near_an_edge(box.positions[i], h, 0.1f)) {
            far_changed += angle_deg(a.normals[i], b.normals[i]) > 1e-3f &&
                           angle_deg(a.normals[i], -b.normals[i]) > 1e-3f;
        }
    }
    ASSERT_GT(truth.size(), 300u);
    const float with90 = axis_error(edge_a, truth, 0.9), without90 = axis_error(edge_b, truth, 0.9);
    EXPECT_GT(without90, 30.0f);
    EXPECT_LT(with90, 0.2f * without90) << "with " << with90 << ", without " << without90;
    EXPECT_EQ(far_changed, 0u);
}

TEST(Fit, ASmallSphereFollowsItsCurve) {
    // Radius 5 sample spacings (300 points): neighbours two spacings away have turned by 23
    // degrees, which a test against the point's own tangent plane alone would drop.
    PointSet ps = sphere({0.3f, 0.2f, 0.1f}, 0.02f, 300, 7);
    std::vector<Vec3> truth;
    for (const Vec3& p : ps.positions) truth.push_back(p - Vec3{0.3f, 0.2f, 0.1f});
    estimate_normals(ps, axes_only());
    // One plain fit of the 12 nearest: p90 6.5 degrees; the sheet fits 4.6.
    EXPECT_LT(axis_error(ps, truth, 0.9), 5.5f);
    // Radius 3 spacings (113 points): the sheet fits' median is 7.8 degrees, worse than one
    // plain fit's 5.9 (neighbours two spacings away turn by 38 degrees, past the sheet test's
    // 37): a guard only.
    PointSet tiny = sphere({0.3f, 0.2f, 0.1f}, 0.02f, 113, 7);
    truth.clear();
    for (const Vec3& p : tiny.positions) truth.push_back(p - Vec3{0.3f, 0.2f, 0.1f});
    estimate_normals(tiny, axes_only());
    EXPECT_LT(axis_error(tiny, truth, 0.5), 10.0f);
}

TEST(Fit, TwoParallelPlatesOneAndAHalfSpacingsApart) {
    // Two 0.4 x 0.25 m sheets of 2500 samples (spacing 6.3 mm), 9 mm apart (1.5 spacings):
    // at their rims a neighbourhood that mixes both sheets is thicker than it is wide.
    // p90 at 1, 1.5, 2 spacings: one plain fit of the 12 nearest 64, 78, 51 degrees; the sheet
    // fits 0, 37, 0 (at 1.5 spacings a rim's first fit across both sheets stays for a tenth).
    const float limit[3] = {1.0f, 40.0f, 1.0f};
    int at = 0;
    for (const float gap : {0.0063f, 0.009f, 0.0126f}) {
        std::vector<Vec3> truth;
        std::mt19937 rng(45);
        PointSet ps;
        add_rect(ps, truth, {0, 0, 0}, {0.4f, 0, 0}, {0, 0.25f, 0}, {0, 0, -1}, 2500, rng);
        add_rect(ps, truth, {0, 0, gap}, {0.4f, 0, 0}, {0, 0.25f, 0}, {0, 0, 1}, 2500, rng);
        estimate_normals(ps, axes_only());
        EXPECT_LT(axis_error(ps, truth, 0.9), limit[at++]) << "gap " << gap;
    }
}

// The jet fits (NormalEstimationParams::jet) against the plane fits alone, on curved surfaces a
// few spacings across and with a rim, where a plane leans toward the side with more neighbours,
// and on a noisy plane, where both reach twice as far once the noise is measured.
TEST(Fit, JetsFollowACurveWithARimAndANoisyPlaneBetterThanPlanes) {
    // An open cylinder of radius 0.02 m (4 spacings), 0.1 m long, 1600 samples.
    std::mt19937 rng(51);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    PointSet cyl;
    std::vector<Vec3> cyl_truth;
    for (int i = 0; i < 1600; ++i) {
        const float a = 2 * kPi * u(rng);
        const Vec3 radial{std::cos(a), std::sin(a), 0.f};
        cyl.positions.push_back(radial * 0.02f + Vec3{0.f, 0.f, 0.1f * u(rng)});
        cyl_truth.push_back(radial);
    }
    // The noisy plane of Fit.ANoisyPlaneIsNoWorse.
    std::mt19937 rng2(47);
    PointSet plane;
    std::vector<Vec3> plane_truth;
    add_rect(plane, plane_truth, {0, 0, 0}, {0.4f, 0, 0}, {0, 0.25f, 0}, {0, 0, 1}, 2500, rng2);
    std::normal_distribution<float> g(0.0f, 0.3f * 0.0063f);
    for (Vec3& p : plane.positions) p += Vec3{g(rng2), g(rng2), g(rng2)};
    NormalEstimationParams with = axes_only(), without = axes_only();
    without.jet = false;
    for (auto* c : {&cyl, &plane}) {
        const std::vector<Vec3>& truth = c == &cyl ? cyl_truth : plane_truth;
        PointSet a = *c, b = *c;
        estimate_normals(a, with);
        estimate_normals(b, without);
        const float jet50 = axis_error(a, truth, 0.5), plane50 = axis_error(b, truth, 0.5);
        const float jet90 = axis_error(a, truth, 0.9), plane90 = axis_error(b, truth, 0.9);
        SCOPED_TRACE(c == &cyl ? "cylinder" : "noisy plane");
        // Measured: cylinder p50 0.03 / 1.21 degrees, p90 0.10 / 2.47 (jet / plane). The noisy
        // plane's noise is measured, so both fits reach twice as far (kNoisyReach): p50 2.00 /
        // 1.72, p90 4.32 / 3.94 (before they did: 4.53 / 4.93, 10.86 / 10.64).
        if (c == &cyl) {
            EXPECT_LT(jet50, 0.95f * plane50);
            EXPECT_LT(jet90, 0.5f * plane90);
        } else {
            EXPECT_LT(jet50, plane50 + 0.5f);
            EXPECT_LT(jet90, plane90 + 1.0f);
            EXPECT_LT(jet50, 2.5f);
            EXPECT_LT(jet90, 5.5f);
        }
    }
}

TEST(Fit, ANoisyPlaneIsNoWorse) {
    // Gaussian noise of 0.3 spacings per axis: one plain fit of the 12 nearest, p90 15 degrees.
    std::vector<Vec3> truth;
    std::mt19937 rng(47);
    PointSet ps;
    add_rect(ps, truth, {0, 0, 0}, {0.4f, 0, 0}, {0, 0.25f, 0}, {0, 0, 1}, 2500, rng);
    std::normal_distribution<float> g(0.0f, 0.3f * 0.0063f);
    for (Vec3& p : ps.positions) p += Vec3{g(rng), g(rng), g(rng)};
    estimate_normals(ps, axes_only());
    EXPECT_LT(axis_error(ps, truth, 0.9), 12.0f);
}

float median(std::vector<float> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
}

TEST(Radii, UniformPlaneGetsTheDiscOfItsShareOfArea) {
    // 4000 samples of one square metre: each stands for 1/4000 m^2, a disc of radius 8.9 mm.
    std::vector<Vec3> truth;
    std::mt19937 rng(40);
    PointSet ps;
    add_rect(ps, truth, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, 4000, rng);
    ps.normals = truth;
    estimate_radii(ps);
    const float r = std::sqrt(1.0f / (kPi * 4000.0f));
    EXPECT_NEAR(median(ps.radii), r, 0.05f * r);
}

// The radius read from neighbour distances assumes independent samples; on evenly spaced ones
// it reads about 12% large, which the sampling correction takes back (estimate_radii with
// RadiusEstimationParams::sampling_correction, the default): blue-noise samples of an empty
// room and a square grid get their true radius within a few percent, independent samples keep
// theirs (Radii.UniformPlaneGetsTheDiscOfItsShareOfArea).
TEST(Radii, EvenSamplesGetTheirTrueRadius) {
    Scene sc = load_scene(test::scene_path("cornell-empty"));
    sc.points = 20000;
    const PointSet truth = sample_scene(sc);  // blue noise, true radii
    for (bool correct : {true, false}) {
        PointSet ps;
        ps.positions = truth.positions;
        ps.normals = truth.normals;
        RadiusEstimationParams p;
        p.sampling_correction = correct;
        estimate_radii(ps, p);
        std::vector<float> ratio;
        for (size_t i = 0; i < ps.size(); ++i) ratio.push_back(ps.radii[i] / truth.radii[i]);
        // Measured: 1.119 without the correction (kEvenRadiusScale is its inverse).
        EXPECT_NEAR(median(ratio), correct ? 1.0f : 1.118f, 0.03f) << "correction " << correct;
    }
    // A square grid of spacing s: the disc of area s^2 has radius s / sqrt(pi).
    PointSet grid;
    const float s = 0.01f;
    for (int i = 0; i < 150; ++i)
        for (int j = 0; j < 150; ++j) {
            grid.positions.push_back({i * s, j * s, 0.f});
            grid.normals.push_back({0.f, 0.f, 1.f});
        }
    estimate_radii(grid);
    std::vector<float> ratio;
    for (float r : grid.radii) ratio.push_back(r / (s / std::sqrt(kPi)));
    EXPECT_NEAR(median(ratio), 1.0f, 0.05f);
}

TEST(Radii, ThinPlateIgnoresItsOtherFace) {
    // Two faces 3 mm apart, each with 2500 samples on 0.1 m^2 (spacing 6 mm, as the test
    // scenes): counting the other face as neighbours would halve the area per sample (radii
    // / sqrt 2).
    std::vector<Vec3> truth;
    std::mt19937 rng(41);
    PointSet ps;
    add_rect(ps, truth, {0, 0, 0}, {0.4f, 0, 0}, {0, 0.25f, 0}, {0, 0, -1}, 2500, rng);
    add_rect(ps, truth, {0, 0, 0.003f}, {0.4f, 0, 0}, {0, 0.25f, 0}, {0, 0, 1}, 2500, rng);
    ps.normals = truth;
    estimate_radii(ps);
    const float r = std::sqrt(0.1f / (kPi * 2500.0f));
    EXPECT_NEAR(median(ps.radii), r, 0.1f * r);
    // The same with unoriented (all +z) normals: the sign does not matter.
    for (Vec3& n : ps.normals) n = {0, 0, 1};
    estimate_radii(ps);
    EXPECT_NEAR(median(ps.radii), r, 0.1f * r);
}

// Percentile q (0..1) of the radii over their true value r.
float radius_ratio(const PointSet& ps, float r, double q) {
    std::vector<float> v = ps.radii;
    const size_t at = size_t(q * double(v.size() - 1));
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(at), v.end());
    return v[at] / r;
}

TEST(Radii, AThinTubeCountsNeighboursAroundIt) {
    // A tube of radius 5 mm, 0.4 m long, 1500 samples (spacing 2.9 mm): a neighbour three
    // spacings around it has a normal turned by 100 degrees but lies on the same sheet. Leaving
    // such neighbours out (as the smooth-surface test does) reads a one-dimensional strip as a
    // sparse surface and inflates the radii.
    std::mt19937 rng(43);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    PointSet ps;
    const float rt = 0.005f, len = 0.4f;
    for (int i = 0; i < 1500; ++i) {
        const float a = 2 * kPi * u(rng);
        ps.positions.push_back({rt * std::cos(a), rt * std::sin(a), len * u(rng)});
        ps.normals.push_back({std::cos(a), std::sin(a), 0});
    }
    RadiusEstimationParams raw;
    raw.smoothing_passes = 0;
    estimate_radii(ps, raw);
    const float r = std::sqrt(2 * kPi * rt * len / (kPi * 1500.0f));
    EXPECT_NEAR(median(ps.radii), r, 0.1f * r);
    estimate_radii(ps);
    EXPECT_NEAR(median(ps.radii), r, 0.1f * r);
    EXPECT_LT(radius_ratio(ps, r, 0.9), 1.2f);
}

TEST(Radii, SmoothingNarrowsTheScatterAndKeepsTheArea) {
    // One estimate from 8 neighbours scatters by about a third; the passes diffuse r^2 over the
    // sheet, keeping its sum (the area), so the radii gather around the true one.
    std::vector<Vec3> truth;
    std::mt19937 rng(44);
    PointSet ps;
    add_rect(ps, truth, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, 8000, rng);
    ps.normals = truth;
    const float r = std::sqrt(1.0f / (kPi * 8000.0f));
    auto area = [&] {
        double a = 0;
        for (float x : ps.radii) a += kPi * double(x) * x;
        return a;
    };
    RadiusEstimationParams raw;
    raw.smoothing_passes = 0;
    estimate_radii(ps, raw);
    const double raw_area = area();
    EXPECT_LT(radius_ratio(ps, r, 0.1), 0.8f);  // the raw scatter
    EXPECT_GT(radius_ratio(ps, r, 0.9), 1.2f);
    estimate_radii(ps);
    EXPECT_GT(radius_ratio(ps, r, 0.1), 0.88f);
    EXPECT_LT(radius_ratio(ps, r, 0.9), 1.12f);
    EXPECT_NEAR(area(), raw_area, 1e-4 * raw_area);
    raw.smoothing_passes = -1;
    EXPECT_THROW(estimate_radii(ps, raw, "scan.ply"), Error);
}

TEST(Radii, BadInputIsAnErrorNamingTheSource) {
    PointSet ps = sphere({0, 0, 0}, 1.0f, 100, 42);
    try {
        estimate_radii(ps, {}, "scan.ply");
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_TRUE(starts_with(e.what(), "scan.ply: ")) << e.what();
    }
    RadiusEstimationParams bad;
    bad.k = 40;
    ps.normals.assign(ps.size(), Vec3{0, 0, 1});
    EXPECT_THROW(estimate_radii(ps, bad, "scan.ply"), Error);
}

// ---- raw clouds: `vmap build --normals`, sensor fields, build_vmap's checks -------------------

std::string written_room(const test::ScratchDir& dir, bool normals, std::vector<Vec3>& truth) {
    PointSet ps = room(true, truth, 50);
    if (normals) ps.normals = truth;
    const std::string path = dir.path("room.ply");
    write_ply(path, ps);
    return path;
}

TEST(RawCloud, KeepUsesTheFileNormalsAndFlipNegatesThem) {
    test::ScratchDir dir;
    std::vector<Vec3> truth;
    const std::string path = written_room(dir, true, truth);
    std::vector<std::string> done;
    PointSet kept = load_point_cloud(path, {}, &done);
    EXPECT_EQ(kept.normals, truth);
    EXPECT_EQ(done.size(), 1u);  // only the radii were estimated
    CloudOptions flip;
    flip.normals = NormalsMode::kFlip;
    PointSet flipped = load_point_cloud(path, flip);
    for (size_t i = 0; i < truth.size(); ++i) ASSERT_EQ(flipped.normals[i], -truth[i]);
}

TEST(RawCloud, EstimateInwardAndOutwardReplaceTheSigns) {
    test::ScratchDir dir;
    std::vector<Vec3> truth;
    const std::string path = written_room(dir, true, truth);
    CloudOptions o;
    o.normals = NormalsMode::kEstimate;
    std::vector<std::string> done;
    PointSet est = load_point_cloud(path, o, &done);
    EXPECT_GT(share_right(est, truth, 0, truth.size()), 0.995);
    ASSERT_FALSE(done.empty());
    EXPECT_NE(done[0].find("estimated"), std::string::npos) << done[0];
    o.normals = NormalsMode::kOutward;
    EXPECT_LT(share_right(load_point_cloud(path, o), truth, 0, truth.size()), 0.01);
    o.normals = NormalsMode::kInward;
    EXPECT_GT(share_right(load_point_cloud(path, o), truth, 0, truth.size()), 0.99);
    o.normals = NormalsMode::kKeep;
    o.viewpoint = std::array<double, 3>{0.5, 0.5, -2.0};  // outside the open side: all face out
    const PointSet seen = load_point_cloud(path, o);
    const Vec3 view{0.5f, 0.5f, -2.0f};
    for (size_t i = 0; i < truth.size(); ++i)
        ASSERT_GT(dot(seen.normals[i], view - seen.positions[i]), 0) << i;
}

TEST(RawCloud, WithoutNormalsTheyAreEstimatedAndFlipIsAnError) {
    test::ScratchDir dir;
    std::vector<Vec3> truth;
    const std::string path = written_room(dir, false, truth);
    EXPECT_GT(share_right(load_point_cloud(path), truth, 0, truth.size()), 0.995);
    CloudOptions flip;
    flip.normals = NormalsMode::kFlip;
    try {
        load_point_cloud(path, flip);
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_TRUE(starts_with(e.what(), path + ": --normals flip")) << e.what();
    }
}

TEST(RawCloud, PlySensorFieldsOrientEstimatedNormals) {
    // A plane z = 0 scanned from alternately above and below: estimated normals follow the
    // sensor of each point, and a file with only some of the three fields is an error.
    test::ScratchDir dir;
    std::string ply =
        "ply\nformat ascii 1.0\nelement vertex 400\nproperty float x\n"
        "property float y\nproperty float z\nproperty float vp_x\n"
        "property float vp_y\nproperty float vp_z\nend_header\n";
    for (int i = 0; i < 400; ++i)
        ply += std::to_string(0.05 * (i % 20)) + " " + std::to_string(0.05 * (i / 20)) + " 0 0.5 " +
               "0.5 " + (i % 2 ? "1" : "-1") + "\n";
    const std::string path = dir.write("scan.ply", ply);
    const PointSet ps = load_point_cloud(path);
    for (int i = 0; i < 400; ++i) ASSERT_EQ(ps.normals[i].z, i % 2 ? 1.0f : -1.0f) << i;
    std::string partial = ply;
    partial.replace(partial.find("property float vp_z\n"), 20, "");
    const std::string bad = dir.write("partial.ply", partial);
    EXPECT_THROW(load_point_cloud(bad), Error);
}

TEST(RawCloud, BuildWithoutRadiiEstimatesThemAndSaysSo) {
    std::vector<Vec3> truth;
    PointSet ps = room(true, truth, 51);
    ps.normals = truth;
    BuildParams bp;
    bp.octree.max_height = 4;
    bp.backend = Backend::kCpu;
    BuildStats st;
    const VisibilityMap vm = build_vmap(ps, bp, &st, "room");
    ASSERT_TRUE(vm.points().has_radii());
    const float r = std::sqrt(5.0f / (kPi * float(ps.size())));         // five unit walls
    EXPECT_NEAR(median(points_in_input_order(vm).radii), r, 0.1f * r);  // input units
    ASSERT_EQ(st.warnings.size(), 1u);
    EXPECT_NE(st.warnings[0].find("radii"), std::string::npos) << st.warnings[0];
}

// One flat wall: no pair faces whichever way the normals point, so the warning says so and
// does not tell the user to flip them (which would change nothing).
TEST(RawCloud, BuildWarnsThatAFlatCloudSeesNothingWithoutSuggestingAFlip) {
    std::vector<Vec3> truth;
    std::mt19937 rng(7);
    PointSet ps;
    add_rect(ps, truth, {0, 0, 0}, {1, 0, 0}, {0, 0, 1}, {0, 1, 0}, 2000, rng);
    ps.normals = truth;
    ps.radii.assign(ps.size(), 0.01f);
    BuildParams bp;
    bp.octree.max_height = 5;
    bp.backend = Backend::kCpu;
    BuildStats st;
    const VisibilityMap vm = build_vmap(ps, bp, &st, "wall");
    EXPECT_EQ(detail::flipped_facing_share(vm.octree(), bp.visibility), 0.0);
    ASSERT_EQ(st.warnings.size(), 1u);
    EXPECT_NE(st.warnings[0].find("face each other"), std::string::npos) << st.warnings[0];
    EXPECT_NE(st.warnings[0].find("flat surface"), std::string::npos) << st.warnings[0];
    EXPECT_EQ(st.warnings[0].find("--normals flip"), std::string::npos) << st.warnings[0];
}

TEST(RawCloud, BuildWarnsWhenARoomFacesOutward) {
    std::vector<Vec3> truth;
    PointSet ps = room(true, truth, 52);
    for (const Vec3& n : truth) ps.normals.push_back(-n);
    ps.radii.assign(ps.size(), 0.01f);
    BuildParams bp;
    bp.octree.max_height = 4;
    bp.backend = Backend::kCpu;
    BuildStats st;
    const VisibilityMap vm = build_vmap(ps, bp, &st, "room");
    ASSERT_EQ(st.warnings.size(), 1u);
    EXPECT_NE(st.warnings[0].find("face each other"), std::string::npos) << st.warnings[0];
    // Flipped, they would face: the warning says so and suggests flipping them.
    EXPECT_NE(st.warnings[0].find("--normals flip"), std::string::npos) << st.warnings[0];
    EXPECT_GT(detail::flipped_facing_share(vm.octree(), bp.visibility), 0.5);
    // Right normals: no warning.
    ps.normals = truth;
    build_vmap(ps, bp, &st, "room");
    EXPECT_TRUE(st.warnings.empty());
}

TEST(RawCloud, BuildWarnsWhenNormalsLookInconsistent) {
    std::vector<Vec3> truth;
    PointSet ps = room(true, truth, 53);
    ps.normals = truth;
    std::mt19937 rng(54);
    for (Vec3& n : ps.normals)
        if (rng() % 3 == 0) n = -n;
    ps.radii.assign(ps.size(), 0.01f);
    BuildParams bp;
    bp.octree.max_height = 4;
    bp.backend = Backend::kCpu;
    BuildStats st;
    build_vmap(ps, bp, &st, "room");
    ASSERT_FALSE(st.warnings.empty());
    EXPECT_NE(st.warnings[0].find("inconsistent"), std::string::npos) << st.warnings[0];
}

// NearestPoints (the estimators' k-d tree behind the public header) against a brute-force
// search: the same neighbours in the same order, nearest first, with the same squared

// The disc floor of a cloud of unknown sampling (cloud_delta_floor): independent uniform samples
// on a plane give the Poisson share of close neighbours and the default floor; a square grid, a
// jittered grid and a hexagonal one give almost none and the even floor. A wavy sheet (its
// normals turning) counts like a plane.
PointSet plane_cloud(const std::vector<std::pair<float, float>>& xy, float wave = 0.f) {
    PointSet ps;
    for (auto [x, y] : xy) {
        const float z = wave * std::sin(3.f * x);
        ps.positions.push_back({x, y, z});
        const Vec3 n{-wave * 3.f * std::cos(3.f * x), 0.f, 1.f};
        ps.normals.push_back(n / length(n));
    }
    return ps;
}

TEST(CloudFloor, IndependentUniformSamplesGetTheDefaultFloor) {
    for (float wave : {0.f, 0.3f}) {
        std::mt19937 rng(11);
        std::uniform_real_distribution<float> u(0.f, 4.f);
        std::vector<std::pair<float, float>> xy(120000);
        for (auto& p : xy) p = {u(rng), u(rng)};
        const PointSet ps = plane_cloud(xy, wave);
        const double share = close_neighbour_share(ps);
        EXPECT_NEAR(share, kPoissonCloseShare, 0.006) << "wave " << wave << " share " << share;
        EXPECT_NEAR(cloud_delta_floor(ps), OctreeParams::kDefaultDeltaFloor, 0.015)
            << "wave " << wave;
    }
}

TEST(CloudFloor, EvenSamplesGetTheEvenFloor) {
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> jitter(-0.15f, 0.15f);
    std::vector<std::pair<float, float>> square, jittered, hex;
    const float s = 0.02f;
    for (int i = 0; i < 200; ++i)
        for (int j = 0; j < 200; ++j) {
            square.push_back({i * s, j * s});
            jittered.push_back({(i + jitter(rng)) * s, (j + jitter(rng)) * s});
            hex.push_back({(i + 0.5f * (j % 2)) * s, j * s * 0.8660254f});
        }
    for (const auto* xy : {&square, &jittered, &hex}) {
        const PointSet ps = plane_cloud(*xy);
        EXPECT_LT(close_neighbour_share(ps), 0.01);
        EXPECT_NEAR(cloud_delta_floor(ps), OctreeParams::kEvenDeltaFloor, 0.03);
    }
}

TEST(CloudFloor, AMixIsInBetweenAndAThinPlatesOtherFaceIsNoNeighbour) {
    // Half the points on a grid, half independent: about half the Poisson share.
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(0.f, 2.f);
    std::vector<std::pair<float, float>> xy;
    for (int i = 0; i < 100; ++i)
        for (int j = 0; j < 200; ++j) xy.push_back({i * 0.02f, j * 0.02f});
    for (int k = 0; k < 20000; ++k) xy.push_back({2.f + u(rng), 2.f * u(rng)});
    const float f = cloud_delta_floor(plane_cloud(xy));
    EXPECT_GT(f, OctreeParams::kEvenDeltaFloor + 0.1f);
    EXPECT_LT(f, OctreeParams::kDefaultDeltaFloor - 0.1f);
    // Two grids a tenth of a spacing apart (a thin plate's faces, opposite normals): each face
    // is even, the other face's points are not its close neighbours.
    PointSet plate =
        plane_cloud(std::vector<std::pair<float, float>>(xy.begin(), xy.begin() + 20000));
    const size_t n = plate.size();
    for (size_t i = 0; i < n; ++i) {
        plate.positions.push_back(plate.positions[i] + Vec3{0.f, 0.f, 0.002f});
        plate.normals.push_back(-plate.normals[i]);
    }
    EXPECT_LT(close_neighbour_share(plate), 0.01);
}

// Clouds with no density to read (too few points, no normals, all copies of one point, a
// line) count as independent samples: the default floor, never a NaN or a throw.
TEST(CloudFloor, CloudsWithNoDensityToReadGetTheDefaultFloor) {
    PointSet few = plane_cloud({{0.f, 0.f}, {1.f, 0.f}, {0.f, 1.f}});
    EXPECT_EQ(close_neighbour_share(few), kPoissonCloseShare);
    PointSet copies = plane_cloud(std::vector<std::pair<float, float>>(5000, {0.3f, 0.4f}));
    EXPECT_EQ(cloud_delta_floor(copies), OctreeParams::kDefaultDeltaFloor);
    PointSet bare = plane_cloud(std::vector<std::pair<float, float>>(100, {0.f, 0.f}));
    bare.normals.clear();
    EXPECT_EQ(close_neighbour_share(bare), kPoissonCloseShare);
    std::vector<std::pair<float, float>> line;
    for (int i = 0; i < 1000; ++i) line.push_back({0.001f * float(i), 0.f});
    const float f = cloud_delta_floor(plane_cloud(line));
    EXPECT_TRUE(f >= OctreeParams::kEvenDeltaFloor && f <= OctreeParams::kDefaultDeltaFloor);
    EXPECT_EQ(even_sampling_radius_scale(0.0), float(kEvenRadiusScale));
    EXPECT_EQ(even_sampling_radius_scale(1.0), 1.0f);
    EXPECT_EQ(even_sampling_radius_scale(std::nan("")), 1.0f);  // no number: no correction
}

// distances, for k below, at and above the number of points.
TEST(NearestPoints, MatchesBruteForce) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    std::vector<Vec3> pts(500);
    for (Vec3& p : pts) p = {u(rng), u(rng), u(rng)};
    const NearestPoints tree(pts);
    for (int q = 0; q < 50; ++q) {
        const Vec3 c = q < 5 ? pts[size_t(q)] : Vec3{u(rng), u(rng), u(rng)};
        std::vector<std::pair<float, uint32_t>> all;
        for (uint32_t i = 0; i < pts.size(); ++i) {
            const Vec3 d = pts[i] - c;
            all.push_back({d.x * d.x + d.y * d.y + d.z * d.z, i});
        }
        std::sort(all.begin(), all.end());
        for (size_t k : {size_t(1), size_t(9), size_t(48), size_t(500), size_t(600)}) {
            std::vector<uint32_t> idx(k);
            std::vector<float> d2(k);
            const size_t got = tree.find(c, k, idx.data(), d2.data());
            ASSERT_EQ(got, std::min(k, pts.size())) << "k " << k;
            for (size_t j = 0; j < got; ++j) {
                EXPECT_EQ(idx[j], all[j].second) << "query " << q << ", k " << k << ", rank " << j;
                EXPECT_FLOAT_EQ(d2[j], all[j].first) << "query " << q << ", k " << k;
            }
        }
    }
}

// ---- surface noise (estimate_surface_noise, roughness_of) ----------------------------------

// A noisy sphere of radius 0.3 (a curved surface, which a plane fit would count as noise) with
// Gaussian noise of sigma per axis: the jet residual reads sigma back within 10%; with no noise
// it reads (almost) none, and the roughness is 0.
TEST(SurfaceNoise, ReadsTheNoiseOfACurvedSurface) {
    for (float sigma : {0.f, 0.0005f, 0.001f, 0.003f}) {
        SCOPED_TRACE(sigma);
        PointSet ps = sphere({0.2f, 0.1f, -0.3f}, 0.3f, 20000, 11);
        std::mt19937 rng(5);
        std::normal_distribution<float> g(0.0f, 1.0f);
        for (Vec3& p : ps.positions) p += Vec3{g(rng), g(rng), g(rng)} * sigma;
        const SurfaceNoise n = estimate_surface_noise(ps);
        // 20,000 samples of the sphere's 1.13 m^2: a spacing of sqrt(pi) r, r^2 = A / (pi n).
        EXPECT_NEAR(n.spacing, std::sqrt(1.131f / 20000.f), 0.15 * std::sqrt(1.131f / 20000.f));
        if (sigma == 0) {
            EXPECT_LT(n.sigma, 0.002 * n.spacing);
            EXPECT_EQ(roughness_of(n), 0.f);
        } else {
            EXPECT_NEAR(n.sigma, sigma, 0.1 * sigma);
            EXPECT_NEAR(roughness_of(n), kRoughnessSigmas * n.sigma, 1e-6);
        }
    }
}

// Exact samples of a box (faces meeting at edges, where the jet cannot follow) and a room
// measure no noise: the median leaves the edges out.
TEST(SurfaceNoise, ExactSamplesOfFacetedSurfacesMeasureNone) {
    Scene sc = load_scene(std::string(VMAP_SOURCE_DIR) + "/scenes/cornell-empty.json");
    sc.points = 20000;
    EXPECT_EQ(roughness_of(estimate_surface_noise(sample_scene(sc))), 0.f);
    std::vector<Vec3> truth;
    std::mt19937 rng(3);
    PointSet box;
    const float s = 0.1f;
    add_rect(box, truth, {0, 0, 0}, {s, 0, 0}, {0, s, 0}, {0, 0, -1}, 800, rng);
    add_rect(box, truth, {0, 0, s}, {s, 0, 0}, {0, s, 0}, {0, 0, 1}, 800, rng);
    add_rect(box, truth, {0, 0, 0}, {s, 0, 0}, {0, 0, s}, {0, -1, 0}, 800, rng);
    add_rect(box, truth, {0, s, 0}, {s, 0, 0}, {0, 0, s}, {0, 1, 0}, 800, rng);
    add_rect(box, truth, {0, 0, 0}, {0, s, 0}, {0, 0, s}, {-1, 0, 0}, 800, rng);
    add_rect(box, truth, {s, 0, 0}, {0, s, 0}, {0, 0, s}, {1, 0, 0}, 800, rng);
    EXPECT_EQ(roughness_of(estimate_surface_noise(box)), 0.f);
    // A lone mesh (held-lone's bull, 30,000 samples): its facets, which a jet cannot follow,
    // read 0.07 spacings through a point's 24 nearest and about two thirds of that through the
    // nearest 12; noise reads the same through both. Shape, not noise: none.
    Scene lone = load_scene(std::string(VMAP_SOURCE_DIR) + "/scenes/test/held/held-lone.json");
    EXPECT_EQ(roughness_of(estimate_surface_noise(sample_scene(lone))), 0.f);
}

// Two parallel sheets closer than the neighbourhood (both faces of a plate, a surface a
// spacing or two from another) are no noise: each point's own sheet is fitted. With noise on
// both, it is read as on one sheet.
TEST(SurfaceNoise, TwoCloseSheetsAreNotNoise) {
    for (const float gap : {0.003f, 0.0063f, 0.009f, 0.0126f}) {  // 0.5 to 2 spacings
        SCOPED_TRACE(gap);
        std::vector<Vec3> truth;
        std::mt19937 rng(41);
        PointSet ps;
        add_rect(ps, truth, {0, 0, 0}, {0.4f, 0, 0}, {0, 0.25f, 0}, {0, 0, -1}, 2500, rng);
        add_rect(ps, truth, {0, 0, gap}, {0.4f, 0, 0}, {0, 0.25f, 0}, {0, 0, 1}, 2500, rng);
        EXPECT_EQ(roughness_of(estimate_surface_noise(ps)), 0.f);
        // Noise of a twelfth of the gap, 2 spacings apart (closer or noisier, the clusters
        // merge and their gap reads as noise: docs/validation.md "Noisy scans").
        if (gap < 0.0126f) continue;
        std::normal_distribution<float> g(0.0f, 0.001f);
        for (Vec3& p : ps.positions) p += Vec3{g(rng), g(rng), g(rng)};
        EXPECT_NEAR(estimate_surface_noise(ps).sigma, 0.001, 0.00015);
    }
}

TEST(SurfaceNoise, TooFewOrNonFinitePointsMeasureNothing) {
    PointSet few = sphere({0, 0, 0}, 1, 20, 1);
    EXPECT_EQ(estimate_surface_noise(few).sigma, 0.0);
    PointSet bad = sphere({0, 0, 0}, 1, 200, 1);
    bad.positions[7].y = std::numeric_limits<float>::quiet_NaN();
    EXPECT_EQ(estimate_surface_noise(bad).sigma, 0.0);
    EXPECT_EQ(roughness_of(SurfaceNoise{}), 0.f);
}

}  // namespace
}  // namespace vmap
