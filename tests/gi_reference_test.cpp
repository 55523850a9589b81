// The path-traced reference (include/vmap/gi_reference.h) against closed forms: the furnace
// (a closed box that emits and reflects everywhere: B = E (1 + rho + ... + rho^k)), a square
// light over a point (the point-to-rectangle form factor), a blocker's shadow; determinism over
// thread counts and seeds; bad input. Also the sampled light's power and the final gather.
#include "vmap/gi_reference.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <numbers>

#include "backend_fixture.h"
#include "test_util.h"
#include "vmap/error.h"
#include "vmap/gi.h"

namespace vmap {
namespace {

constexpr double kPi = std::numbers::pi;

// A quad a, b, c, d (counter-clockwise seen from the side its normal points to).
SceneSurface quad(const char* name, Vec3 a, Vec3 b, Vec3 c, Vec3 d, Vec3 albedo, Vec3 emission) {
    SceneSurface s;
    s.name = name;
    s.mesh.vertices = {a, b, c, d};
    s.mesh.triangles = {{0, 1, 2}, {0, 2, 3}};
    s.albedo = albedo;
    s.emission = emission;
    return s;
}

// The unit cube's six faces, normals inward.
std::vector<SceneSurface> cube(Vec3 albedo, Vec3 emission) {
    const Vec3 p[8] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                       {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
    return {quad("floor", p[0], p[4], p[5], p[1], albedo, emission),
            quad("ceiling", p[3], p[2], p[6], p[7], albedo, emission),
            quad("left", p[0], p[3], p[7], p[4], albedo, emission),
            quad("right", p[1], p[5], p[6], p[2], albedo, emission),
            quad("back", p[0], p[1], p[2], p[3], albedo, emission),
            quad("front", p[4], p[7], p[6], p[5], albedo, emission)};
}

// Form factor from a point to a rectangle a x b in a parallel plane at height h, the point
// below one corner (the classical closed form).
double corner_form_factor(double a, double b, double h) {
    const double A = a / h, B = b / h, sa = std::sqrt(1 + A * A), sb = std::sqrt(1 + B * B);
    return (A / sa * std::atan(B / sa) + B / sb * std::atan(A / sb)) / (2 * kPi);
}

TEST(Reference, FurnaceGivesTheGeometricSeriesPerBounce) {
    const double rho = 0.6, E = 2.0;
    const auto surfaces = cube(Vec3{0.6f, 0.6f, 0.6f}, Vec3{2, 2, 2});
    const Vec3 a{0.6f, 0.6f, 0.6f}, e{2, 2, 2};
    const std::vector<ReferencePoint> at = {{{0.5f, 0, 0.5f}, {0, 1, 0}, a, e},
                                            {{0.1f, 1, 0.2f}, {0, -1, 0}, a, e}};
    ReferenceParams p;
    p.samples = 4000;
    p.bounces = 3;
    const ReferenceResult r = path_trace_radiosity(surfaces, at, p, "furnace");
    ASSERT_EQ(r.value.size(), 4u);
    for (size_t i = 0; i < at.size(); ++i) {
        double want = E, term = E;
        for (int k = 0; k < 3; ++k) {
            term *= rho;
            want += term;
            const double se = r.std_error[k][i].x;
            EXPECT_LT(se, 0.03 * want);  // area sampling of emitters at the corners is noisy
            EXPECT_NEAR(r.value[k][i].x, want, 4 * se) << "bounce " << k + 1;
        }
        EXPECT_NEAR(r.value[3][i].x, E / (1 - rho), 4 * r.std_error[3][i].x);
    }
}

TEST(Reference, SquareLightMatchesThePointToRectangleFormFactor) {
    // A 0.4 x 0.4 light at height 0.5 facing down over the origin; nothing else.
    const float s = 0.2f, h = 0.5f;
    std::vector<SceneSurface> surfaces = {
        quad("light", {-s, h, -s}, {s, h, -s}, {s, h, s}, {-s, h, s}, Vec3{}, Vec3{10, 5, 1})};
    const std::vector<ReferencePoint> at = {{{0, 0, 0}, {0, 1, 0}, {1, 1, 1}, {}}};
    ReferenceParams p;
    p.samples = 20000;
    const ReferenceResult r = path_trace_radiosity(surfaces, at, p, "light");
    const double F = 4 * corner_form_factor(s, s, h);
    const double se = r.std_error[0][0].x;
    EXPECT_GT(se, 0);
    EXPECT_LT(se, 0.01 * 10 * F);
    EXPECT_NEAR(r.value[0][0].x, 10 * F, 4 * se);
    EXPECT_NEAR(r.value[0][0].y / r.value[0][0].x, 0.5, 1e-5);
    EXPECT_EQ(r.value[3][0].x, r.value[0][0].x);  // nothing to bounce off
}

TEST(Reference, BlockerCastsItsShadow) {
    const float s = 0.2f, h = 0.5f;
    std::vector<SceneSurface> surfaces = {
        quad("light", {-s, h, -s}, {s, h, -s}, {s, h, s}, {-s, h, s}, Vec3{}, Vec3{10, 10, 10}),
        // A blocker at mid height over x < 0.1, both sides facing (two quads).
        quad("top", {-1, 0.25f, -1}, {-1, 0.25f, 1}, {0.1f, 0.25f, 1}, {0.1f, 0.25f, -1}, Vec3{},
             Vec3{}),
        quad("bottom", {-1, 0.25f, -1}, {0.1f, 0.25f, -1}, {0.1f, 0.25f, 1}, {-1, 0.25f, 1}, Vec3{},
             Vec3{})};
    const std::vector<ReferencePoint> at = {{{-0.5f, 0, 0}, {0, 1, 0}, {1, 1, 1}, {}},
                                            {{0.8f, 0, 0}, {0, 1, 0}, {1, 1, 1}, {}}};
    ReferenceParams p;
    p.samples = 1000;
    const ReferenceResult r = path_trace_radiosity(surfaces, at, p, "blocker");
    EXPECT_EQ(r.value[0][0].x, 0.0f);  // under the blocker: no light
    EXPECT_GT(r.value[0][1].x, 0.0f);  // outside it: lit
}

TEST(Reference, SameSeedSameResultOnAnyThreadCount) {
    const auto surfaces = cube(Vec3{0.5f, 0.7f, 0.9f}, Vec3{});
    auto lit = surfaces;
    lit[1].emission = Vec3{5, 5, 5};
    std::vector<ReferencePoint> at;
    for (int i = 0; i < 16; ++i)
        at.push_back({{0.05f + 0.06f * i, 0, 0.5f}, {0, 1, 0}, {0.5f, 0.7f, 0.9f}, {}});
    ReferenceParams p;
    p.samples = 64;
    ReferenceResult a, b, c;
    {
        tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
        a = path_trace_radiosity(lit, at, p, "t");
    }
    b = path_trace_radiosity(lit, at, p, "t");
    p.seed = 2;
    c = path_trace_radiosity(lit, at, p, "t");
    for (size_t k = 0; k < a.value.size(); ++k)
        for (size_t i = 0; i < at.size(); ++i) {
            EXPECT_EQ(a.value[k][i], b.value[k][i]);
            EXPECT_EQ(a.std_error[k][i], b.std_error[k][i]);
        }
    EXPECT_NE(a.value[3][0].x, c.value[3][0].x);
    EXPECT_EQ(a.rays, b.rays);
}

TEST(Reference, BadInputIsAnError) {
    const std::vector<ReferencePoint> at = {{{0.5f, 0.5f, 0.5f}, {0, 1, 0}, {1, 1, 1}, {}}};
    ReferenceParams p;
    auto fails = [&](const std::vector<SceneSurface>& s, const ReferenceParams& q,
                     const char* what) {
        try {
            path_trace_radiosity(s, at, q, "scene.json");
            ADD_FAILURE() << "no error for " << what;
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("scene.json"), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
        }
    };
    fails(cube(Vec3{0.5f, 0.5f, 0.5f}, Vec3{}), p, "emitting");
    fails({}, p, "triangles");
    ReferenceParams q = p;
    q.samples = 1;
    fails(cube(Vec3{}, Vec3{1, 1, 1}), q, "samples");
    q = p;
    q.bounces = 0;
    fails(cube(Vec3{}, Vec3{1, 1, 1}), q, "bounces");
}

TEST(Sampling, LightPointsEmitTheLightsPower) {
    for (uint64_t n : {3000u, 5000u}) {
        Scene sc = load_scene(test::scene_path("cornell-bunny"));
        sc.points = n;
        std::vector<uint32_t> surf;
        const PointSet ps = sample_scene(sc, &surf);
        ASSERT_EQ(surf.size(), ps.size());
        double power = 0, want = 0;
        for (size_t i = 0; i < ps.size(); ++i)
            power += kPi * double(ps.radii[i]) * ps.radii[i] * ps.emission[i].x;
        for (const SceneSurface& s : sc.surfaces)
            if (s.emission.x > 0)
                for (const auto& t : s.mesh.triangles)
                    want += 0.5 * s.emission.x *
                            length(cross(s.mesh.vertices[t[1]] - s.mesh.vertices[t[0]],
                                         s.mesh.vertices[t[2]] - s.mesh.vertices[t[0]]));
        EXPECT_NEAR(power, want, 1e-5 * want) << n;
        for (size_t i = 0; i < ps.size(); ++i)
            EXPECT_EQ(ps.emission[i].x > 0, sc.surfaces[surf[i]].emission.x > 0);
    }
}

// The final gather on every backend (gi_final_gather_point on the GPU), against the brute force.
class FinalGather : public test::OnEachBackend {};

TEST_P(FinalGather, EqualsOneBruteForceBounceWhenThetaIsHuge) {
    const VisibilityMap vm = build_vmap(test::sample(test::scene_path("cornell-bunny"), 3000, 1),
                                        test::cpu_params(5, 4));
    RadiositySolver s(vm, gi_params(1e9f, 1));
    expect_ran_here(s.stats().backend);
    s.bounce();
    const std::vector<Vec3> fg = s.final_gather(1e9f);
    const std::vector<Vec3> bf = brute_force_radiosity(vm, 2);
    EXPECT_LT(relative_rms(fg, bf), 1e-5);
    // A subset gives the same values.
    const std::vector<uint32_t> some = {0, 17, 2999};
    const std::vector<Vec3> part = s.final_gather(1e9f, some);
    for (size_t k = 0; k < some.size(); ++k) EXPECT_EQ(part[k], fg[some[k]]);
}

TEST_P(FinalGather, IsCloseToTheBruteForceAtTheDefaults) {
    const VisibilityMap vm = build_vmap(test::sample(test::scene_path("cornell-bunny"), 4000, 1),
                                        test::cpu_params(6, 4));
    RadiositySolver s(vm, gi_params(4, 1));
    s.bounce();
    const std::vector<Vec3> fg = s.final_gather(2.0f);  // the CLI's default --gather-theta
    EXPECT_LT(relative_rms(fg, brute_force_radiosity(vm, 2)), 0.02);
    EXPECT_THROW(s.final_gather(0), Error);
    const std::vector<uint32_t> bad = {4000};
    EXPECT_THROW(s.final_gather(1, bad), Error);
}

VMAP_ON_EACH_BACKEND(FinalGather);

}  // namespace
}  // namespace vmap
