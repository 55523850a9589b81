// The radiosity solver (include/vmap/gi.h): the form factor against closed forms, reciprocity
// and bounds; the brute-force reference against an independent leaf-by-leaf oracle; the
// hierarchical solver against the brute force (converging as theta grows); energy in a closed
// box and an open room; determinism; bad parameters.
#include "vmap/gi.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>

#include "backend_fixture.h"
#include "gi/gi_host.h"
#include "test_util.h"
#include "vmap/error.h"

namespace vmap {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;

// A closed unit cube: n x n points on each face at the cell centres, normals inward, each
// standing for its h x h cell (r = h / sqrt(pi)); a 4 x 4 emitting patch in the ceiling's middle.
PointSet closed_box(int n, Vec3 albedo) {
    PointSet ps;
    const float h = 1.0f / n;
    for (int axis = 0; axis < 3; ++axis)
        for (int side = 0; side < 2; ++side)
            for (int u = 0; u < n; ++u)
                for (int v = 0; v < n; ++v) {
                    float c[3];
                    c[axis] = side ? 1.0f : 0.0f;
                    c[(axis + 1) % 3] = (u + 0.5f) * h;
                    c[(axis + 2) % 3] = (v + 0.5f) * h;
                    float nn[3] = {0, 0, 0};
                    nn[axis] = side ? -1.0f : 1.0f;
                    ps.positions.push_back({c[0], c[1], c[2]});
                    ps.normals.push_back({nn[0], nn[1], nn[2]});
                    ps.colors.push_back(albedo);
                    ps.radii.push_back(h / std::sqrt(kPi));
                    const bool light = axis == 1 && side == 1 && std::abs(u - n / 2 + 0.5f) < 2 &&
                                       std::abs(v - n / 2 + 0.5f) < 2;
                    ps.emission.push_back(light ? Vec3{10, 10, 10} : Vec3{});
                }
    return ps;
}

VisibilityMap box_vmap(int n, Vec3 albedo) {
    return build_vmap(closed_box(n, albedo), test::cpu_params(6, 4));
}

VisibilityMap room_vmap(const char* scene, uint64_t points, int height) {
    return build_vmap(test::sample(test::scene_path(scene), points, 1),
                      test::cpu_params(height, 4));
}

GiParams cpu_gi(float theta, int bounces, GiRefine refine = GiRefine::kBlocks) {
    GiParams p;
    p.backend = Backend::kCpu;
    p.refine = refine;
    p.theta = theta;
    p.bounces = bounces;
    return p;
}

// sum_j F_ij per point i: one bounce with E = 1 and albedo 1 everywhere gives 1 + sum_j F_ij
// (by the solver with `p`, one bounce; by the brute force when p.theta <= 0).
std::vector<double> row_sums(VisibilityMap vm, GiParams p) {
    test::points_of(vm).emission.assign(vm.points().size(), Vec3{1, 1, 1});
    test::points_of(vm).colors.assign(vm.points().size(), Vec3{1, 1, 1});
    p.bounces = 1;
    const auto B = p.theta > 0 ? solve_radiosity(vm, p) : brute_force_radiosity(vm, 1);
    std::vector<double> s(B.size());
    for (size_t i = 0; i < B.size(); ++i) s[i] = double(B[i].x) - 1.0;
    return s;
}

TEST(FormFactor, SmallFacingDiscsMatchTheClosedForm) {
    const float a = 1e-4f;  // small discs one unit apart: F = cos cos A / (pi d^2)
    for (float deg : {0.0f, 30.0f, 60.0f}) {
        const float t = deg * kPi / 180;
        const Vec3 nr{0, 0, 1}, ns{std::sin(t), 0, -std::cos(t)};
        const float F = a * gi_kernel({0, 0, 0}, nr, a, {0, 0, 1}, ns, a);
        const float expect = std::cos(t) * a / kPi;
        EXPECT_NEAR(F, expect, 1e-3 * expect) << deg;
    }
    // Receiver tilted: cos at the receiver.
    const float F =
        a * gi_kernel({0, 0, 0}, {0, std::sin(0.5f), std::cos(0.5f)}, a, {0, 0, 2}, {0, 0, -1}, a);
    EXPECT_NEAR(F, std::cos(0.5f) * a / (kPi * 4), 1e-3 * F);
    // Back-facing either way, or coincident: nothing.
    EXPECT_EQ(gi_kernel({0, 0, 0}, {0, 0, -1}, a, {0, 0, 1}, {0, 0, -1}, a), 0.0f);
    EXPECT_EQ(gi_kernel({0, 0, 0}, {0, 0, 1}, a, {0, 0, 1}, {0, 0, 1}, a), 0.0f);
    EXPECT_EQ(gi_kernel({0, 0, 0}, {0, 0, 1}, a, {0, 0, 0}, {0, 0, -1}, a), 0.0f);
}

TEST(FormFactor, IsReciprocalAndNeverAboveOne) {
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(-1, 1), ar(1e-6f, 1e-1f), sc(1e-4f, 2.0f);
    auto unit = [&] {
        Vec3 v{u(rng), u(rng), u(rng)};
        return v / length(v);
    };
    int nonzero = 0;
    for (int k = 0; k < 20000; ++k) {
        const Vec3 p{0, 0, 0}, q = unit() * sc(rng);
        const Vec3 np = unit(), nq = unit();
        const float ap = ar(rng), aq = ar(rng);
        const float Fpq = aq * gi_kernel(p, np, ap, q, nq, aq);
        const float Fqp = ap * gi_kernel(q, nq, aq, p, np, ap);
        EXPECT_LE(Fpq, 1.0f);
        EXPECT_LE(Fqp, 1.0f);
        EXPECT_GE(Fpq, 0.0f);
        EXPECT_NEAR(ap * Fpq, aq * Fqp, 1e-6f * std::max(ap * Fpq, 1e-30f));
        nonzero += Fpq > 0;
    }
    EXPECT_GT(nonzero, 1000);  // the random pairs did exercise facing ones
}

// One bounce from the V-map by an independent route: every point pair, visibility from
// leaves_visible, the same form factor, in double.
std::vector<Vec3> oracle_one_bounce(const VisibilityMap& vm) {
    const PointSet& ps = vm.points();
    const size_t P = ps.size();
    std::vector<Vec3> out(P);
    for (size_t i = 0; i < P; ++i) {
        const int32_t li = vm.octree().leaf_of_point(uint32_t(i));
        double h[3] = {0, 0, 0};
        for (size_t j = 0; j < P; ++j) {
            const int32_t lj = vm.octree().leaf_of_point(uint32_t(j));
            if (li == lj || !vm.leaves_visible(li, lj)) continue;
            const float ai = kPi * ps.radii[i] * ps.radii[i], aj = kPi * ps.radii[j] * ps.radii[j];
            const double F = double(aj) * gi_kernel(ps.positions[i], ps.normals[i], ai,
                                                    ps.positions[j], ps.normals[j], aj);
            h[0] += F * ps.emission[j].x, h[1] += F * ps.emission[j].y,
                h[2] += F * ps.emission[j].z;
        }
        const Vec3 E = ps.emission[i], rho = ps.colors[i];
        out[i] =
            Vec3{float(E.x + rho.x * h[0]), float(E.y + rho.y * h[1]), float(E.z + rho.z * h[2])};
    }
    return out;
}

TEST(Gi, BruteForceMatchesAPointPairOracle) {
    const VisibilityMap vm = room_vmap("cornell-bunny", 1500, 6);
    const auto oracle = oracle_one_bounce(vm);
    const auto brute = brute_force_radiosity(vm, 1);
    EXPECT_LT(relative_rms(brute, oracle), 1e-5);
    // And the light did reach the other points.
    size_t lit = 0;
    for (size_t i = 0; i < brute.size(); ++i)
        lit += vm.points().emission[i].x == 0 && brute[i].x > 0;
    EXPECT_GT(lit, brute.size() / 2);
}

// The hierarchical solver on every backend, each refinement, against the brute force.
class GiSolve : public test::OnEachBackendWith<GiRefine> {};

TEST_P(GiSolve, HierarchicalEqualsBruteForceWhenThetaIsHuge) {
    const VisibilityMap vm = room_vmap("cornell-two-models", 2500, 7);
    std::vector<std::vector<Vec3>> ref;
    brute_force_radiosity(vm, 3, &ref);
    RadiositySolver s(vm, gi_params(1e9f, 3, param()));
    expect_ran_here(s.stats().backend);
    EXPECT_EQ(s.stats().node_interactions, 0u);
    for (int b = 0; b < 3; ++b) {
        s.bounce();
        EXPECT_LT(relative_rms(s.radiosity(), ref[b]), 1e-5) << "bounce " << b + 1;
    }
}

TEST_P(GiSolve, FormFactorsAreReciprocalAndBounded) {
    const VisibilityMap vm = room_vmap("cornell-two-models", 3000, 7);
    for (float theta : {0.5f, 2.0f}) {
        RadiositySolver s(vm, gi_params(theta, 1, param()));
        std::vector<uint64_t> row;
        std::vector<uint32_t> src;
        std::vector<float> coef;
        std::vector<double> area;
        s.interaction_list(row, src, coef, area);
        ASSERT_GT(src.size(), 0u);
        size_t checked = 0;
        for (uint32_t r = 0; r + 1 < row.size(); ++r)
            for (uint64_t k = row[r]; k < row[r + 1]; ++k) {
                const uint32_t q = src[k];
                ASSERT_GT(coef[k], 0.0f);
                ASSERT_LE(coef[k], 1.0f);
                // The reverse interaction: rows are sorted by source.
                const auto b = src.begin() + row[q], e = src.begin() + row[q + 1];
                const auto it = std::lower_bound(b, e, r);
                ASSERT_TRUE(it != e && *it == r) << "no reverse of " << r << " <- " << q;
                const float back = coef[it - src.begin()];
                if (coef[k] == 1.0f || back == 1.0f) continue;  // capped
                const double x = area[r] * coef[k], y = area[q] * back;
                ASSERT_NEAR(x, y, 1e-5 * std::max(x, y)) << r << " <-> " << q;
                ++checked;
            }
        EXPECT_GT(checked, src.size() / 2);
    }
}

VMAP_ON_EACH_BACKEND_WITH(GiSolve, ::testing::Values(GiRefine::kBlocks, GiRefine::kLinks),
                          [](GiRefine r) { return std::string(name_of(r)); });

TEST_P(GiSolve, ErrorFallsAsThetaTightens) {
    const VisibilityMap vm = room_vmap("cornell-two-models", 4000, 7);
    std::vector<std::vector<Vec3>> ref;
    brute_force_radiosity(vm, 3, &ref);
    std::vector<std::vector<double>> err;  // [theta][bounce]
    std::vector<uint64_t> node_links;
    const std::vector<float> thetas{0.5f, 1.0f, 4.0f, 16.0f};
    for (float theta : thetas) {
        RadiositySolver s(vm, gi_params(theta, 3, param()));
        node_links.push_back(s.stats().node_interactions);
        err.emplace_back();
        for (int b = 0; b < 3; ++b) {
            s.bounce();
            err.back().push_back(relative_rms(s.radiosity(), ref[b]));
        }
    }
    for (size_t t = 0; t < thetas.size(); ++t) {
        std::cout << name_of(param()) << ", theta " << thetas[t] << ": node interactions "
                  << node_links[t] << ", relative RMS per bounce";
        for (double e : err[t]) std::cout << " " << e;
        std::cout << "\n";
    }
    EXPECT_GT(node_links[0], 0u);  // the coarse setting did transfer at node level
    for (int b = 0; b < 3; ++b) {
        // links: equal where no link changes level. Theta 0.5 and 1 transfer at nearly the same
        // nodes, and their errors then differ by rounding-sized amounts either way (2e-4
        // relative at the near-end exit rule of the predicate, 1.5e-3 on the blue-noise
        // samples): a rise below 0.3% is no rise.
        for (size_t t = 1; t < thetas.size(); ++t)
            EXPECT_LE(err[t][b], err[t - 1][b] * (1 + 3e-3))
                << "theta " << thetas[t] << " bounce " << b + 1;
        EXPECT_LT(err[1][b], 0.03) << "theta 1, bounce " << b + 1;
        EXPECT_LT(err[2][b], 0.02) << "the default theta 4, bounce " << b + 1;
        EXPECT_LT(err[3][b], 0.5 * err[1][b]) << "theta 16 against 1, bounce " << b + 1;
    }
}

// The energy tests on every backend.
class GiEnergy : public test::OnEachBackend {};

TEST_P(GiEnergy, ClosedBoxKeepsEnergyWithAlbedoOne) {
    // Form factor row sums: ~1 in a closed box (each point sees the whole hemisphere), never
    // much above (the point-disc form factor overestimates slightly near edges and corners).
    const VisibilityMap vm = box_vmap(16, {1, 1, 1});
    const auto rs = row_sums(vm, gi_params(-1, 1));
    double mean = 0, mx = 0;
    for (double s : rs) mean += s / rs.size(), mx = std::max(mx, s);
    std::cout << "row sums: mean " << mean << ", max " << mx << "\n";
    EXPECT_GT(mean, 0.9);
    EXPECT_LT(mean, 1.02);
    EXPECT_LT(mx, 1.1);
    // The hierarchical sums approach it from below as theta tightens (order 0 takes 1/d^2 at
    // the centres, which underestimates the mean of 1/d^2 over a pair of nearby nodes).
    double gap_prev = 1;
    for (float theta : {0.5f, 1.0f, 2.0f, 4.0f}) {
        const auto rh = row_sums(vm, gi_params(theta, 1));
        double mean_h = 0;
        for (double s : rh) mean_h += s / rh.size();
        std::cout << "theta " << theta << " mean row sum " << mean_h << "\n";
        const double gap = mean - mean_h;
        EXPECT_GT(gap, -0.01) << theta;
        EXPECT_LT(gap, gap_prev) << theta;
        gap_prev = gap;
    }
    EXPECT_LT(gap_prev, 0.02);

    // Power: with albedo 1 and reciprocity, a bounce's increment over the previous one is an
    // average of the row sums weighted by where the energy is: between their min and max.
    const double mn = *std::min_element(rs.begin(), rs.end());
    std::vector<std::vector<Vec3>> per;
    brute_force_radiosity(vm, 4, &per);
    const double e0 = total_power(vm, std::vector<Vec3>(vm.points().emission)).x;
    double prev = e0, prev_inc = e0;
    for (int b = 0; b < 4; ++b) {
        const double p = total_power(vm, per[b]).x;
        const double inc = p - prev;
        std::cout << "bounce " << b + 1 << ": increment ratio " << inc / prev_inc << "\n";
        EXPECT_LE(inc / prev_inc, mx + 1e-3) << "bounce " << b + 1;
        EXPECT_GE(inc / prev_inc, std::max(mn, 0.85)) << "bounce " << b + 1;
        prev = p, prev_inc = inc;
    }
}

TEST_P(GiEnergy, EachBounceAddsLessWithAlbedoBelowOne) {
    for (const float rho : {0.5f, 0.8f}) {
        const VisibilityMap vm = box_vmap(12, {rho, rho, rho});
        RadiositySolver s(vm, gi_params(1.0f, 5));
        float prev = total_power(vm, s.radiosity()).x, prev_inc = prev;
        for (int b = 0; b < 5; ++b) {
            s.bounce();
            const float p = total_power(vm, s.radiosity()).x;
            const float inc = p - prev;
            EXPECT_GT(inc, 0);
            EXPECT_LT(inc, prev_inc * rho * 1.05f) << "albedo " << rho << " bounce " << b + 1;
            prev = p, prev_inc = inc;
        }
    }
}

TEST_P(GiEnergy, OpenRoomLosesEnergyThroughItsOpenSide) {
    VisibilityMap vm = room_vmap("cornell-empty", 3000, 6);
    test::points_of(vm).colors.assign(vm.points().size(), Vec3{1, 1, 1});
    const auto rs = row_sums(vm, gi_params(1.0f, 1));
    double mean = 0;
    for (double s : rs) mean += s / rs.size();
    EXPECT_LT(mean, 0.95);  // part of every hemisphere looks out of the open side
    EXPECT_GT(mean, 0.3);
}

TEST_P(GiEnergy, PerChannelAlbedoColoursTheBounce) {
    // Red walls reflect red: the second bounce's increment at a white floor point near the red
    // wall is redder than green.
    const VisibilityMap vm = room_vmap("cornell-empty", 3000, 6);
    const auto one = solve_radiosity(vm, gi_params(1.0f, 1));
    const auto two = solve_radiosity(vm, gi_params(1.0f, 2));
    const float W = 0.5528f;
    double red = 0, green = 0;
    for (size_t i = 0; i < one.size(); ++i) {
        const Vec3 p = vm.points().positions[i], n = vm.points().normals[i];
        if (n.y > 0.9f && p.y < 0.01f && p.x > 0.8f * W) {  // floor, next to the x = W wall
            red += two[i].x - one[i].x;
            green += two[i].y - one[i].y;
        }
    }
    EXPECT_GT(red, 1.5 * green);
}

class GiMode : public ::testing::TestWithParam<GiRefine> {};

TEST_P(GiMode, CpuResultDoesNotDependOnThreadCount) {
    const VisibilityMap vm = room_vmap("cornell-bunny", 3000, 7);
    std::vector<Vec3> a, b;
    {
        tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
        a = solve_radiosity(vm, cpu_gi(1.0f, 3, GetParam()));
    }
    b = solve_radiosity(vm, cpu_gi(1.0f, 3, GetParam()));
    ASSERT_EQ(a.size(), b.size());
    for (size_t i = 0; i < a.size(); ++i) ASSERT_TRUE(a[i] == b[i]) << i;
}

INSTANTIATE_TEST_SUITE_P(Refine, GiMode, ::testing::Values(GiRefine::kBlocks, GiRefine::kLinks),
                         [](const auto& i) { return std::string(name_of(i.param)); });

TEST(Gi, BlockInteractionsGrowSlowerThanLinks) {
    // Links grow faster than the points; blocks about linearly. Four times the points:
    uint64_t blocks[2], links[2];
    const uint64_t sizes[2] = {2000, 8000};
    for (int k = 0; k < 2; ++k) {
        const VisibilityMap vm = room_vmap("cornell-bunny", sizes[k], 10);
        blocks[k] = RadiositySolver(vm, cpu_gi(1.0f, 1, GiRefine::kBlocks)).stats().interactions();
        links[k] = RadiositySolver(vm, cpu_gi(1.0f, 1, GiRefine::kLinks)).stats().interactions();
        EXPECT_GE(links[k], vm.num_links());
    }
    const double gb = double(blocks[1]) / blocks[0], gl = double(links[1]) / links[0];
    std::cout << "4x points: blocks x" << gb << ", links x" << gl << "\n";
    EXPECT_LT(gb, 6.0);
    EXPECT_LT(gb, 0.7 * gl);
    EXPECT_LT(blocks[1], links[1]);
}

// The block walk started where the last link's descent from the root left off
// (detail::GiLinkPath, the CPU refinement) against the walk from the root (the GPU's): the same
// parts in the same order with the same bits, for the V-map's links in order and for every
// disjoint node pair walked in increasing and in decreasing order (ancestors and descendants of
// the last pair's b among them), at several theta.
TEST(Gi, LinkWalkFromTheKeptPathEqualsTheWalkFromTheRoot) {
    const VisibilityMap vm = room_vmap("cornell-bunny", 3000, 8);
    const Octree& t = vm.octree();
    const PointSet& ps = vm.points();
    const int32_t N = t.num_nodes();
    const std::vector<detail::NodeGeom> geom = detail::gi_node_geometry(vm);
    std::vector<float> area(ps.size());
    std::vector<int32_t> point_leaf(ps.size());
    for (size_t i = 0; i < ps.size(); ++i) area[i] = kPi * ps.radii[i] * ps.radii[i];
    for (int32_t l = 0; l < t.num_leaves(); ++l)
        for (uint32_t k = t.point_begin()[t.leaf_node()[l]]; k < t.point_end()[t.leaf_node()[l]];
             ++k)
            point_leaf[k] = t.leaf_node()[l];
    const detail::GiTree tree =
        detail::gi_tree_view(vm, geom.data(), area.data(), point_leaf.data());
    struct Part {
        uint64_t key;
        double w;
        bool operator==(const Part&) const = default;
    };
    auto walk = [&](float theta, int32_t x, int32_t y, int32_t a0, int32_t b0) {
        std::vector<Part> parts;
        const uint32_t n = detail::gi_link_blocks(
            tree, theta, x, y,
            [&](uint64_t key, double w) {
                parts.push_back({key, w});
            },
            a0, b0);
        EXPECT_EQ(n, parts.size());
        return parts;
    };
    uint64_t walks = 0, parts = 0, deep_starts = 0;
    auto check = [&](float theta, int32_t x, const std::vector<int32_t>& ys) {
        detail::GiLinkPath path;
        for (int32_t y : ys) {
            path.seek(tree, theta, x, y);
            const auto kept = walk(theta, x, y, path.a(), path.b());
            ASSERT_EQ(kept, walk(theta, x, y, 0, 0))
                << "theta " << theta << " link " << x << " " << y << " from " << path.a() << " "
                << path.b();
            ++walks, parts += kept.size(), deep_starts += path.m >= 4;
        }
    };
    const auto disjoint = [&](int32_t x, int32_t y) {
        return !(x <= y && y < t.skip()[x]) && !(y <= x && x < t.skip()[y]);
    };
    for (float theta : {0.5f, 1.0f, 2.0f, 4.0f}) {
        for (int32_t x = 0; x < N; ++x) {
            std::vector<int32_t> ys;
            for (int32_t y : vm.links(x))
                if (y > x) ys.push_back(y);
            check(theta, x, ys);
        }
        for (int32_t x = 0; x < N; x += 37) {
            std::vector<int32_t> ys;
            for (int32_t y = 0; y < N; ++y)
                if (disjoint(x, y)) ys.push_back(y);
            check(theta, x, ys);
            std::reverse(ys.begin(), ys.end());
            check(theta, x, ys);
        }
    }
    std::cout << walks << " walks, " << parts << " parts, " << deep_starts
              << " started 4 or more steps below the root\n";
    EXPECT_GT(parts, walks);
    EXPECT_GT(deep_starts, walks / 2);  // most walks start 4 or more steps below the root
}

TEST(Gi, EmissionStaysWithItsPointInOctreeOrder) {
    // The light is on the ceiling facing down: after the octree reorders the points, every
    // emitting point must still be there (the octree once left emission in input order).
    const PointSet in = test::sample(test::scene_path("cornell-bunny"), 4000, 1);
    const VisibilityMap vm = build_vmap(in, test::cpu_params(7, 4));
    size_t emitting = 0;
    for (size_t k = 0; k < vm.points().size(); ++k) {
        const uint32_t i = vm.order()[k];
        ASSERT_TRUE(vm.points().emission[k] == in.emission[i]) << k;
        if (vm.points().emission[k].x > 0) {
            ++emitting;
            EXPECT_LT(vm.points().normals[k].y, -0.99f) << k;
            EXPECT_GT(vm.points().positions[k].y, 0.54f) << k;
        }
    }
    EXPECT_GT(emitting, 0u);
}

TEST_P(GiEnergy, ZeroBouncesGiveTheEmission) {
    const VisibilityMap vm = room_vmap("cornell-empty", 1000, 5);
    const auto B = solve_radiosity(vm, gi_params(1.0f, 0));
    for (size_t i = 0; i < B.size(); ++i) ASSERT_TRUE(B[i] == vm.points().emission[i]);
}

VMAP_ON_EACH_BACKEND(GiEnergy);

TEST(Gi, BadParametersAreErrors) {
    const VisibilityMap vm = room_vmap("cornell-empty", 500, 4);
    auto fails = [&](GiParams p, const char* what) {
        try {
            RadiositySolver s(vm, p);
            ADD_FAILURE() << "no error for " << what;
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
        }
    };
    fails(cpu_gi(0.0f, 1), "theta");
    fails(cpu_gi(-1.0f, 1), "theta");
    fails(cpu_gi(NAN, 1), "theta");
    fails(cpu_gi(INFINITY, 1), "theta");
    fails(cpu_gi(1.0f, -1), "bounces");
    GiParams p = cpu_gi(1.0f, 1);
    EXPECT_THROW(parse<Backend>("gpu", "backend"), Error);
    EXPECT_THROW(parse<GiRefine>("nope", "refine"), Error);
    p = cpu_gi(1e9f, 1);
    p.max_interactions = 10;
    fails(p, "theta");
    EXPECT_THROW(brute_force_radiosity(vm, -2), Error);
    VisibilityMap no_radii = vm;
    test::points_of(no_radii).radii.clear();
    try {
        RadiositySolver s(no_radii, cpu_gi(1.0f, 1));
        ADD_FAILURE() << "no error without radii";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("radii"), std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace vmap
