// `vmap validate` (include/vmap/validate.h): V-map answers against exact visibility from the
// scene's triangles, per octree height; and Embree rays timed against the leaf-pair kernel.
#include "vmap/validate.h"

#include <fmt/format.h>
#include <tbb/combinable.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <nanoflann.hpp>
#include <nlohmann/json.hpp>
#include <random>

#include "octree/delta_rule.h"
#include "octree/records.h"
#include "util/progress.h"
#include "validate/npz.h"
#include "visibility/grid_walk.h"
#include "visibility/leaf_pair.h"
#include "vmap/error.h"
#include "vmap/io.h"
#include "vmap/normals.h"
#include "vmap/octree.h"
#include "vmap/visibility_map.h"

namespace vmap {

double Confusion::agreement() const {
    return total() ? double(true_visible + true_hidden) / double(total()) : 0.0;
}
double Confusion::false_visible_rate() const {
    return total() ? double(false_visible) / double(total()) : 0.0;
}
double Confusion::false_hidden_rate() const {
    return total() ? double(false_hidden) / double(total()) : 0.0;
}

namespace {

using Clock = std::chrono::steady_clock;

}  // namespace

void ValidateParams::check(const std::string& src) const {
    const ValidateParams& p = *this;
    if (p.pairs < 1 || p.pairs > 1000000000ull)
        throw Error(fmt::format("{}: pairs {} out of range (1..1000000000)", src, p.pairs));
    if (p.heights.empty()) throw Error(fmt::format("{}: heights: no height given", src));
    for (int h : p.heights)
        if (h < 1 || h > 21)
            throw Error(fmt::format("{}: heights: height {} out of range (1..21)", src, h));
    if (p.leaf_points < 0 || p.leaf_points > 1000000)
        throw Error(
            fmt::format("{}: leaf_points {} out of range (1..1000000)", src, p.leaf_points));
    if (p.points > 50000000)
        throw Error(fmt::format("{}: points {} out of range (1..50000000)", src, p.points));
    if (p.predict != "vmap" && p.predict != "direct")
        throw Error(fmt::format("{}: predict: unknown mode '{}' (expected vmap or direct)", src,
                                p.predict));
    if (!(p.bury_distance >= 0 && p.bury_distance <= 0.1))
        throw Error(
            fmt::format("{}: bury distance {} out of range [0, 0.1]", src, p.bury_distance));
    if (!(p.ray_offset > 0 && p.ray_offset <= 0.01))
        throw Error(fmt::format("{}: ray offset {} out of range (0, 0.01]", src, p.ray_offset));
    if (!p.as_cloud.empty() && p.as_cloud != "normals" && p.as_cloud != "bare" &&
        p.as_cloud != "sensors")
        throw Error(fmt::format(
            "{}: as_cloud: unknown mode '{}' (expected normals, bare or, with scan, sensors)", src,
            p.as_cloud));
    if (p.as_cloud == "sensors" && !p.scan)
        throw Error(fmt::format("{}: as_cloud sensors needs scan (the scanners' positions)", src));
    if (p.scan > 64)
        throw Error(fmt::format("{}: scan: {} scanners out of range (0..64)", src, p.scan));
    if (p.scan && !p.cloud.empty())
        throw Error(fmt::format("{}: give scan or cloud, not both", src));
    if (p.scan && !p.sampling.empty())
        throw Error(
            fmt::format("{}: sampling: a scan's points come from its beams, not a sample "
                        "pattern (give scan or sampling, not both)",
                        src));
    if (!p.as_cloud.empty() && !p.cloud.empty())
        throw Error(fmt::format("{}: give as_cloud or cloud, not both", src));
    if (!(p.noise >= 0 && p.noise <= 10))
        throw Error(fmt::format("{}: noise {} out of range [0, 10] sample spacings", src, p.noise));
    if (p.noise > 0 && p.as_cloud.empty() && !p.scan)
        throw Error(fmt::format("{}: noise needs as_cloud (normals or bare) or scan", src));
    if (p.eyes > 10000)
        throw Error(fmt::format("{}: eyes {} out of range (0..10000)", src, p.eyes));
    p.visibility.check(src);
    if (!(p.delta_scale >= 0.1f && p.delta_scale <= 10.f))
        throw Error(fmt::format("{}: delta_scale {} out of range [0.1, 10]", src, p.delta_scale));
    if (!(p.splat_floor <= 10.f))
        throw Error(fmt::format("{}: splat_floor {} out of range [0, 10]", src, p.splat_floor));
    if ((p.delta_scale != 1.f || p.splat_floor >= 0.f) && p.predict != "direct")
        throw Error(fmt::format(
            "{}: delta_scale/splat_floor change the octree's Delta rule and need predict "
            "direct (the V-map build uses the octree's own rule)",
            src));
}

namespace {

// Recomputes every leaf's Delta by the rule delta_scale * max(farthest, splat_floor * splat) and
// the content boxes (detail::apply_delta_rule, the builder's). `pts` in octree order.
void apply_delta_rule(Octree& t, const PointSet& pts, float scale, float floor) {
    double maxabs = 0;
    for (const Vec3& q : pts.positions)
        maxabs = std::max(
            {maxabs, double(std::fabs(q.x)), double(std::fabs(q.y)), double(std::fabs(q.z))});
    detail::apply_delta_rule(t, pts, scale, floor, detail::content_slack(maxabs, t.root_size()));
}

struct Pair {
    uint32_t i, j;
};

// Seeded uniform pairs i != j of n points; the same seed gives the same pairs everywhere.
std::vector<Pair> sample_pairs(uint64_t n, uint64_t count, uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::vector<Pair> out(count);
    for (Pair& p : out) {
        const uint64_t i = rng() % n;
        uint64_t j = rng() % (n - 1);
        if (j >= i) ++j;
        p = {uint32_t(i), uint32_t(j)};
    }
    return out;
}

// Leaf-pair evaluation as the V-map builder does it: the lower leaf index first.
struct DirectPredictor {
    const Octree& t;
    const VisibilityParams vp;     // in the octree's frame
    const detail::LeafGrid* grid;  // non-null: the grid walk
    bool operator()(int32_t a, int32_t b, WorkCounters* wc) const {
        if (a > b) std::swap(a, b);
        if (grid) return detail::grid_walk_leaf_pair_visible(t, *grid, a, b, vp, wc);
        return detail::leaf_pair_visible<true>(octree_view(t), a, b, vp, wc);
    }
};

}  // namespace

void add_surface_noise(std::vector<Vec3>& positions, const std::vector<float>& radii,
                       double spacings, uint64_t seed) {
    if (radii.size() != positions.size())
        throw Error(fmt::format("add_surface_noise: {} radii for {} points", radii.size(),
                                positions.size()));
    std::mt19937_64 rng(seed);
    std::normal_distribution<float> g(0.f, 1.f);
    for (size_t i = 0; i < positions.size(); ++i) {
        const float s = float(spacings * std::sqrt(M_PI)) * radii[i];
        positions[i] += Vec3{g(rng), g(rng), g(rng)} * s;
    }
}

namespace {

// The points a validation scores: the truth's (true positions, normals, model flags) and the
// prediction's (what the V-map is built from: the same points, perhaps with estimated normals
// and radii). Index i is the same point in both.
struct ScoredPoints {
    PointSet truth, pred;
    std::vector<uint8_t> on_model;
    std::vector<uint32_t> surface;  // the scene surface each point lies on (kNoSurface: none)
};

// Writes `pts` (positions, and normals when `normals`) as a PLY and reads it back through the
// raw-cloud path, as `vmap build cloud.ply` would.
// With noise > 0 each position first moves by Gaussian noise of `noise` sample spacings per
// axis (seeded, the same for every run).
// With `sensors`, the file carries each point's scanner position (sensor_x, sensor_y, sensor_z),
// as a scanner's export does.
PointSet through_cloud_path(const PointSet& pts, bool normals, double noise,
                            const std::string& path, const std::vector<Vec3>* sensors = nullptr) {
    PointSet bare;
    bare.positions = pts.positions;
    if (noise > 0) add_surface_noise(bare.positions, pts.radii, noise, 0x5ca90015eULL);
    if (normals) bare.normals = pts.normals;
    const std::string tmp =
        (std::filesystem::temp_directory_path() /
         fmt::format("vmap-validate-{}-{}.ply", ::getpid(), std::hash<std::string>{}(path)))
            .string();
    write_ply(tmp, bare, true, sensors ? *sensors : std::vector<Vec3>{});
    PointSet out;
    try {
        out = load_point_cloud(tmp);
    } catch (...) {
        std::filesystem::remove(tmp);
        throw;
    }
    std::filesystem::remove(tmp);
    return out;
}

struct CloudAdaptor3 {
    const std::vector<Vec3>& p;
    size_t kdtree_get_point_count() const { return p.size(); }
    float kdtree_get_pt(size_t i, size_t d) const {
        return d == 0 ? p[i].x : d == 1 ? p[i].y : p[i].z;
    }
    template <class B>
    bool kdtree_get_bbox(B&) const {
        return false;
    }
};

// A cloud file scored against the scene: each point takes the true normal and model flag of
// the nearest point of a dense sample of the scene's surfaces.
ScoredPoints cloud_file_points(const Scene& scene, const std::string& cloud) {
    ScoredPoints sp;
    sp.pred = load_point_cloud(cloud);
    to_file_frame(sp.pred);  // the scene's triangles are in the file's coordinates
    Scene dense = scene;
    dense.points = std::clamp<uint64_t>(8 * sp.pred.size(), 200000, 4000000);
    dense.pattern = SamplePattern::kUniform;  // a lookup table: no need to thin it
    std::vector<uint32_t> surf;
    const PointSet ref = sample_scene(dense, &surf);
    using Tree =
        nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, CloudAdaptor3>,
                                            CloudAdaptor3, 3, uint32_t>;
    CloudAdaptor3 ad{ref.positions};
    Tree tree(3, ad, nanoflann::KDTreeSingleIndexAdaptorParams(16));
    tree.buildIndex();
    const size_t n = sp.pred.size();
    sp.truth.positions = sp.pred.positions;
    sp.truth.normals.resize(n);
    sp.on_model.resize(n);
    sp.surface.resize(n);
    tbb::parallel_for(size_t(0), n, [&](size_t i) {
        const Vec3 q = sp.pred.positions[i];
        const float qq[3] = {q.x, q.y, q.z};
        uint32_t k = 0;
        float d2 = 0;
        tree.knnSearch(qq, 1, &k, &d2);
        sp.truth.normals[i] = ref.normals[k];
        sp.on_model[i] = surf[k] != kNoSurface && scene.surfaces[surf[k]].is_model;
        sp.surface[i] = surf[k];
    });
    return sp;
}

// A simulated scan's points (scan_scene), the prediction's through the raw-cloud path.
ScoredPoints scan_points(const Scene& sc, const ExactVisibility& exact, const ValidateParams& p,
                         const std::string& path) {
    ScanPoints scan =
        scan_scene(sc, exact, p.scan, p.points ? p.points : sc.points, p.scan_seed, path);
    ScoredPoints sp;
    sp.truth = std::move(scan.points);
    sp.surface = std::move(scan.surface);
    sp.on_model.resize(sp.surface.size());
    for (size_t i = 0; i < sp.surface.size(); ++i)
        sp.on_model[i] = sc.surfaces[sp.surface[i]].is_model;
    const bool sensors = p.as_cloud == "sensors";
    sp.pred = through_cloud_path(sp.truth, p.as_cloud == "normals", p.noise, path,
                                 sensors ? &scan.sensors : nullptr);
    return sp;
}

ScoredPoints scored_points(const Scene& sc, const ExactVisibility& exact, const ValidateParams& p,
                           const std::string& path) {
    if (!p.cloud.empty()) return cloud_file_points(sc, p.cloud);
    if (p.scan) return scan_points(sc, exact, p, path);
    ScoredPoints sp;
    std::vector<uint32_t> surf;
    sp.truth = sample_scene(sc, &surf);
    sp.on_model.resize(surf.size());
    for (size_t i = 0; i < surf.size(); ++i)
        sp.on_model[i] = surf[i] != kNoSurface && sc.surfaces[surf[i]].is_model;
    sp.surface = std::move(surf);
    if (p.as_cloud.empty())
        sp.pred = sp.truth;
    else
        sp.pred = through_cloud_path(sp.truth, p.as_cloud == "normals", p.noise, path);
    return sp;
}

// Leaves out the buried points (ValidateParams::drop_buried) from every array.
uint64_t drop_points(ScoredPoints& sp, const std::vector<uint8_t>& drop) {
    uint64_t dropped = 0;
    auto keep = [&](auto& v) {
        if (v.empty()) return;
        size_t o = 0;
        for (size_t i = 0; i < v.size(); ++i)
            if (!drop[i]) v[o++] = v[i];
        v.resize(o);
    };
    for (PointSet* ps : {&sp.truth, &sp.pred}) {
        keep(ps->positions), keep(ps->normals), keep(ps->colors), keep(ps->radii);
        keep(ps->emission);
    }
    keep(sp.on_model), keep(sp.surface);
    for (uint8_t d : drop) dropped += d;
    return dropped;
}

// 0 hidden, 1 visible, 2 same leaf: the V-map's answer for a point pair, or the leaf-pair
// predicate's on the pair's leaves (direct mode).
struct Predictor {
    const VisibilityMap* vm = nullptr;
    const Octree* tree = nullptr;
    const std::vector<uint32_t>* inverse = nullptr;
    const DirectPredictor* direct = nullptr;

    int32_t leaf(uint32_t i) const { return tree->leaf_of_point((*inverse)[i]); }
    uint8_t operator()(uint32_t i, uint32_t j, WorkCounters* wc) const {
        if (vm) {
            const PairVisibility v = vm->query(i, j);
            return v == PairVisibility::kSameLeaf ? 2 : v == PairVisibility::kVisible;
        }
        const int32_t a = leaf(i), b = leaf(j);
        if (a == b) return 2;
        wc->pairs++;
        const bool vis = (*direct)(a, b, wc);
        wc->visible_pairs += vis;
        return vis;
    }
};

std::vector<uint8_t> predict_pairs(const Predictor& pr, const std::vector<Pair>& pairs,
                                   WorkCounters* work) {
    std::vector<uint8_t> out(pairs.size());
    tbb::combinable<WorkCounters> counters;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, pairs.size(), 64), [&](const auto& rg) {
        WorkCounters& wc = counters.local();
        for (size_t k = rg.begin(); k < rg.end(); ++k) out[k] = pr(pairs[k].i, pairs[k].j, &wc);
    });
    if (work)
        *work = counters.combine([](WorkCounters x, const WorkCounters& y) {
            x += y;
            return x;
        });
    return out;
}

// Eye e against every point j != e, flattened eye-major (n - 1 entries an eye: j skips e).
std::vector<Pair> eye_pairs(const std::vector<uint32_t>& eyes, uint32_t n) {
    std::vector<Pair> out;
    out.reserve(eyes.size() * (n - 1));
    for (uint32_t e : eyes)
        for (uint32_t j = 0; j < n; ++j)
            if (j != e) out.push_back({e, j});
    return out;
}

// Seeded choice of `count` indices among those with `want(i)` (with repetition).
template <class F>
std::vector<uint32_t> sample_indices(uint32_t n, uint64_t count, uint64_t seed, F&& want) {
    std::vector<uint32_t> pool;
    for (uint32_t i = 0; i < n; ++i)
        if (want(i)) pool.push_back(i);
    std::vector<uint32_t> out;
    if (pool.empty()) return out;
    std::mt19937_64 rng(seed);
    for (uint64_t k = 0; k < count; ++k) out.push_back(pool[rng() % pool.size()]);
    return out;
}

// Pairs with one end on a model (uniform over model points), the other uniform over all.
std::vector<Pair> model_pair_sample(const std::vector<uint8_t>& on_model, uint64_t count,
                                    uint64_t seed) {
    const uint32_t n = uint32_t(on_model.size());
    const std::vector<uint32_t> ends =
        sample_indices(n, count, seed ^ 0x6d6f64656cULL, [&](uint32_t i) { return on_model[i]; });
    std::vector<Pair> out;
    std::mt19937_64 rng(seed ^ 0x6f74686572ULL);
    for (uint32_t i : ends) {
        uint32_t j = uint32_t(rng() % (n - 1));
        if (j >= i) ++j;
        out.push_back({i, j});
    }
    return out;
}

// The truth for a list of pairs: facing and not occluded (ExactVisibility::visible).
void truth_of(const ExactVisibility& exact, const PointSet& pts, const std::vector<Pair>& pairs,
              float offset, std::vector<uint8_t>& truth, std::vector<uint8_t>* facing) {
    truth.resize(pairs.size());
    if (facing) facing->resize(pairs.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, pairs.size(), 256), [&](const auto& rg) {
        for (size_t k = rg.begin(); k < rg.end(); ++k) {
            const auto [i, j] = pairs[k];
            const Vec3 a = pts.positions[i], b = pts.positions[j];
            const Vec3 na = pts.normals[i], nb = pts.normals[j];
            const bool f = ExactVisibility::facing(a, na, b, nb);
            if (facing) (*facing)[k] = f;
            truth[k] = f && exact.visible(a, na, b, nb, offset);
        }
    });
}

Confusion tally(const std::vector<uint8_t>& truth, const std::vector<uint8_t>& pred) {
    Confusion c;
    for (size_t k = 0; k < truth.size(); ++k)
        if (pred[k] != 2) c.add(truth[k], pred[k]);
    return c;
}

// Fraction of points whose predicted normal lies on the side of the true one.
std::pair<double, double> normal_agreement(const ScoredPoints& sp) {
    uint64_t n = 0, ok = 0, nm = 0, okm = 0;
    for (size_t i = 0; i < sp.pred.size(); ++i) {
        const bool good = dot(sp.pred.normals[i], sp.truth.normals[i]) > 0;
        ++n, ok += good;
        if (sp.on_model[i]) ++nm, okm += good;
    }
    return {n ? double(ok) / n : 1.0, nm ? double(okm) / nm : 1.0};
}

// The sampled pairs of one validation, with their truth.
struct PairSets {
    std::vector<Pair> pairs, model, eyes_model, eyes_all;
    std::vector<uint32_t> eye_model, eye_all;  // the eyes (eyes_model: eye_model[k] vs all)
    std::vector<uint8_t> truth, facing, truth_model, truth_eyes_model, truth_eyes_all;
};

// The predictions for the eye pair sets at one height (0 hidden, 1 visible, 2 same leaf).
struct EyeAnswers {
    std::vector<uint8_t> model, all;
};

// What answers a height's queries: the V-map, or the octree with the direct predicate.
struct HeightPredictor {
    VisibilityMap vm;
    Octree t;
    std::vector<uint32_t> inverse;
    std::unique_ptr<detail::LeafGrid> grid;
    std::unique_ptr<DirectPredictor> direct;
    Predictor pr;
};

void build_predictor(HeightPredictor& hp, HeightResult& row, const PointSet& pred_pts,
                     const ValidateParams& params, const OctreeParams& op,
                     const std::string& path) {
    if (params.predict == "vmap") {
        BuildParams bp;
        bp.octree = op;
        bp.visibility = params.visibility;
        bp.backend = params.backend;
        bp.occluders = params.occluders;
        BuildStats st;
        hp.vm = build_vmap(pred_pts, bp, &st, path);
        row.height = hp.vm.octree().height();
        row.leaves = hp.vm.octree().num_leaves();
        row.links = hp.vm.num_links();
        row.work = st.work;
        row.backend = st.backend;
        hp.pr.vm = &hp.vm;
        return;
    }
    PointSet copy = pred_pts;
    std::vector<uint32_t> order;
    hp.t = Octree::build(copy, op, order, path);
    if (params.delta_scale != 1.f || params.splat_floor >= 0.f)
        apply_delta_rule(hp.t, copy, params.delta_scale, op.delta_floor);
    hp.inverse.resize(order.size());
    for (uint32_t k = 0; k < order.size(); ++k) hp.inverse[order[k]] = k;
    if (params.occluders == OccluderSearch::kGridWalk)
        hp.grid = std::make_unique<detail::LeafGrid>(hp.t);
    row.height = hp.t.height();
    row.leaves = hp.t.num_leaves();
    row.backend = params.occluders == OccluderSearch::kGridWalk ? "direct, cpu grid walk"
                                                                : "direct, cpu boxes";
    hp.direct = std::make_unique<DirectPredictor>(
        DirectPredictor{hp.t, in_octree_frame(params.visibility, hp.t.scale()), hp.grid.get()});
    hp.pr.tree = &hp.t, hp.pr.inverse = &hp.inverse, hp.pr.direct = hp.direct.get();
}

// One octree height: build the V-map (or the octree alone, direct mode) from the prediction's
// points and score every pair set; the eye sets' answers go to `answers` when given.
HeightResult validate_height(const PointSet& pred_pts, const PairSets& ps,
                             const std::vector<uint8_t>& buried, const ValidateParams& params,
                             int leaf_points, int max_height, float delta_floor,
                             const std::string& path, EyeAnswers* answers) {
    HeightResult row;
    row.max_height = max_height;
    row.leaf_points = leaf_points;
    OctreeParams op;
    op.max_height = max_height;
    op.leaf_points = leaf_points;
    op.delta_floor = delta_floor;
    const auto tb = Clock::now();
    HeightPredictor hp;
    build_predictor(hp, row, pred_pts, params, op, path);
    row.build_seconds = seconds_since(tb);
    const auto tq = Clock::now();
    WorkCounters work;
    const std::vector<uint8_t> pred = predict_pairs(hp.pr, ps.pairs, &work);
    if (params.predict != "vmap") row.work = work;
    row.predict_seconds = seconds_since(tq);
    for (size_t k = 0; k < ps.pairs.size(); ++k) {
        if (pred[k] == 2) {
            row.same_leaf++;
            row.same_leaf_visible += ps.truth[k];
            continue;
        }
        row.all.add(ps.truth[k], pred[k]);
        if (ps.facing[k]) row.facing.add(ps.truth[k], pred[k]);
        if (!buried[ps.pairs[k].i] && !buried[ps.pairs[k].j]) row.live.add(ps.truth[k], pred[k]);
    }
    row.model = tally(ps.truth_model, predict_pairs(hp.pr, ps.model, nullptr));
    EyeAnswers eyes{predict_pairs(hp.pr, ps.eyes_model, nullptr),
                    predict_pairs(hp.pr, ps.eyes_all, nullptr)};
    row.eyes_model = tally(ps.truth_eyes_model, eyes.model);
    row.eyes_all = tally(ps.truth_eyes_all, eyes.all);
    if (answers) *answers = std::move(eyes);
    return row;
}

// Eye-major answers (n - 1 an eye, skipping the eye) as an eyes x n array; the eye's own entry
// is `self`.
std::vector<uint8_t> eye_square(const std::vector<uint8_t>& flat, const std::vector<uint32_t>& eyes,
                                uint32_t n, uint8_t self) {
    std::vector<uint8_t> out(eyes.size() * size_t(n), self);
    for (size_t k = 0; k < eyes.size(); ++k)
        for (uint32_t j = 0; j < n; ++j)
            if (j != eyes[k]) out[k * n + j] = flat[k * (n - 1) + (j < eyes[k] ? j : j - 1)];
    return out;
}

// --dump-eyes (docs/validation.md "Hidden point removal"): the points, the eyes, the truth and
// the V-map's answers of the first height, as an .npz.
void write_eye_dump(const std::string& file, const ScoredPoints& sp, const PairSets& ps,
                    const EyeAnswers& answers, const ValidationReport& r) {
    using detail::npy_array;
    const uint64_t n = sp.truth.size();
    auto vec3 = [&](const char* name, const std::vector<Vec3>& v) {
        return npy_array(name, "<f4", {n, 3}, &v[0].x, 3 * v.size());
    };
    auto u8 = [&](const char* name, const std::vector<uint8_t>& v, uint64_t rows) {
        return npy_array(name, "|u1", {rows, n}, v.data(), v.size());
    };
    auto u32 = [&](const char* name, const std::vector<uint32_t>& v) {
        return npy_array(name, "<u4", {v.size()}, v.data(), v.size());
    };
    const uint64_t e = ps.eye_model.size();
    const HeightResult& h = r.rows.front();
    const double offset = r.offset;
    const int32_t ints[3] = {h.max_height, h.height, h.leaves};
    detail::write_npz(
        file,
        {vec3("positions", sp.truth.positions), vec3("normals", sp.truth.normals),
         vec3("pred_normals", sp.pred.normals),
         npy_array("pred_radii", "<f4", {sp.pred.radii.size()}, sp.pred.radii.data(),
                   sp.pred.radii.size()),
         npy_array("on_model", "|u1", {n}, sp.on_model.data(), n), u32("surface", sp.surface),
         u32("eyes_model", ps.eye_model), u32("eyes_all", ps.eye_all),
         u8("truth_eyes_model", eye_square(ps.truth_eyes_model, ps.eye_model, n, 0), e),
         u8("pred_eyes_model", eye_square(answers.model, ps.eye_model, n, 2), e),
         u8("truth_eyes_all", eye_square(ps.truth_eyes_all, ps.eye_all, n, 0), e),
         u8("pred_eyes_all", eye_square(answers.all, ps.eye_all, n, 2), e),
         npy_array("offset", "<f8", {}, &offset, 1), npy_array("octree", "<i4", {3}, ints, 3)});
}

}  // namespace

namespace {

// The scene a validation takes its truth from: a scene file or a mesh, without point clouds.
Scene validation_scene(const std::string& path, const ValidateParams& params) {
    params.check(path);
    if (!is_scene_input(path))
        throw Error(
            fmt::format("{}: validate needs a scene file (.json) or a mesh: a point cloud has no "
                        "triangles to take the truth from",
                        path));
    Scene sc = load_scene(path);
    if (!sc.clouds.empty())
        throw Error(
            fmt::format("{}: clouds: validate takes the truth from triangles, which a "
                        "point cloud does not have",
                        path));
    if (params.points) sc.points = params.points;
    if (!params.sampling.empty()) sc.pattern = parse<SamplePattern>(params.sampling, "sampling");
    return sc;
}

// Buried points: a triangle in front of the point within `bury` along its true normal.
std::vector<uint8_t> buried_flags(const ExactVisibility& exact, const PointSet& truth,
                                  double offset, double bury) {
    std::vector<uint8_t> b(truth.size());
    tbb::parallel_for(size_t(0), truth.size(), [&](size_t i) {
        const Vec3 q = truth.positions[i], nq = truth.normals[i];
        b[i] = exact.occluded(q, q + nq, float(offset), float(bury));
    });
    return b;
}

// The report's description of the points and settings, before any pair is scored.
ValidationReport report_header(const Scene& sc, const ScoredPoints& sp, const std::string& path,
                               const ValidateParams& params) {
    ValidationReport r;
    r.scene = sc.name;
    r.path = path;
    r.points = sp.truth.size();
    r.pairs = params.pairs;
    r.params = params;
    const std::string what =
        params.scan ? fmt::format("a simulated scan from {} scanner{} (seed {})", params.scan,
                                  params.scan > 1 ? "s" : "", params.scan_seed)
                    : "the samples";
    r.source = !params.cloud.empty()          ? "the cloud " + params.cloud
               : params.as_cloud == "normals" ? what + " as a raw cloud with true normals"
               : params.as_cloud == "bare"
                   ? what + " as a bare raw cloud (normals and radii estimated)"
               : params.as_cloud == "sensors"
                   ? what +
                         " as a raw cloud with its scanner positions (normals estimated and "
                         "turned toward them, radii estimated)"
                   : "the scene's samples";
    if (params.noise > 0)
        r.source += fmt::format(", moved by noise of {} sample spacings per axis", params.noise);
    if (!r.params.leaf_points)
        r.params.leaf_points = sc.octree ? sc.octree->leaf_points : OctreeParams{}.leaf_points;
    std::tie(r.normal_agreement, r.normal_agreement_model) = normal_agreement(sp);
    for (uint8_t m : sp.on_model) r.model_points += m;
    return r;
}

// Every pair set of the validation with its truth: uniform pairs, model pairs and the eyes.
PairSets sample_truth(const ExactVisibility& exact, const ScoredPoints& sp,
                      const ValidateParams& params, ValidationReport& r) {
    const PointSet& pts = sp.truth;
    const uint32_t n = uint32_t(pts.size());
    const float offset = float(r.offset);
    PairSets ps;
    ps.pairs = sample_pairs(n, params.pairs, params.pair_seed);
    truth_of(exact, pts, ps.pairs, offset, ps.truth, &ps.facing);
    for (size_t k = 0; k < ps.pairs.size(); ++k)
        r.truth_facing += ps.facing[k], r.truth_visible += ps.truth[k];
    ps.model = model_pair_sample(sp.on_model, params.pairs, params.pair_seed);
    r.model_pairs = ps.model.size();
    truth_of(exact, pts, ps.model, offset, ps.truth_model, nullptr);
    if (params.eyes && r.model_points) {
        auto on_model = [&](uint32_t i) { return bool(sp.on_model[i]); };
        auto any = [](uint32_t) { return true; };
        ps.eye_model = sample_indices(n, params.eyes, params.eye_seed, on_model);
        ps.eye_all = sample_indices(n, params.eyes, params.eye_seed + 1, any);
        ps.eyes_model = eye_pairs(ps.eye_model, n);
        ps.eyes_all = eye_pairs(ps.eye_all, n);
        truth_of(exact, pts, ps.eyes_model, offset, ps.truth_eyes_model, nullptr);
        truth_of(exact, pts, ps.eyes_all, offset, ps.truth_eyes_all, nullptr);
        r.eyes = params.eyes;
    }
    return ps;
}

}  // namespace

ValidationReport validate_scene(const std::string& path, const ValidateParams& given) {
    ValidateParams params = given;
    if (params.scan && params.as_cloud.empty()) params.as_cloud = "bare";
    const Scene sc = validation_scene(path, params);
    const auto t_embree = Clock::now();
    ExactVisibility exact(sc.surfaces, path);
    const double embree_seconds = seconds_since(t_embree);
    ScoredPoints sp = scored_points(sc, exact, params, path);
    // A raw cloud's predicate takes the roughness of its measured noise, as `vmap build` does.
    if (params.measure_roughness && (!params.as_cloud.empty() || !params.cloud.empty()))
        params.visibility.roughness = roughness_of(estimate_surface_noise(sp.pred));
    const float room = std::max({sc.room_size.x, sc.room_size.y, sc.room_size.z});
    const auto t0 = Clock::now();  // the truth's time: Embree's scene and the rays
    const double offset = params.ray_offset * room, bury = params.bury_distance * room;
    // What not sampling covered surface would give: the same points less the buried ones.
    const uint64_t dropped =
        params.drop_buried ? drop_points(sp, buried_flags(exact, sp.truth, offset, bury)) : 0;
    const uint64_t n = sp.truth.size();
    if (n < 2) throw Error(fmt::format("{}: {} point(s): no pairs to validate", path, n));

    ValidationReport r = report_header(sc, sp, path, params);
    const bool raw = !params.as_cloud.empty() || !params.cloud.empty();
    r.delta_floor = params.splat_floor >= 0.f ? params.splat_floor
                    : raw                     ? cloud_delta_floor(sp.pred)
                                              : scene_octree(sc).delta_floor;
    r.dropped_points = dropped;
    r.offset = offset;
    r.triangles = exact.triangles();
    const PairSets ps = sample_truth(exact, sp, params, r);
    r.bury_distance = bury;
    const std::vector<uint8_t> buried = buried_flags(exact, sp.truth, offset, bury);
    for (uint8_t b : buried) r.buried_points += b;
    for (const Pair& q : ps.pairs) r.live_pairs += !buried[q.i] && !buried[q.j];
    r.truth_seconds = embree_seconds + seconds_since(t0);

    detail::Progress progress("heights", params.heights.size(), &params.progress);
    for (size_t hi = 0; hi < params.heights.size(); ++hi) {
        EyeAnswers answers;
        const bool dump = hi == 0 && !params.dump_eyes.empty();
        r.rows.push_back(validate_height(sp.pred, ps, buried, params, r.params.leaf_points,
                                         params.heights[hi], r.delta_floor, path,
                                         dump ? &answers : nullptr));
        if (dump) write_eye_dump(params.dump_eyes, sp, ps, answers, r);
        progress.set(hi + 1);
        progress.throw_if_cancelled();
    }
    return r;
}

namespace {

std::string pct(double f) { return fmt::format("{:.2f}%", 100.0 * f); }

}  // namespace

std::string validation_markdown(const ValidationReport& r) {
    const auto& p = r.params;
    const auto& vp = p.visibility;
    std::string s;
    s += fmt::format("### {} ({}): {} points, {} pairs (seed {})\n\n", r.scene, r.path, r.points,
                     r.pairs, p.pair_seed);
    s += fmt::format(
        "Truth: {} pairs face each other ({}), {} visible ({}); {} triangles (Embree 3 "
        "occlusion rays, ends trimmed by {:.3g} = {:g} of the room's largest extent); {:.2f} s.  "
        "\n",
        r.truth_facing, pct(double(r.truth_facing) / r.pairs), r.truth_visible,
        pct(double(r.truth_visible) / r.pairs), r.triangles, r.offset, p.ray_offset,
        r.truth_seconds);
    s += fmt::format(
        "Prediction: {} ({} occluders); K {}, eps {:g}, facing_tol {:g}, parallel_tol {:g}, "
        "roughness {:g}, core {:g}; "
        "leaf_points {}; Delta = {:g} max(farthest point, {:g} splat radius).  \n"
        "Buried points (a triangle within {:.3g} in front): {} ({}); pairs without one "
        "(\"live\"): {}{}.\n\n",
        p.predict == "vmap" ? "V-map query" : "leaf-pair predicate on the pairs' leaves (direct)",
        name_of(p.occluders), vp.K, vp.eps, vp.facing_tol, vp.parallel_tol, vp.roughness, vp.core,
        p.leaf_points, p.delta_scale, r.delta_floor, r.bury_distance, r.buried_points,
        pct(double(r.buried_points) / r.points), r.live_pairs,
        r.dropped_points ? fmt::format(" (after dropping {} buried points before sampling pairs)",
                                       r.dropped_points)
                         : std::string());
    s += "| max_height | height | leaves | links | same leaf (vis.) | pairs | agreement | "
         "false visible | false hidden | facing pairs | agreement | false visible | false hidden "
         "| live pairs | agreement | false visible | false hidden | build s | predict s |\n";
    s += "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
         "---:|---:|\n";
    for (const HeightResult& h : r.rows)
        s += fmt::format(
            "| {} | {} | {} | {} | {} ({}) | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | "
            "{} | {} | {:.2f} | {:.3f} |\n",
            h.max_height, h.height, h.leaves, h.links, h.same_leaf, h.same_leaf_visible,
            h.all.total(), pct(h.all.agreement()), pct(h.all.false_visible_rate()),
            pct(h.all.false_hidden_rate()), h.facing.total(), pct(h.facing.agreement()),
            pct(h.facing.false_visible_rate()), pct(h.facing.false_hidden_rate()), h.live.total(),
            pct(h.live.agreement()), pct(h.live.false_visible_rate()),
            pct(h.live.false_hidden_rate()), h.build_seconds, h.predict_seconds);
    s += "\n";
    s += fmt::format(
        "Where people look: {} model points ({}); {} pairs with one end on a model; {} eyes on "
        "the models and {} uniform eyes, each against every point (pairs sharing a leaf left "
        "out).  \nPrediction built from {}; normals on the true side: {} of all points, {} of "
        "model points.\n\n",
        r.model_points, pct(double(r.model_points) / std::max<uint64_t>(1, r.points)),
        r.model_pairs, r.eyes, r.eyes, r.source, pct(r.normal_agreement),
        pct(r.normal_agreement_model));
    s += "| max_height | model pairs | agreement | false visible | false hidden | eyes on models "
         "| agreement | false visible | false hidden | eyes uniform | agreement | false visible | "
         "false hidden |\n";
    s += "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
    for (const HeightResult& h : r.rows) {
        s += fmt::format("| {} ", h.max_height);
        for (const Confusion* c : {&h.model, &h.eyes_model, &h.eyes_all})
            s += fmt::format("| {} | {} | {} | {} ", c->total(), pct(c->agreement()),
                             pct(c->false_visible_rate()), pct(c->false_hidden_rate()));
        s += "|\n";
    }
    s += "\n";
    return s;
}

std::string validation_json(const ValidationReport& r) {
    using nlohmann::json;
    auto conf = [](const Confusion& c) {
        return json{{"true_visible", c.true_visible},
                    {"true_hidden", c.true_hidden},
                    {"false_visible", c.false_visible},
                    {"false_hidden", c.false_hidden},
                    {"total", c.total()},
                    {"agreement", c.agreement()},
                    {"false_visible_rate", c.false_visible_rate()},
                    {"false_hidden_rate", c.false_hidden_rate()}};
    };
    const auto& p = r.params;
    json j{{"scene", r.scene},
           {"path", r.path},
           {"points", r.points},
           {"pairs", r.pairs},
           {"pair_seed", p.pair_seed},
           {"truth_facing", r.truth_facing},
           {"truth_visible", r.truth_visible},
           {"buried_points", r.buried_points},
           {"dropped_points", r.dropped_points},
           {"live_pairs", r.live_pairs},
           {"bury_distance", r.bury_distance},
           {"triangles", r.triangles},
           {"ray_offset", r.offset},
           {"ray_offset_relative", p.ray_offset},
           {"truth_seconds", r.truth_seconds},
           {"predict", p.predict},
           {"occluders", name_of(p.occluders)},
           {"leaf_points", p.leaf_points},
           {"K", p.visibility.K},
           {"eps", p.visibility.eps},
           {"facing_tol", p.visibility.facing_tol},
           {"parallel_tol", p.visibility.parallel_tol},
           {"roughness", p.visibility.roughness},
           {"core", p.visibility.core},
           {"delta_scale", p.delta_scale},
           {"splat_floor", r.delta_floor},
           {"model_points", r.model_points},
           {"model_pairs", r.model_pairs},
           {"eyes", r.eyes},
           {"eye_seed", p.eye_seed},
           {"source", r.source},
           {"normal_agreement", r.normal_agreement},
           {"normal_agreement_model", r.normal_agreement_model}};
    json rows = json::array();
    for (const HeightResult& h : r.rows)
        rows.push_back(json{{"max_height", h.max_height},
                            {"height", h.height},
                            {"leaves", h.leaves},
                            {"links", h.links},
                            {"same_leaf", h.same_leaf},
                            {"same_leaf_visible", h.same_leaf_visible},
                            {"all", conf(h.all)},
                            {"facing", conf(h.facing)},
                            {"live", conf(h.live)},
                            {"model", conf(h.model)},
                            {"eyes_model", conf(h.eyes_model)},
                            {"eyes_all", conf(h.eyes_all)},
                            {"build_seconds", h.build_seconds},
                            {"predict_seconds", h.predict_seconds},
                            {"backend", h.backend},
                            {"work",
                             {{"pairs", h.work.pairs},
                              {"facing_pairs", h.work.facing_pairs},
                              {"visible_pairs", h.work.visible_pairs},
                              {"node_tests", h.work.node_tests},
                              {"occluder_tests", h.work.occluder_tests},
                              {"cells_stepped", h.work.cells_stepped}}}});
    j["heights"] = rows;
    return j.dump(1) + "\n";
}

// ---- Embree rays against the kernel ---------------------------------------------------------

namespace {

Spread spread(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    const size_t n = v.size();
    return {n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]), v.front(), v.back()};
}

}  // namespace

namespace {

using LeafPairs = std::vector<std::pair<int32_t, int32_t>>;

// Leaf pairs a < b: all of them when they fit the sample, else seeded blocks of 8 rows by 32
// consecutive columns at uniform places above the diagonal: the access pattern of a V-map
// build (one leaf against 32 neighbouring leaves, neighbouring rows after each other; the same
// as `vmap bench` samples), so caches behave for both methods as in a real run.
LeafPairs sample_leaf_pairs(int32_t L, uint64_t count) {
    LeafPairs lp;
    const uint64_t all = uint64_t(L) * (L - 1) / 2;
    if (all <= count || L < 80) {
        for (int32_t a = 0; a < L; ++a)
            for (int32_t b = a + 1; b < L; ++b) lp.emplace_back(a, b);
        return lp;
    }
    std::mt19937_64 rng(7);
    while (lp.size() < count) {
        int32_t a = int32_t(rng() % uint64_t(L - 40)), b = int32_t(rng() % uint64_t(L - 40));
        if (a > b) std::swap(a, b);
        if (b - a < 8) continue;
        for (int32_t r = 0; r < 8; ++r)
            for (int32_t c = 0; c < 32 && b + c < L; ++c) lp.emplace_back(a + r, b + c);
    }
    lp.resize(count);
    return lp;
}

// The three timed methods over one leaf-pair sample, each writing its answers.
struct TimedPasses {
    const OctreeView v;
    const VisibilityParams vp;
    const ExactVisibility& exact;
    const LeafPairs& lp;
    std::vector<uint8_t> kern, ray, occ;
    std::vector<Vec3> from, to;
    std::vector<size_t> idx;  // the facing pairs, in packet order

    float t0() const { return vp.eps; }
    float t1() const { return 1.f - vp.eps; }
    bool facing(size_t k, Vec3& a, Vec3& b) const {
        const LeafDisc& la = v.leaves[lp[k].first];
        const LeafDisc& lb = v.leaves[lp[k].second];
        a = la.centroid, b = lb.centroid;
        const Vec3 d = b - a;
        const float len = length(d);
        return len > 0 && detail::leaves_face(la, lb, d, len, vp);
    }
    // Work of one counted kernel pass (not timed).
    WorkCounters counted_kernel() {
        tbb::combinable<WorkCounters> c;
        tbb::parallel_for(size_t(0), lp.size(), [&](size_t k) {
            kern[k] = detail::leaf_pair_visible<true>(v, lp[k].first, lp[k].second, vp, &c.local());
        });
        WorkCounters w = c.combine([](WorkCounters x, const WorkCounters& y) {
            x += y;
            return x;
        });
        w.pairs = lp.size();
        return w;
    }
    void kernel() {
        tbb::parallel_for(tbb::blocked_range<size_t>(0, lp.size(), 256), [&](const auto& rg) {
            for (size_t k = rg.begin(); k < rg.end(); ++k)
                kern[k] = detail::leaf_pair_visible<false>(v, lp[k].first, lp[k].second, vp,
                                                           static_cast<WorkCounters*>(nullptr));
        });
    }
    void ray1() {
        tbb::parallel_for(tbb::blocked_range<size_t>(0, lp.size(), 256), [&](const auto& rg) {
            for (size_t k = rg.begin(); k < rg.end(); ++k) {
                Vec3 a, b;
                ray[k] = facing(k, a, b) && !exact.occluded(a, b, t0(), t1());
            }
        });
    }
    void ray16() {
        from.clear(), to.clear(), idx.clear();
        for (size_t k = 0; k < lp.size(); ++k) {
            Vec3 a, b;
            if (facing(k, a, b)) from.push_back(a), to.push_back(b), idx.push_back(k);
        }
        exact.occluded_packets(from, to, t0(), t1(), occ);
    }
};

// Warm-up, then the three passes in turn in every run, so a change in machine load during the
// measurement falls on all three alike; then the answers compared.
void time_passes(TimedPasses& tp, int runs, EmbreeTiming& r, const std::string& path) {
    tp.kernel(), tp.ray1(), tp.ray16();
    std::vector<double> tk, t1s, t16;
    auto time_of = [](auto&& f) {
        const auto tb = Clock::now();
        f();
        return seconds_since(tb);
    };
    for (int k = 0; k < runs; ++k) {
        tk.push_back(time_of([&] { tp.kernel(); }));
        t1s.push_back(time_of([&] { tp.ray1(); }));
        t16.push_back(time_of([&] { tp.ray16(); }));
    }
    r.kernel_s = spread(tk);
    r.ray1_s = spread(t1s);
    r.ray16_s = spread(t16);
    r.facing = tp.idx.size();
    for (size_t k = 0; k < tp.lp.size(); ++k) {
        r.kernel_visible += tp.kern[k];
        r.ray_visible += tp.ray[k];
        r.agree += tp.kern[k] == tp.ray[k];
    }
    // The packet pass must give the single-ray answers.
    for (size_t m = 0; m < tp.idx.size(); ++m)
        if (!tp.occ[m] != bool(tp.ray[tp.idx[m]]))
            throw Error(
                fmt::format("{}: Embree rtcOccluded16 and rtcOccluded1 disagree on leaf pair {}",
                            path, tp.idx[m]));
}

void check_timing_params(const EmbreeTimingParams& p, const std::string& path) {
    p.visibility.check(path);
    if (p.runs < 1 || p.runs > 100)
        throw Error(fmt::format("{}: runs {} out of range (1..100)", path, p.runs));
    if (p.sample_pairs < 1 || p.sample_pairs > 1000000000ull)
        throw Error(
            fmt::format("{}: --pairs {} out of range (1..1000000000)", path, p.sample_pairs));
}

}  // namespace

EmbreeTiming time_embree(const std::string& path, const EmbreeTimingParams& p) {
    check_timing_params(p, path);
    Scene sc = load_scene(path);
    if (p.points) sc.points = p.points;
    PointSet pts = sample_scene(sc);
    OctreeParams op;
    op.max_height = p.max_height;
    op.leaf_points =
        p.leaf_points ? p.leaf_points : (sc.octree ? sc.octree->leaf_points : op.leaf_points);
    std::vector<uint32_t> order;
    const Octree t = Octree::build(pts, op, order, path);
    ExactVisibility exact(sc.surfaces, path);

    EmbreeTiming r;
    r.scene = sc.name;
    r.points = pts.size();
    r.triangles = exact.triangles();
    r.height = t.height();
    r.leaf_points = op.leaf_points;
    r.leaves = t.num_leaves();
    r.threads = int(std::min<size_t>(
        tbb::this_task_arena::max_concurrency(),
        tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism)));
    if (t.num_leaves() < 2)
        throw Error(fmt::format("{}: the octree has one leaf: no leaf pairs", path));
    const LeafPairs lp = sample_leaf_pairs(t.num_leaves(), p.sample_pairs);
    r.pairs = lp.size();
    TimedPasses tp{octree_view(t),
                   in_octree_frame(p.visibility, t.scale()),
                   exact,
                   lp,
                   {},
                   {},
                   {},
                   {},
                   {},
                   {}};
    tp.kern.resize(lp.size()), tp.ray.resize(lp.size());
    r.kernel_work = tp.counted_kernel();
    time_passes(tp, p.runs, r, path);
    return r;
}

std::string embree_timing_markdown(const std::vector<EmbreeTiming>& rows) {
    std::string s =
        "| scene | points | triangles | height | leaves | threads | leaf pairs | facing | "
        "kernel s (min-max) | kernel pairs/s | rtcOccluded1 s (min-max) | rays/s | pairs/s | "
        "rtcOccluded16 s (min-max) | rays/s | pairs/s | kernel = ray |\n"
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
    for (const EmbreeTiming& r : rows) {
        auto sp = [](const Spread& x) {
            return fmt::format("{:.3f} ({:.3f}-{:.3f})", x.median, x.lo, x.hi);
        };
        auto rate = [](double n, double s) { return fmt::format("{:.3g}", n / std::max(1e-9, s)); };
        s += fmt::format(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | "
            "{} | {} | {:.2f}% |\n",
            r.scene, r.points, r.triangles, r.height, r.leaves, r.threads, r.pairs, r.facing,
            sp(r.kernel_s), rate(r.pairs, r.kernel_s.median), sp(r.ray1_s),
            rate(r.facing, r.ray1_s.median), rate(r.pairs, r.ray1_s.median), sp(r.ray16_s),
            rate(r.facing, r.ray16_s.median), rate(r.pairs, r.ray16_s.median),
            100.0 * r.agree / std::max<uint64_t>(1, r.pairs));
    }
    return s;
}

}  // namespace vmap
