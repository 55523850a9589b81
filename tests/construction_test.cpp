// Output-sensitive construction (visibility/node_pair.h): the node path must give the V-map of
// the leaf-pair path byte for byte, and each node-level decision must agree with a brute-force
// walk of every leaf pair under it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "backend_fixture.h"
#include "octree/records.h"
#include "test_files.h"
#include "test_util.h"
#include "visibility/node_pair.h"
#include "visibility/packet_walk.h"

namespace vmap {
namespace {

void expect_same_vmap(const PointSet& ps, BuildParams bp, const std::string& what,
                      BuildStats* nodes_stats = nullptr) {
    BuildParams ref_bp = bp;  // the oracle holds each level of the frontier whole
    ref_bp.construction = Construction::kLeafPairs;
    ref_bp.max_level_pairs = BuildParams{}.max_level_pairs;
    BuildStats ls, ns;
    const VisibilityMap ref = build_vmap(ps, ref_bp, &ls);
    bp.construction = Construction::kNodes;
    const VisibilityMap got = build_vmap(ps, bp, &ns);
    ASSERT_EQ(ns.construction, "nodes");
    ASSERT_EQ(ns.backend.rfind(name_of(bp.backend), 0), 0u) << ns.backend;
    EXPECT_EQ(ls.leaf_pairs_walked, ls.leaf_pairs) << what;
    EXPECT_EQ(ns.work.pairs, ns.leaf_pairs_walked) << what;
    EXPECT_EQ(got.link_offsets(), ref.link_offsets()) << what;
    EXPECT_TRUE(std::ranges::equal(got.link_targets(), ref.link_targets())) << what;
    uint64_t decided = 0, walked = 0;
    for (const ConstructionLevel& l : ns.levels) {
        decided += l.leaf_pairs_decided;
        walked += l.leaf_pairs_walked;
        EXPECT_EQ(l.pairs, l.visible + l.invisible + l.split + l.walked) << what;
    }
    EXPECT_EQ(decided + walked, ns.leaf_pairs) << what << ": every leaf pair decided or walked";
    if (nodes_stats) *nodes_stats = ns;
}

struct SceneCase {
    const char* scene;
    int height, leaf_points;
};

class SameVmapOnScenes : public test::OnEachBackendWith<SceneCase> {};

TEST_P(SameVmapOnScenes, NodePathMatchesLeafPairPath) {
    const SceneCase c = param();
    const std::string file =
        c.scene[0] == '.' ? test::oracle_path(c.scene + 2) : test::scene_path(c.scene);
    BuildStats st;
    expect_same_vmap(test::sample(file, 1000, 2), build_params(c.height, c.leaf_points), file,
                     &st);
    EXPECT_LT(st.leaf_pairs_walked, st.leaf_pairs) << "some node pair should be decided";
}

std::vector<SceneCase> scene_cases() {
    std::vector<SceneCase> v;
    for (const char* s : {"cornell-bunny", "cornell-dragon", "cornell-empty", "cornell-two-models",
                          "./room-with-block.json", "./room-with-raised-block.json"})
        for (auto [h, lp] : {std::pair{5, 1}, {7, 4}, {9, 8}, {12, 2}}) v.push_back({s, h, lp});
    return v;
}

VMAP_ON_EACH_BACKEND_WITH(SameVmapOnScenes, ::testing::ValuesIn(scene_cases()),
                          [](const SceneCase& c) {
                              return std::string(c.scene) + "_h" + std::to_string(c.height) +
                                     "_lp" + std::to_string(c.leaf_points);
                          });

TEST(Construction, SavedFilesAreByteIdentical) {
    const PointSet ps = test::sample(test::scene_path("cornell-bunny"), 1500, 5);
    BuildParams bp = test::cpu_params(8, 4);
    test::ScratchDir dir;
    bp.construction = Construction::kLeafPairs;
    save_vmap(dir.path("a.vmap"), build_vmap(ps, bp));
    bp.construction = Construction::kNodes;
    save_vmap(dir.path("b.vmap"), build_vmap(ps, bp));
    EXPECT_EQ(test::slurp(dir.path("a.vmap")), test::slurp(dir.path("b.vmap")));
}

// ---- random scenes ----

struct Gen {
    std::mt19937_64 rng;
    PointSet ps;
    float unit(float lo, float hi) { return std::uniform_real_distribution<float>(lo, hi)(rng); }
    void add(Vec3 p, Vec3 n, float r) {
        ps.positions.push_back(p);
        ps.normals.push_back(n);
        ps.radii.push_back(r);
    }
    // A rectangle at o spanned by u, v (normal n), k points; both sides when two_sided.
    void plate(Vec3 o, Vec3 u, Vec3 v, int k, bool two_sided, float gap) {
        Vec3 n = cross(u, v);
        n = n / length(n);
        const float r = std::sqrt(length(cross(u, v)) / (3.14159f * k));
        for (int i = 0; i < k; ++i) {
            const Vec3 p = o + u * unit(0, 1) + v * unit(0, 1);
            add(p, n, r);
            if (two_sided) add(p - n * gap, -n, r);
        }
    }
    void box(Vec3 lo, Vec3 s, int k) {
        const Vec3 ex{s.x, 0, 0}, ey{0, s.y, 0}, ez{0, 0, s.z};
        plate(lo, ey, ex, k, false, 0);  // bottom, normal -z
        plate(lo + ez, ex, ey, k, false, 0);
        plate(lo, ex, ez, k, false, 0);  // normal -y
        plate(lo + ey, ez, ex, k, false, 0);
        plate(lo, ez, ey, k, false, 0);  // normal -x
        plate(lo + ex, ey, ez, k, false, 0);
    }
    void sphere(Vec3 c, float rad, int k, bool inward) {
        const float r = rad * std::sqrt(4.f / k);
        for (int i = 0; i < k; ++i) {
            Vec3 n{unit(-1, 1), unit(-1, 1), unit(-1, 1)};
            if (length(n) < 1e-3f) continue;
            n = n / length(n);
            add(c + n * rad, inward ? -n : n, r);
        }
    }
    void triangles(Vec3 c, float size, int tris, int k) {  // a random triangle soup
        for (int t = 0; t < tris; ++t) {
            const Vec3 a = c + Vec3{unit(-1, 1), unit(-1, 1), unit(-1, 1)} * size;
            const Vec3 u = Vec3{unit(-1, 1), unit(-1, 1), unit(-1, 1)} * (size * 0.5f);
            const Vec3 v = Vec3{unit(-1, 1), unit(-1, 1), unit(-1, 1)} * (size * 0.5f);
            if (length(cross(u, v)) < 1e-4f * size * size) continue;
            plate(a, u, v, k, unit(0, 1) < 0.3f, 0);
        }
    }
    void room(float s, int k) {  // five walls, normals inward, open at z = 0
        const Vec3 ex{s, 0, 0}, ey{0, s, 0}, ez{0, 0, s};
        plate({0, 0, 0}, ez, ex, k, false, 0);  // floor, +y
        plate(ey, ex, ez, k, false, 0);         // ceiling, -y
        plate({0, 0, 0}, ey, ez, k, false, 0);  // x = 0 wall, +x
        plate(ex, ez, ey, k, false, 0);         // x = s wall, -x
        plate(ez, ey, ex, k, false, 0);         // back wall, -z
    }
};

PointSet random_scene(uint64_t seed) {
    Gen g{std::mt19937_64(seed), {}};
    const bool room = seed % 3 != 0;
    if (room) g.room(1.f, 30 + int(seed % 5) * 10);
    const int objects = 1 + int(g.rng() % 4);
    for (int o = 0; o < objects; ++o) {
        const Vec3 c{g.unit(0.2f, 0.8f), g.unit(0.1f, 0.8f), g.unit(0.2f, 0.8f)};
        switch (g.rng() % 5) {
            case 0:
                g.box(c, {g.unit(0.05f, 0.3f), g.unit(0.05f, 0.3f), g.unit(0.05f, 0.3f)}, 20);
                break;
            case 1:
                g.sphere(c, g.unit(0.05f, 0.2f), 60, false);
                break;
            case 2:  // a thin wall with points on both sides (gap 0: flagged leaves)
                g.plate(c, {g.unit(0.1f, 0.5f), 0, 0}, {0, g.unit(0.1f, 0.5f), g.unit(-0.1f, 0.1f)},
                        40, true, g.rng() % 2 ? 0.f : 0.002f);
                break;
            case 3:
                g.triangles(c, 0.15f, 6, 8);
                break;
            default:
                g.sphere(c, g.unit(0.1f, 0.3f), 60, true);
                break;
        }
    }
    // Some scenes far from the origin or at other scales (the margins scale with coordinates).
    const float scale = seed % 7 == 0 ? 1e3f : (seed % 11 == 0 ? 1e-3f : 1.f);
    const Vec3 shift = seed % 5 == 0 ? Vec3{20, -7, 3} : Vec3{0, 0, 0};
    for (size_t i = 0; i < g.ps.size(); ++i) {
        g.ps.positions[i] = (g.ps.positions[i] + shift) * scale;
        g.ps.radii[i] *= scale;
    }
    return g.ps;
}

class NodeConstruction : public test::OnEachBackend {};

TEST_P(NodeConstruction, RandomScenesGiveTheLeafPairVmap) {
    uint64_t decided_scenes = 0;
    for (uint64_t seed = 1; seed <= 220; ++seed) {
        const PointSet ps = random_scene(seed);
        std::mt19937_64 r(seed * 7919);
        BuildParams bp = build_params(3 + int(r() % 7), 1 + int(r() % 6));
        bp.visibility.K = 1 + int(r() % 3);
        bp.visibility.eps = std::array<float, 4>{0.f, 0.001f, 0.01f, 0.05f}[r() % 4];
        bp.visibility.facing_tol = std::array<float, 3>{0.f, 0.005f, 0.05f}[r() % 3];
        // The end windows from a stream of their own (the draws above and below stay as they were).
        bp.visibility.end_window =
            std::array<float, 4>{0.f, 0.f, 1.f, 2.5f}[std::mt19937_64(seed * 104729)() % 4];
        // A roughness (in the scene's units: the scale below) from a stream of its own too.
        bp.visibility.roughness =
            std::array<float, 4>{0.f, 0.f, 0.002f, 0.02f}[std::mt19937_64(seed * 15485863)() % 4] *
            (seed % 7 == 0 ? 1e3f : (seed % 11 == 0 ? 1e-3f : 1.f));
        bp.walk_pairs = std::array<uint64_t, 4>{1, 16, 256, 4096}[r() % 4];
        // Frontier slices of a few pairs: pairs settled across slices and levels.
        bp.max_level_pairs = std::array<uint64_t, 4>{1, 7, 64, 1u << 20}[r() % 4];
        // Lanes (one to three frontiers taking a split's slices at once), from a stream of
        // their own.
        bp.lanes = 1 + int(std::mt19937_64(seed * 49979687)() % 3);
        BuildStats st;
        expect_same_vmap(ps, bp, "seed " + std::to_string(seed), &st);
        if (HasFailure()) return;
        decided_scenes += st.leaf_pairs_walked < st.leaf_pairs;
    }
    EXPECT_GT(decided_scenes, 150u) << "the node tests should decide something in most scenes";
}

// Two builds of one scene that must agree: the same links, and the same work counted.
void expect_same_build(const VisibilityMap& a, const BuildStats& sa, const VisibilityMap& b,
                       const BuildStats& sb, const std::string& what) {
    EXPECT_EQ(b.link_offsets(), a.link_offsets()) << what;
    EXPECT_TRUE(std::ranges::equal(b.link_targets(), a.link_targets())) << what;
    EXPECT_EQ(sb.leaf_pairs_walked, sa.leaf_pairs_walked) << what;
    EXPECT_EQ(sb.node_pairs_tested, sa.node_pairs_tested) << what;
    EXPECT_EQ(sb.shaft_node_tests, sa.shaft_node_tests) << what;
    EXPECT_EQ(sb.work.pairs, sa.work.pairs) << what;
    EXPECT_EQ(sb.work.facing_pairs, sa.work.facing_pairs) << what;
    EXPECT_EQ(sb.work.visible_pairs, sa.work.visible_pairs) << what;
    EXPECT_EQ(sb.work.node_tests, sa.work.node_tests) << what;
    EXPECT_EQ(sb.leaf_walked, sa.leaf_walked) << what;
    ASSERT_EQ(sb.levels.size(), sa.levels.size()) << what;
    for (size_t k = 0; k < sa.levels.size(); ++k) {
        EXPECT_EQ(sb.levels[k].pairs, sa.levels[k].pairs) << what << ", level " << k;
        EXPECT_EQ(sb.levels[k].visible, sa.levels[k].visible) << what << ", level " << k;
        EXPECT_EQ(sb.levels[k].walked, sa.levels[k].walked) << what << ", level " << k;
        EXPECT_EQ(sb.levels[k].leaf_pairs_walked, sa.levels[k].leaf_pairs_walked)
            << what << ", level " << k;
    }
}

// The frontier held a pair at a time per level (the bound on memory), and lanes (three
// frontiers with backends of their own taking a split's slices at once, over slices of 50
// pairs), give the same V-map and the same counts as one frontier held whole, on both
// constructions.
TEST_P(NodeConstruction, SlicedFrontierAndLanesGiveTheSameVmap) {
    const PointSet ps = test::sample(test::scene_path("cornell-bunny"), 2500, 4);
    for (const Construction method : {Construction::kLeafPairs, Construction::kNodes}) {
        BuildParams bp = build_params(7, 2);
        bp.construction = method;
        bp.walk_pairs = 64;
        bp.lanes = 1;  // (the GPU's default is 3)
        BuildStats ws, ss, ls;
        const VisibilityMap whole = build_vmap(ps, bp, &ws);
        bp.max_level_pairs = 1;
        const VisibilityMap sliced = build_vmap(ps, bp, &ss);
        bp.max_level_pairs = 50;
        bp.lanes = 3;
        const VisibilityMap laned = build_vmap(ps, bp, &ls);
        expect_same_build(whole, ws, sliced, ss, name_of(method) + std::string(", sliced"));
        EXPECT_GT(ss.batches, ws.batches) << name_of(method);
        expect_same_build(whole, ws, laned, ls, name_of(method) + std::string(", 3 lanes"));
        EXPECT_EQ(ws.lanes, 1u);
        EXPECT_EQ(ls.lanes, 3u) << name_of(method);
    }
}

// BuildParams::lanes out of range is refused, naming the field.
TEST(Construction, LanesOutOfRangeAreRefused) {
    BuildParams bp;
    bp.lanes = 17;
    EXPECT_THROW(
        {
            try {
                bp.check("lanes.test");
            } catch (const Error& e) {
                EXPECT_NE(std::string(e.what()).find("lanes"), std::string::npos);
                throw;
            }
        },
        Error);
    bp.lanes = -1;
    EXPECT_THROW(bp.check("lanes.test"), Error);
}

// decide_node_pair for `pairs` on the backend, a byte per pair (PairDecision): on the device
// when it decides (the GPU: the pairs worth_deciding, as the builder asks it), else on the host
// (every pair, two leaves too).
std::vector<uint8_t> decisions_on(detail::Backend& backend, const Octree& t,
                                  const detail::NodePairContext& c,
                                  const std::vector<detail::NodePairRef>& pairs) {
    std::vector<uint8_t> out(pairs.size());
    backend.prepare(t, c.vp, 1024);
    backend.set_node_context(&c);
    uint64_t shaft = 0;
    if (backend.decide(pairs, out.data(), &shaft)) return out;
    struct {
        uint64_t shaft_node_tests = 0;
    } wc;
    for (size_t i = 0; i < pairs.size(); ++i)
        out[i] = uint8_t(detail::decide_node_pair(c, pairs[i].a, pairs[i].b, &wc));
    return out;
}

// A random scene's V-map (the leaf-pair path, height and leaf_points from the seed), every leaf
// pair's answer, and the node tests' context.
struct NodeTestScene {
    VisibilityMap vm;
    const Octree& t;
    std::vector<uint8_t> m;  // leaf x, y: m[x * L + y]
    detail::NodeBoundsSet nb;
    detail::NodePairContext c;
    NodeTestScene(uint64_t seed, int leaf_points)
        : vm(build_vmap(random_scene(seed), [&] {
              BuildParams bp = test::cpu_params(4 + int(seed % 4), leaf_points);
              bp.construction = Construction::kLeafPairs;
              return bp;
          }())),
          t(vm.octree()),
          m(test::brute_matrix(vm)),
          nb(detail::node_bounds(t)),
          c{octree_view(t),  nb.nodes.data(),        nb.cones.data(),
            t.skip().data(), vm.visibility_params(), detail::node_pair_margin(t.boxes()[0])} {}
    NodeTestScene(const NodeTestScene&) = delete;
};

// Every node pair of disjoint subtrees, not only those the builder meets: a decision must hold
// for each leaf pair under it (the brute-force matrix).
TEST_P(NodeConstruction, DecisionsAgreeWithEveryLeafPair) {
    uint64_t all = 0, none = 0;
    for (uint64_t seed = 300; seed < 320; ++seed) {
        const NodeTestScene sc(seed, 2 + int(seed % 3));
        const Octree& t = sc.t;
        const auto& m = sc.m;
        const detail::NodePairContext& c = sc.c;
        std::vector<detail::NodePairRef> pairs;
        for (int32_t a = 0; a < t.num_nodes(); ++a)
            for (int32_t b = t.skip()[a]; b < t.num_nodes(); b += 1 + int32_t(seed % 3))
                pairs.push_back({a, b});
        const std::vector<uint8_t> got = decisions_on(*leaf_pair_backend(), t, c, pairs);
        const int32_t L = t.num_leaves();
        for (size_t i = 0; i < pairs.size(); ++i) {
            const auto d = detail::PairDecision(got[i]);
            if (d == detail::PairDecision::kUndecided) continue;
            const bool want = d == detail::PairDecision::kAllVisible;
            (want ? all : none)++;
            const auto [a, b] = pairs[i];
            for (int32_t x = t.leaf_begin()[a]; x < t.leaf_end()[a]; ++x)
                for (int32_t y = t.leaf_begin()[b]; y < t.leaf_end()[b]; ++y)
                    ASSERT_EQ(bool(m[size_t(x) * L + y]), want)
                        << "seed " << seed << ": nodes " << a << ", " << b << ", leaves " << x
                        << ", " << y;
        }
    }
    EXPECT_GT(all, 1000u);
    EXPECT_GT(none, 1000u);
}

VMAP_ON_EACH_BACKEND(NodeConstruction);

// Every leaf pair under node pair (a, b), walked over `list` (a list of the tree's nodes for
// that pair), gets the whole walk's answer (m, the leaf-by-leaf table): one at a time, then in
// packets of 32, all pairs loaded (load) or only those that face (load_faced, the backend's
// path). Adds the pairs to *pairs.
void expect_list_gives_the_whole_walks_answers(const Octree& t, const detail::NodePairContext& c,
                                               const std::vector<uint8_t>& m,
                                               std::vector<WalkNode>& list, int32_t a, int32_t b,
                                               bool faced, uint64_t* pairs) {
    const int32_t L = t.num_leaves();
    OctreeView lv = c.tree;
    lv.walk = list.data();
    lv.num_nodes = int32_t(list.size());
    std::vector<int32_t> xs, ys;
    for (int32_t x = t.leaf_begin()[a]; x < t.leaf_end()[a]; ++x)
        for (int32_t y = t.leaf_begin()[b]; y < t.leaf_end()[b]; ++y) {
            WorkCounters wc;
            ASSERT_EQ(detail::leaf_pair_visible<true>(lv, x, y, c.vp, &wc),
                      bool(m[size_t(x) * L + y]))
                << "nodes " << a << ", " << b << ", leaves " << x << ", " << y;
            ++*pairs;
            if (!faced || detail::pair_faces(lv.leaves[x], lv.leaves[y], c.vp))
                xs.push_back(x), ys.push_back(y);
        }
    for (size_t k = 0; k < xs.size(); k += 32) {
        const int n = int(std::min<size_t>(32, xs.size() - k));
        detail::SegmentPacket<32> pk;
        WorkCounters wc;
        const bool any = faced ? pk.load_faced(lv, xs.data() + k, ys.data() + k, n, c.vp, &wc)
                               : pk.load(lv, xs.data() + k, ys.data() + k, n, c.vp, &wc);
        const uint32_t vis = any ? pk.walk(lv, c.vp, &wc) : 0u;
        for (int i = 0; i < n; ++i)
            ASSERT_EQ(bool(vis >> i & 1u), bool(m[size_t(xs[k + i]) * L + ys[k + i]]))
                << "packet, nodes " << a << ", " << b;
    }
}

// The CPU walks a job's leaf pairs through the shaft list of an enclosing node pair (the split
// pair it came from: cpu_backend.cpp): for every node pair (A, B) of disjoint subtrees, each leaf
// pair under it, and so under any pair of A's and B's descendants, walked through (A, B)'s list
// gets the answer of the whole walk, by the packet walk too.
TEST(Construction, ShaftListsGiveTheWholeWalksAnswers) {
    uint64_t pairs = 0, shorter = 0;
    for (uint64_t seed = 400; seed < 412; ++seed) {
        SCOPED_TRACE(seed);
        NodeTestScene sc(seed, 1 + int(seed % 3));
        detail::NodePairContext& c = sc.c;
        c.leaves_stored = true;
        ASSERT_GT(c.margin, 0.0);
        std::vector<WalkNode> list;
        std::vector<int32_t> scratch;
        for (int32_t a = 0; a < sc.t.num_nodes(); a += 1 + int32_t(seed % 2))
            for (int32_t b = sc.t.skip()[a]; b < sc.t.num_nodes(); b += 2 + int32_t(seed % 3)) {
                detail::shaft_walk_nodes(c, a, b, list, scratch);
                shorter += list.size() < size_t(sc.t.num_nodes());
                expect_list_gives_the_whole_walks_answers(sc.t, c, sc.m, list, a, b, false, &pairs);
                if (HasFatalFailure()) return;
            }
    }
    EXPECT_GT(pairs, 100000u);
    EXPECT_GT(shorter, 1000u) << "the lists should leave out parts of the tree";
}

// The CPU backend's lists (box_walk_nodes: walk_shaft's box test and flat ends, no plane or
// disc tests) hold shaft_walk_nodes' (every entry of that list is in this one) and give every
// leaf pair under their node pair the whole walk's answer, one at a time and in packets of
// facing pairs (load_faced, the backend's path).
TEST(Construction, BoxListsHoldTheShaftListsAndGiveTheWholeWalksAnswers) {
    uint64_t pairs = 0, shorter = 0;
    for (uint64_t seed = 420; seed < 430; ++seed) {
        SCOPED_TRACE(seed);
        NodeTestScene sc(seed, 1 + int(seed % 3));
        detail::NodePairContext& c = sc.c;
        c.leaves_stored = true;
        ASSERT_GT(c.margin, 0.0);
        std::vector<WalkNode> list, shaft;
        std::vector<int32_t> scratch;
        for (int32_t a = 0; a < sc.t.num_nodes(); a += 1 + int32_t(seed % 2))
            for (int32_t b = sc.t.skip()[a]; b < sc.t.num_nodes(); b += 2 + int32_t(seed % 3)) {
                detail::box_walk_nodes(c, a, b, list, scratch);
                detail::shaft_walk_nodes(c, a, b, shaft, scratch);
                size_t k = 0;  // shaft's entries in order within list (same boxes, same leaves)
                for (const WalkNode& w : list)
                    if (k < shaft.size() && w.leaf == shaft[k].leaf && w.lo == shaft[k].lo &&
                        w.hi == shaft[k].hi)
                        ++k;
                ASSERT_EQ(k, shaft.size()) << "nodes " << a << ", " << b;
                shorter += list.size() < size_t(sc.t.num_nodes());
                expect_list_gives_the_whole_walks_answers(sc.t, c, sc.m, list, a, b, true, &pairs);
                if (HasFatalFailure()) return;
            }
    }
    EXPECT_GT(pairs, 100000u);
    EXPECT_GT(shorter, 1000u) << "the lists should leave out parts of the tree";
}

// The default decides node pairs (gpu_test and the Cuda cases check the same V-map on the GPU).
TEST(Construction, AutoDecidesNodePairsOnTheCpu) {
    const PointSet ps = test::sample(test::scene_path("cornell-bunny"), 1500, 2);
    BuildParams bp = test::cpu_params(7, 2);
    ASSERT_EQ(bp.construction, Construction::kAuto);
    BuildStats st;
    const VisibilityMap got = build_vmap(ps, bp, &st);
    EXPECT_EQ(st.construction, "nodes");
    EXPECT_LT(st.leaf_pairs_walked, st.leaf_pairs);
    bp.construction = Construction::kLeafPairs;
    const VisibilityMap ref = build_vmap(ps, bp);
    EXPECT_TRUE(std::ranges::equal(got.link_targets(), ref.link_targets()));
}

TEST(Construction, UnknownMethodIsRejected) {
    try {
        parse<Construction>("magic", "construction");
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_EQ(std::string(e.what()),
                  "construction: unknown value 'magic' (expected auto, nodes or leaf-pairs)");
    }
    EXPECT_EQ(parse<Construction>("leaf-pairs", "construction"), Construction::kLeafPairs);
}

}  // namespace
}  // namespace vmap
