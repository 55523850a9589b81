// Area-weighted, seeded sampling of scene surfaces into points; raw point cloud loading.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "vmap/error.h"
#include "vmap/io.h"
#include "vmap/normals.h"
#include "vmap/parallel.h"
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

    explicit SurfaceDraw(const Scene& sc) : scene(sc), surface_area(sc.surfaces.size(), 0.0) {
        for (uint32_t s = 0; s < sc.surfaces.size(); ++s) {
            const Mesh& m = sc.surfaces[s].mesh;
            for (uint32_t k = 0; k < m.triangles.size(); ++k) {
                const auto& t = m.triangles[k];
                const Vec3 a = m.vertices[t[0]], b = m.vertices[t[1]], c = m.vertices[t[2]];
                const Vec3 x = cross(b - a, c - a);
                const double ar =
                    0.5 * std::sqrt(double(x.x) * x.x + double(x.y) * x.y + double(x.z) * x.z);
                if (!(ar > 0) || !std::isfinite(ar)) continue;  // degenerate triangle: no area
                tris.push_back({s, k, a, b, c, x / float(2 * ar)});
                area += ar;
                surface_area[s] += ar;
                cdf.push_back(area);
            }
        }
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
// its neighbours is removed, one at a time, until `keep` remain. (Removing every candidate more
// crowded than all its neighbours at once, in parallel rounds, was tried: 10% of the samples
// then keep a neighbour closer than 0.6 splat radii, against under 1% one at a time.) Crowding is the sum over the
// neighbours within 2 r_max of (1 - d / 2 r_max)^8, where r_max = sqrt(area / (2 sqrt(3) keep))
// is the disc radius of the densest packing of `keep` discs on the area, and d is clamped below
// at 2 r_min (Yuksel's weight limit, r_min = 0.65 r_max (1 - (keep / candidates)^1.5)) so that
// a tight cluster does not outweigh everything else. Only neighbours on the same side of a
// surface count (normals less than 90 degrees apart): the two faces of a thin plate, or an
// object and the wall it touches, are thinned each on its own. Returns the kept candidates'
// indices, ascending. Deterministic: the neighbour lists do not depend on the thread count, and
// the elimination runs in one thread (ties to the larger index).
std::vector<uint64_t> eliminate(const std::vector<Vec3>& pos, const std::vector<Vec3>& nrm,
                                uint64_t keep, double area) {
    const uint64_t M = pos.size();
    if (keep >= M) {
        std::vector<uint64_t> all(M);
        for (uint64_t i = 0; i < M; ++i) all[i] = i;
        return all;
    }
    const double rmax = std::sqrt(area / (2 * std::sqrt(3.0) * double(keep)));
    const double rmin = 0.65 * rmax * (1 - std::pow(double(keep) / double(M), 1.5));
    const double reach = 2 * rmax, reach2 = reach * reach, floor_d = 2 * rmin;
    constexpr int kNb = 32;  // about 14.5 same-side candidates lie within reach at 4x
    // Neighbours from a grid of cells `reach` wide: a candidate's lie in the 27 cells around it.
    // Cells are keyed by their integer coordinates; the candidates sorted by key (then index).
    Vec3 lo = pos[0], hi = pos[0];
    for (const Vec3& p : pos) {
        lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
        hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
    }
    // At least `reach` wide, and at most 2^20 cells an axis (21-bit coordinates in the key).
    const double extent = std::max({double(hi.x - lo.x), double(hi.y - lo.y), double(hi.z - lo.z)});
    const double cell = std::max(reach, extent / double(1 << 20));
    auto cell_of = [&](Vec3 p, int axis) {
        const float v = axis == 0 ? p.x - lo.x : axis == 1 ? p.y - lo.y : p.z - lo.z;
        return int64_t(std::floor(double(v) / cell));
    };
    auto key_of = [](int64_t x, int64_t y, int64_t z) {
        return (uint64_t(x) << 42) | (uint64_t(y) << 21) | uint64_t(z);
    };
    std::vector<std::pair<uint64_t, uint32_t>> by_cell(M);
    parallel_for(M, [&](uint64_t i) {
        by_cell[i] = {key_of(cell_of(pos[i], 0), cell_of(pos[i], 1), cell_of(pos[i], 2)),
                      uint32_t(i)};
    });
    parallel_sort(by_cell.begin(), by_cell.end(), std::less<>());
    std::vector<uint64_t> cell_start;
    // The cells in an open-addressing table (key -> cell), and the candidates' positions and
    // normals in cell order, so that a cell's are read in one run.
    std::vector<Vec3> cpos(M), cnrm(M);
    parallel_for(M, [&](uint64_t k) {
        cpos[k] = pos[by_cell[k].second];
        cnrm[k] = nrm[by_cell[k].second];
    });
    for (uint64_t k = 0; k < M; ++k)
        if (k == 0 || by_cell[k].first != by_cell[k - 1].first) cell_start.push_back(k);
    const size_t cells = cell_start.size();
    cell_start.push_back(M);
    size_t cap = 16;
    while (cap < 2 * cells) cap <<= 1;
    constexpr uint64_t kEmpty = ~0ull;  // no key reaches it (63 bits at most)
    std::vector<uint64_t> table_key(cap, kEmpty);
    std::vector<uint32_t> table_cell(cap);
    for (size_t c = 0; c < cells; ++c) {
        const uint64_t key = by_cell[cell_start[c]].first;
        size_t at = mix(key) & (cap - 1);
        while (table_key[at] != kEmpty) at = (at + 1) & (cap - 1);
        table_key[at] = key;
        table_cell[at] = uint32_t(c);
    }
    auto find_cell = [&](uint64_t key) -> int64_t {
        for (size_t at = mix(key) & (cap - 1); table_key[at] != kEmpty; at = (at + 1) & (cap - 1))
            if (table_key[at] == key) return table_cell[at];
        return -1;
    };
    std::vector<uint32_t> nb(M * kNb);
    std::vector<float> nw(M * kNb);
    std::vector<uint8_t> count(M, 0);
    std::vector<double> W(M, 0.0);
    // A cell at a time: its 27 neighbouring cells are looked up once for all its candidates.
    parallel_for_range<size_t>(cells, 256, [&](size_t cb, size_t ce) {
        std::vector<std::pair<double, uint32_t>> found;
        std::vector<std::pair<uint64_t, uint64_t>> ranges;
        for (size_t cell_index = cb; cell_index < ce; ++cell_index) {
            const uint64_t first = cell_start[cell_index];
            const Vec3 p0 = cpos[first];
            const int64_t cx = cell_of(p0, 0), cy = cell_of(p0, 1), cz = cell_of(p0, 2);
            ranges.clear();
            for (int64_t dx = -1; dx <= 1; ++dx)
                for (int64_t dy = -1; dy <= 1; ++dy)
                    for (int64_t dz = -1; dz <= 1; ++dz) {
                        if (cx + dx < 0 || cy + dy < 0 || cz + dz < 0) continue;
                        const int64_t c = find_cell(key_of(cx + dx, cy + dy, cz + dz));
                        if (c >= 0) ranges.push_back({cell_start[c], cell_start[c + 1]});
                    }
            for (uint64_t q = first; q < cell_start[cell_index + 1]; ++q) {
                const uint32_t i = by_cell[q].second;
                const Vec3 pi = cpos[q], ni = cnrm[q];
                found.clear();
                for (const auto& [kb, ke] : ranges)
                    for (uint64_t k = kb; k < ke; ++k) {
                        if (k == q || !(dot(ni, cnrm[k]) > 0)) continue;
                        const Vec3 d = cpos[k] - pi;
                        const double d2 =
                            double(d.x) * d.x + double(d.y) * d.y + double(d.z) * d.z;
                        if (d2 < reach2) found.push_back({std::sqrt(d2), by_cell[k].second});
                    }
                // The nearest kNb (ties by index), in that order.
                std::sort(found.begin(), found.end());
                const int n = int(std::min<size_t>(found.size(), kNb));
                double sum = 0;
                for (int c = 0; c < n; ++c) {
                    const double t = 1 - std::max(found[c].first, floor_d) / reach;
                    const double t2 = t * t, t4 = t2 * t2;
                    const float w = float(t4 * t4);
                    nb[uint64_t(i) * kNb + c] = found[c].second;
                    nw[uint64_t(i) * kNb + c] = w;
                    sum += w;
                }
                count[i] = uint8_t(n);
                W[i] = sum;
            }
        }
    });
    // Removing i lowers each neighbour j's crowding by the weight j's own list holds for i (a
    // list cut at kNb may lack it).
    auto weight_in = [&](uint64_t j, uint64_t i) -> double {
        for (int c = 0; c < count[j]; ++c)
            if (nb[j * kNb + c] == i) return nw[j * kNb + c];
        return 0.0;
    };
    // An indexed binary max-heap on (W, index): removing a candidate lowers its neighbours'
    // crowding, and each moves down in place (no stale entries).
    std::vector<uint32_t> heap(M), where(M);
    for (uint64_t i = 0; i < M; ++i) heap[i] = uint32_t(i);
    auto above = [&](uint32_t a, uint32_t b) { return W[a] > W[b] || (W[a] == W[b] && a > b); };
    auto place = [&](uint64_t at, uint32_t item) {
        heap[at] = item;
        where[item] = uint32_t(at);
    };
    uint64_t size = M;
    auto sift_down = [&](uint64_t at) {
        const uint32_t item = heap[at];
        for (;;) {
            uint64_t c = 2 * at + 1;
            if (c >= size) break;
            if (c + 1 < size && above(heap[c + 1], heap[c])) ++c;
            if (!above(heap[c], item)) break;
            place(at, heap[c]);
            at = c;
        }
        place(at, item);
    };
    for (uint64_t i = 0; i < M; ++i) where[i] = uint32_t(i);
    for (uint64_t at = M / 2; at-- > 0;) sift_down(at);
    std::vector<uint8_t> gone(M, 0);
    while (size > keep) {
        const uint32_t i = heap[0];
        gone[i] = 1;
        place(0, heap[--size]);
        if (size > 0) sift_down(0);
        for (int c = 0; c < count[i]; ++c) {
            const uint64_t j = nb[uint64_t(i) * kNb + c];
            if (gone[j]) continue;
            const double wj = weight_in(j, i);
            if (wj == 0) continue;
            W[j] -= wj;
            sift_down(where[j]);
        }
    }
    std::vector<uint64_t> kept;
    kept.reserve(keep);
    for (uint64_t i = 0; i < M; ++i)
        if (!gone[i]) kept.push_back(i);
    return kept;
}

// Candidates per kept sample for blue noise (Yuksel: 3-5x; more gives little).
constexpr uint64_t kBlueNoiseCandidates = 4;

}  // namespace

PointSet sample_scene(const Scene& scene, std::vector<uint32_t>* surface_of) {
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
        const std::vector<uint64_t> kept = eliminate(cand.positions, cand.normals, n, draw.area);
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
    if (o.normals == NormalsMode::kFlip) {
        if (!had)
            throw Error(fmt::format("{}: --normals flip: the file has no normals to flip", path));
        for (Vec3& n : ps.normals) n = -n;
        if (o.viewpoint) orient_toward(ps, *o.viewpoint);
        return o.viewpoint ? "normals: the file's, flipped, then toward the viewpoint"
                           : "normals: the file's, flipped";
    }
    NormalEstimationParams np;
    if (o.normals == NormalsMode::kInward) np.orientation = Orientation::kInward;
    if (o.normals == NormalsMode::kOutward) np.orientation = Orientation::kOutward;
    if (o.viewpoint) {
        np.orientation = Orientation::kViewpoint;
        np.viewpoint = *o.viewpoint;
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
    if (sensed) {
        orient_toward(ps, sensors, path.c_str());
        rep.method = "toward the file's per-point sensor positions";
    }
    std::string line =
        fmt::format("normals: {} ({}), oriented {}",
                    estimate ? "estimated from 12 nearest neighbours" : "the file's axes",
                    estimate && had ? "the file's replaced" : "plane fits", rep.method);
    if (!sensed && rep.by_space + rep.by_rays > 0)
        line += fmt::format(
            "; {} points by free space, {} by rays ({} of those then turned by their "
            "neighbours' votes), {} from their neighbours",
            rep.by_space, rep.by_rays, rep.by_neighbours, ps.size() - rep.by_space - rep.by_rays);
    return line;
}

}  // namespace

PointSet load_point_cloud(const std::string& path, const CloudOptions& options,
                          std::vector<std::string>* done) {
    ModelData md = read_model(path);
    for (const std::string& note : md.notes) fmt::print(stderr, "note:       {}\n", note);
    PointSet ps = std::move(md.points);
    if (ps.size() == 0) throw Error(fmt::format("{}: the point cloud is empty", path));
    std::vector<std::string> lines;
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
