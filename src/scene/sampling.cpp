// Area-weighted, seeded sampling of scene surfaces into points; raw point cloud loading.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "scene/elimination.h"
#include "util/progress.h"
#include "util/splitmix.h"
#include "vmap/error.h"
#include "vmap/io.h"
#include "vmap/normals.h"
#include "vmap/parallel.h"
#include "vmap/scene.h"

namespace vmap {
namespace {

// SplitMix64: a counter-based generator, so sample i depends only on (seed, i) and the result
// is the same for any thread count and standard library.
uint64_t mix(uint64_t x) { return detail::splitmix64(x); }
double u01(uint64_t bits) { return double(bits >> 11) * (1.0 / 9007199254740992.0); }

struct Tri {
    uint32_t surface, index;  // the surface, and the triangle in its mesh
    Vec3 a, b, c, n;
};

// Each emitting surface's points share its power: k points of disc area a on a surface of area
// S with emission E emit k a E, which the binomial count k makes differ from S E by a few
// percent; scaling their emission by S / (k a) makes the points emit exactly the surface's power.
void match_emitted_power(const std::vector<double>& area, const std::vector<uint32_t>& surface_of,
                         PointSet& ps) {
    std::vector<uint64_t> count(area.size(), 0);
    for (uint32_t s : surface_of) count[s]++;
    const double disc = M_PI * double(ps.radii[0]) * ps.radii[0];
    for (size_t i = 0; i < surface_of.size(); ++i) {
        const uint32_t s = surface_of[i];
        if (ps.emission[i] == Vec3{}) continue;
        ps.emission[i] = ps.emission[i] * float(area[s] / (double(count[s]) * disc));
    }
}

// A per-vertex value at barycentric weights (w0, w1, w2) of triangle t, or `whole` when the
// surface has none.
Vec3 at_corner(const std::vector<Vec3>& values, const Mesh& m, uint32_t t, Vec3 whole, double w0,
               double w1, double w2) {
    if (values.empty()) return whole;
    const auto& c = m.triangles[t];
    const Vec3 a = values[c[0]], b = values[c[1]], d = values[c[2]];
    return {float(w0 * a.x + w1 * b.x + w2 * d.x), float(w0 * a.y + w1 * b.y + w2 * d.y),
            float(w0 * a.z + w1 * b.z + w2 * d.z)};
}

void append_clouds(const Scene& scene, PointSet& ps) {
    for (const PointSet& c : scene.clouds) {
        ps.positions.insert(ps.positions.end(), c.positions.begin(), c.positions.end());
        ps.normals.insert(ps.normals.end(), c.normals.begin(), c.normals.end());
        ps.colors.insert(ps.colors.end(), c.colors.begin(), c.colors.end());
        ps.radii.insert(ps.radii.end(), c.radii.begin(), c.radii.end());
        ps.emission.insert(ps.emission.end(), c.emission.begin(), c.emission.end());
    }
}

}  // namespace

namespace {

// The scene's triangles with their cumulative areas, for area-weighted draws.
struct SurfaceDraw {
    const Scene& scene;
    std::vector<Tri> tris;
    std::vector<double> cdf;
    std::vector<double> surface_area;
    double area = 0;

    // The areas and the triangles in parallel, the running sums in one thread (in triangle
    // order: the same doubles, so the same draws, at any thread count).
    explicit SurfaceDraw(const Scene& sc) : scene(sc), surface_area(sc.surfaces.size(), 0.0) {
        std::vector<double> ar;
        std::vector<uint32_t> slot;
        for (uint32_t s = 0; s < sc.surfaces.size(); ++s) {
            const Mesh& m = sc.surfaces[s].mesh;
            const uint32_t n = uint32_t(m.triangles.size());
            ar.resize(n);
            slot.resize(n);
            parallel_for(n, [&](uint32_t k) {
                const double a = twice_area(m, k) * 0.5;
                ar[k] = a > 0 && std::isfinite(a) ? a : 0;  // degenerate: no area, not drawn
            });
            const size_t base = tris.size();
            uint32_t kept = 0;
            for (uint32_t k = 0; k < n; ++k) {
                if (ar[k] == 0) continue;
                slot[k] = kept++;
                area += ar[k];
                surface_area[s] += ar[k];
                cdf.push_back(area);
            }
            tris.resize(base + kept);
            parallel_for(n, [&](uint32_t k) {
                if (ar[k] == 0) return;
                const auto& t = m.triangles[k];
                const Vec3 a = m.vertices[t[0]], b = m.vertices[t[1]], c = m.vertices[t[2]];
                tris[base + slot[k]] = {s, k, a, b, c, cross(b - a, c - a) / float(2 * ar[k])};
            });
        }
    }
    static double twice_area(const Mesh& m, uint32_t k) {
        const auto& t = m.triangles[k];
        const Vec3 a = m.vertices[t[0]], b = m.vertices[t[1]], c = m.vertices[t[2]];
        const Vec3 x = cross(b - a, c - a);
        return std::sqrt(double(x.x) * x.x + double(x.y) * x.y + double(x.z) * x.z);
    }

    // Draw i of the stream `seed` into slot `at` of ps and surf (arrays already sized).
    void draw(uint64_t seed, uint64_t i, uint64_t at, PointSet& ps,
              std::vector<uint32_t>& surf) const {
        const uint64_t r0 = mix(seed + 3 * i), r1 = mix(seed + 3 * i + 1),
                       r2 = mix(seed + 3 * i + 2);
        const double pick = u01(r0) * area;
        size_t k = std::upper_bound(cdf.begin(), cdf.end(), pick) - cdf.begin();
        k = std::min(k, tris.size() - 1);
        const Tri& t = tris[k];
        // Uniform point in a triangle: (1 - sqrt(u), sqrt(u)(1 - v), sqrt(u) v).
        const double su = std::sqrt(u01(r1)), v = u01(r2);
        const double w0 = 1 - su, w1 = su * (1 - v), w2 = su * v;
        ps.positions[at] = {float(w0 * t.a.x + w1 * t.b.x + w2 * t.c.x),
                            float(w0 * t.a.y + w1 * t.b.y + w2 * t.c.y),
                            float(w0 * t.a.z + w1 * t.b.z + w2 * t.c.z)};
        ps.normals[at] = t.n;
        const SceneSurface& s = scene.surfaces[t.surface];
        ps.colors[at] = at_corner(s.vertex_colors, s.mesh, t.index, s.albedo, w0, w1, w2);
        ps.emission[at] = at_corner(s.vertex_emission, s.mesh, t.index, s.emission, w0, w1, w2);
        surf[at] = t.surface;
    }
};

void resize_points(PointSet& ps, std::vector<uint32_t>& surf, uint64_t n) {
    ps.positions.resize(n);
    ps.normals.resize(n);
    ps.colors.resize(n);
    ps.emission.resize(n);
    surf.resize(n);
}

// Blue noise by sample elimination (after Yuksel, "Sample Elimination for Generating Poisson
// Disk Sample Sets", 2015): of the candidates (uniform over the area), the one most crowded by
// its neighbours is removed, one at a time, until `keep` remain. detail::eliminate runs this in
// parallel rounds that give exactly the one-at-a-time result (an earlier try, which removed at
// once every candidate more crowded than all its neighbours and so was not that result, left
// 10% of the samples a neighbour closer than 0.6 splat radii, against under 1% one at a time).
// Crowding is the sum over the neighbours within 2 r_max of (1 - d / 2 r_max)^8, where r_max =
// sqrt(area / (2 sqrt(3) keep)) is the disc radius of the densest packing of `keep` discs on
// the area, and d is clamped below at 2 r_min (Yuksel's weight limit, r_min = 0.65 r_max (1 -
// (keep / candidates)^1.5)) so that a tight cluster does not outweigh everything else. Only
// neighbours on the same side of a surface count (normals less than 90 degrees apart): the two
// faces of a thin plate, or an object and the wall it touches, are thinned each on its own.
// Returns the kept candidates' indices, ascending. Deterministic: neither the neighbour lists
// nor the elimination depend on the thread count.
std::vector<uint64_t> eliminate(const std::vector<Vec3>& pos, const std::vector<Vec3>& nrm,
                                uint64_t keep, double area, const ProgressCallback& callback) {
    const uint64_t M = pos.size();
    if (keep >= M) {
        std::vector<uint64_t> all(M);
        for (uint64_t i = 0; i < M; ++i) all[i] = i;
        return all;
    }
    // The stage counts the candidates removed; the neighbour lists come first, at 0.
    detail::Progress progress("sampling (candidates removed)", M - keep, &callback,
                              "cpu (" + cpu_threads() + ")");
    const double rmax = std::sqrt(area / (2 * std::sqrt(3.0) * double(keep)));
    const double rmin = 0.65 * rmax * (1 - std::pow(double(keep) / double(M), 1.5));
    const detail::NeighbourLists lists = detail::same_side_neighbours(pos, nrm, 2 * rmax, 2 * rmin);
    progress.throw_if_cancelled();
    std::vector<uint64_t> kept = detail::eliminate(lists, keep, &progress);
    progress.finish();
    return kept;
}

// Candidates per kept sample for blue noise (Yuksel: 3-5x; more gives little).
constexpr uint64_t kBlueNoiseCandidates = 4;

}  // namespace

PointSet sample_scene(const Scene& scene, std::vector<uint32_t>* surface_of,
                      const ProgressCallback& progress) {
    const SurfaceDraw draw(scene);
    PointSet ps;
    if (draw.tris.empty() && !scene.clouds.empty()) {
        append_clouds(scene, ps);
        if (surface_of) surface_of->assign(ps.size(), kNoSurface);
        return ps;
    }
    if (draw.tris.empty())
        throw Error(fmt::format("{}: the scene has no surface area", scene.path));
    const uint64_t n = scene.points;
    if (n == 0) throw Error(fmt::format("{}: sampling.points must be at least 1", scene.path));
    std::vector<uint32_t> surf;
    const uint64_t seed = mix(scene.seed ^ 0x766d6170ULL);
    if (scene.pattern == SamplePattern::kUniform) {
        resize_points(ps, surf, n);
        parallel_for(n, [&](uint64_t i) { draw.draw(seed, i, i, ps, surf); });
    } else {
        const uint64_t m = n * kBlueNoiseCandidates;
        PointSet cand;
        std::vector<uint32_t> cand_surf;
        resize_points(cand, cand_surf, m);
        parallel_for(m, [&](uint64_t i) { draw.draw(seed, i, i, cand, cand_surf); });
        const std::vector<uint64_t> kept =
            eliminate(cand.positions, cand.normals, n, draw.area, progress);
        resize_points(ps, surf, n);
        parallel_for(n, [&](uint64_t k) {
            const uint64_t i = kept[k];
            ps.positions[k] = cand.positions[i];
            ps.normals[k] = cand.normals[i];
            ps.colors[k] = cand.colors[i];
            ps.emission[k] = cand.emission[i];
            surf[k] = cand_surf[i];
        });
    }
    // Each sample stands for an equal share of the area: a disc of that area.
    ps.radii.assign(n, float(std::sqrt(draw.area / (M_PI * double(n)))));
    match_emitted_power(draw.surface_area, surf, ps);
    append_clouds(scene, ps);
    if (surface_of) {
        *surface_of = std::move(surf);
        surface_of->resize(ps.size(), kNoSurface);
    }
    return ps;
}

namespace {

// Normals for a raw cloud per options; returns what was done, in words.
std::string complete_normals(PointSet& ps, const std::vector<Vec3>& sensors, const CloudOptions& o,
                             const std::string& path) {
    const bool had = ps.has_normals();
    std::optional<Vec3> view;  // o.viewpoint relative to the points' origin
    if (o.viewpoint) {
        const std::array<double, 3>& v = *o.viewpoint;
        view = Vec3{float(v[0] - ps.origin[0]), float(v[1] - ps.origin[1]),
                    float(v[2] - ps.origin[2])};
    }
    if (o.normals == NormalsMode::kFlip) {
        if (!had)
            throw Error(fmt::format("{}: --normals flip: the file has no normals to flip", path));
        for (Vec3& n : ps.normals) n = -n;
        if (view) orient_toward(ps, *view);
        return o.viewpoint ? "normals: the file's, flipped, then toward the viewpoint"
                           : "normals: the file's, flipped";
    }
    NormalEstimationParams np;
    if (o.normals == NormalsMode::kInward) np.orientation = Orientation::kInward;
    if (o.normals == NormalsMode::kOutward) np.orientation = Orientation::kOutward;
    if (o.viewpoint) {
        np.orientation = Orientation::kViewpoint;
        np.viewpoint = *view;
    }
    const bool estimate = !had || o.normals == NormalsMode::kEstimate;
    const bool sensed =
        estimate && !o.viewpoint && !sensors.empty() && np.orientation == Orientation::kAuto;
    if (sensed) np.orientation = Orientation::kOutward;  // replaced by the sensors below
    if (!estimate && o.normals == NormalsMode::kKeep && !o.viewpoint) return "";
    OrientationReport rep;
    if (estimate) {
        estimate_normals(ps, np, path.c_str(), &rep);
    } else {
        orient_normals(ps, np, path.c_str(), &rep);
    }
    if (o.viewpoint && ps.has_origin()) {  // the file's coordinates
        const std::array<double, 3>& v = *o.viewpoint;
        rep.method = fmt::format("toward the viewpoint ({}, {}, {})", v[0], v[1], v[2]);
    }
    if (sensed) {
        orient_toward(ps, sensors, path.c_str());
        rep.method = "toward the file's per-point sensor positions";
    }
    const std::string fits =
        rep.at_creases > 0
            ? fmt::format("plane, then jet fits, {} points at creases on a plane through them",
                          rep.at_creases)
            : std::string("plane, then jet fits");
    std::string line = fmt::format(
        "normals: {} ({}), oriented {}",
        estimate ? "estimated from the 24 nearest on each point's own sheet" : "the file's axes",
        estimate && had ? "the file's replaced; " + fits
        : estimate      ? fits
                        : "as given",
        rep.method);
    const size_t voted = rep.by_space + rep.by_rays + rep.by_shape + rep.by_view;
    if (!sensed && voted > 0)
        line += fmt::format(
            "; {} points by free space, {} toward where a scanner stood, {} by rays, {} by their "
            "open sheet's "
            "shape ({} of those then turned by their neighbours' votes), {} from their "
            "neighbours",
            rep.by_space, rep.by_view, rep.by_rays, rep.by_shape, rep.by_neighbours,
            ps.size() - voted);
    return line;
}

}  // namespace

PointSet load_point_cloud(const std::string& path, const CloudOptions& options,
                          std::vector<std::string>* done) {
    ModelData md = read_model(path);
    std::vector<std::string> lines;
    // Far from the file's zero, float positions lose what the file holds: read it again
    // relative to a point near the cloud (PointSet::origin).
    if (const auto origin = far_origin(md.points.positions)) {
        md = read_model(path, *origin);
        lines.push_back(fmt::format(
            "coordinates: relative to ({}, {}, {}), the cloud being far from the file's zero "
            "for its size; positions given and written are the file's",
            (*origin)[0], (*origin)[1], (*origin)[2]));
    }
    for (const std::string& note : md.notes) fmt::print(stderr, "note:       {}\n", note);
    PointSet ps = std::move(md.points);
    if (ps.size() == 0) throw Error(fmt::format("{}: the point cloud is empty", path));
    const std::string normals = complete_normals(ps, md.sensors, options, path);
    if (!normals.empty()) lines.push_back(normals);
    if (!ps.has_colors()) ps.colors.assign(ps.size(), Vec3{0.8f, 0.8f, 0.8f});
    if (!ps.has_radii()) {
        estimate_radii(ps, {}, path.c_str());
        lines.push_back("splat radii: estimated from the spacing of 8 same-surface neighbours");
    }
    if (done) *done = std::move(lines);
    return ps;
}

}  // namespace vmap
