// Area-weighted, seeded sampling of scene surfaces into points; raw point cloud loading.
#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <nanoflann.hpp>

#include "vmap/error.h"
#include "vmap/io.h"
#include "vmap/normals.h"
#include "vmap/scene.h"

namespace vmap {
namespace {

// SplitMix64: a counter-based generator, so sample i depends only on (seed, i) and the result
// is the same for any thread count and standard library.
uint64_t mix(uint64_t x) {
    x += 0x9e3779b97f4a7c15ULL;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    return x ^ (x >> 31);
}
double u01(uint64_t bits) { return double(bits >> 11) * (1.0 / 9007199254740992.0); }

struct Tri {
    uint32_t surface;
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
    for (size_t i = 0; i < ps.size(); ++i) {
        const uint32_t s = surface_of[i];
        if (ps.emission[i] == Vec3{}) continue;
        ps.emission[i] = ps.emission[i] * float(area[s] / (double(count[s]) * disc));
    }
}

}  // namespace

PointSet sample_scene(const Scene& scene, std::vector<uint32_t>* surface_of) {
    std::vector<Tri> tris;
    std::vector<double> cdf;
    std::vector<double> surface_area(scene.surfaces.size(), 0.0);
    double area = 0;
    for (uint32_t s = 0; s < scene.surfaces.size(); ++s) {
        const Mesh& m = scene.surfaces[s].mesh;
        for (const auto& t : m.triangles) {
            const Vec3 a = m.vertices[t[0]], b = m.vertices[t[1]], c = m.vertices[t[2]];
            const Vec3 x = cross(b - a, c - a);
            const double ar =
                0.5 * std::sqrt(double(x.x) * x.x + double(x.y) * x.y + double(x.z) * x.z);
            if (!(ar > 0) || !std::isfinite(ar)) continue;  // degenerate triangle: no area
            tris.push_back({s, a, b, c, x / float(2 * ar)});
            area += ar;
            surface_area[s] += ar;
            cdf.push_back(area);
        }
    }
    if (tris.empty()) throw Error(fmt::format("{}: the scene has no surface area", scene.path));
    const uint64_t n = scene.points;
    if (n == 0) throw Error(fmt::format("{}: sampling.points must be at least 1", scene.path));
    PointSet ps;
    ps.positions.resize(n);
    ps.normals.resize(n);
    ps.colors.resize(n);
    ps.emission.resize(n);
    std::vector<uint32_t> surf(n);
    // Each sample stands for an equal share of the area: a disc of that area.
    ps.radii.assign(n, float(std::sqrt(area / (M_PI * double(n)))));
    const uint64_t seed = mix(scene.seed ^ 0x766d6170ULL);
    tbb::parallel_for(uint64_t(0), n, [&](uint64_t i) {
        const uint64_t r0 = mix(seed + 3 * i), r1 = mix(seed + 3 * i + 1),
                       r2 = mix(seed + 3 * i + 2);
        const double pick = u01(r0) * area;
        size_t k = std::upper_bound(cdf.begin(), cdf.end(), pick) - cdf.begin();
        k = std::min(k, tris.size() - 1);
        const Tri& t = tris[k];
        // Uniform point in a triangle: (1 - sqrt(u), sqrt(u)(1 - v), sqrt(u) v).
        const double su = std::sqrt(u01(r1)), v = u01(r2);
        const double w0 = 1 - su, w1 = su * (1 - v), w2 = su * v;
        ps.positions[i] = {float(w0 * t.a.x + w1 * t.b.x + w2 * t.c.x),
                           float(w0 * t.a.y + w1 * t.b.y + w2 * t.c.y),
                           float(w0 * t.a.z + w1 * t.b.z + w2 * t.c.z)};
        ps.normals[i] = t.n;
        ps.colors[i] = scene.surfaces[t.surface].albedo;
        ps.emission[i] = scene.surfaces[t.surface].emission;
        surf[i] = t.surface;
    });
    match_emitted_power(surface_area, surf, ps);
    if (surface_of) *surface_of = std::move(surf);
    return ps;
}

namespace {
struct CloudAdaptor {
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
}  // namespace

PointSet load_point_cloud(const std::string& path) {
    ModelData md = read_model(path);
    PointSet ps = std::move(md.points);
    if (ps.size() == 0) throw Error(fmt::format("{}: the point cloud is empty", path));
    if (!ps.has_normals()) estimate_normals(ps, {}, path.c_str());
    if (!ps.has_colors()) ps.colors.assign(ps.size(), Vec3{0.8f, 0.8f, 0.8f});
    if (!ps.has_radii()) {
        // Splat radius from the local spacing: the disc that holds k neighbours' share of area,
        // r = d_k / sqrt(k) for d_k the distance to the k-th nearest neighbour.
        using Tree =
            nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, CloudAdaptor>,
                                                CloudAdaptor, 3, uint32_t>;
        CloudAdaptor ad{ps.positions};
        Tree tree(3, ad, nanoflann::KDTreeSingleIndexAdaptorParams(16));
        tree.buildIndex();
        const size_t k = std::min<size_t>(8, ps.size());
        ps.radii.resize(ps.size());
        tbb::parallel_for(size_t(0), ps.size(), [&](size_t i) {
            std::vector<uint32_t> idx(k + 1);
            std::vector<float> d2(k + 1);
            const float q[3] = {ps.positions[i].x, ps.positions[i].y, ps.positions[i].z};
            const size_t got = tree.knnSearch(q, k + 1, idx.data(), d2.data());
            const float dk = got > 1 ? std::sqrt(d2[got - 1]) : 0.f;
            ps.radii[i] = got > 1 ? dk / std::sqrt(float(got - 1)) : 0.f;
        });
    }
    return ps;
}

}  // namespace vmap
