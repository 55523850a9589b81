// Splat radii from the density of neighbours on the point's own sheet (not the other face of a
// thin part), smoothed over that sheet; and the normal consistency check.

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <vector>

#include "scene/cloud_knn.h"
#include "vmap/error.h"
#include "vmap/normals.h"
#include "vmap/octree.h"
#include "vmap/parallel.h"

namespace vmap {
namespace {

// The radius from the sorted squared distances of m same-sheet neighbours. For samples of
// density rho on a surface, the j-th neighbour's squared distance has mean j / (pi rho), so each
// d_j^2 / j estimates 1 / (pi rho) = r^2 for the disc of area 1 / rho; their mean is less noisy
// than the k-th alone.
float radius_from(const std::vector<float>& d2, size_t m) {
    double sum = 0;
    for (size_t j = 0; j < m; ++j) sum += double(d2[j]) / double(j + 1);
    return float(std::sqrt(sum / double(m)));
}

// Whether a point's nearest same-sheet neighbour (kept: the sorted squared distances of its
// same-sheet neighbours, duplicates left out) lies within half the radius read from them:
// the close_neighbour_share test (vmap/normals.h).
bool has_close_neighbour(const float* kept, size_t m) {
    double sum = 0;
    for (size_t j = 0; j < m; ++j) sum += double(kept[j]) / double(j + 1);
    const float r = float(std::sqrt(sum / double(m)));  // radius_from's
    return kept[0] < 0.25f * r * r;
}

// How far a close-neighbour share is from even (0) toward independent samples (1); a share that
// is no number counts as independent (no correction).
double clumped_share(double close_share) {
    return std::isfinite(close_share) ? std::clamp(close_share / kPoissonCloseShare, 0.0, 1.0)
                                      : 1.0;
}

// Two counts summed over the points s * stride, s < steps, each from the point's `want` nearest
// (sorted squared distances): count(i, idx, d2, got, tally) adds to the tally.
struct Tally {
    uint64_t total = 0, hits = 0;
};
template <class Count>
Tally tally_neighbours(const std::vector<Vec3>& pts, size_t want, size_t steps, size_t stride,
                       Count count) {
    const detail::CloudAdaptor adaptor{pts};
    const detail::KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16));
    return parallel_reduce_range<size_t>(
        steps, 1024, Tally{},
        [&](size_t chunk_begin, size_t chunk_end, Tally acc) {
            std::vector<uint32_t> idx(want);
            std::vector<float> d2(want);
            for (size_t s = chunk_begin; s < chunk_end; ++s) {
                const size_t i = s * stride;
                const float q[3] = {pts[i].x, pts[i].y, pts[i].z};
                const size_t got = tree.knnSearch(q, want, idx.data(), d2.data());
                count(i, idx.data(), d2.data(), got, acc);
            }
            return acc;
        },
        [](Tally a, Tally b) {
            return Tally{a.total + b.total, a.hits + b.hits};
        });
}

// Whether q lies on another sheet than p for the density: a surface parallel to p's (normal
// axes within 37 degrees) and off p's tangent plane (more than 14 degrees): the other face of a
// thin plate or a thin part, a surface a few millimetres away. A neighbour whose normal turns
// (around a thin tube, across a crease) lies on p's own surface and counts, which
// detail::same_surface (for orientation: one smooth surface) would leave out.
// On a noisy cloud `slack` (its roughness, roughness_of) is allowed off the plane besides.
bool other_sheet(Vec3 p, Vec3 np, Vec3 q, Vec3 nq, float slack) {
    const Vec3 d = q - p;
    const float off = std::max(0.0f, std::fabs(dot(np, d)) - slack);
    return std::fabs(dot(np, nq)) >= 0.8f && off * off > 0.0625f * length2(d);
}

// The radius of every point from its k nearest same-sheet neighbours (radius_from), and those
// neighbours (up to k a point, kNone-padded) for the smoothing passes.
constexpr uint32_t kNone = 0xffffffffu;
// The same-sheet neighbours close_neighbour_share reads the radius from.
constexpr size_t kCloseNeighbours = 8;

std::vector<uint32_t> raw_radii(PointSet& points, const RadiusEstimationParams& params,
                                double* close_share, float slack) {
    const std::vector<Vec3>& pts = points.positions;
    const size_t n = pts.size(), k = params.k;
    const detail::CloudAdaptor adaptor{pts};
    const detail::KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16));
    const size_t want = std::min(params.candidates + 1, n);
    points.radii.resize(n);
    std::vector<uint32_t> same(n * k, kNone);
    std::vector<uint8_t> probed(n, 0), close(n, 0);
    parallel_for_range<size_t>(n, 256, [&](size_t chunk_begin, size_t chunk_end) {
        std::vector<uint32_t> idx(want);
        std::vector<float> d2(want), kept, all, distinct;
        for (size_t i = chunk_begin; i < chunk_end; ++i) {
            const Vec3 p = pts[i], np = points.normals[i];
            const float q[3] = {p.x, p.y, p.z};
            const size_t got = tree.knnSearch(q, want, idx.data(), d2.data());
            kept.clear();
            all.clear();
            for (size_t j = 0; j < got; ++j) {
                if (idx[j] == i) continue;
                all.push_back(d2[j]);
                const Vec3 o = pts[idx[j]];
                if (other_sheet(p, np, o, points.normals[idx[j]], slack)) continue;
                same[i * k + kept.size()] = idx[j];
                kept.push_back(d2[j]);
                if (kept.size() == k) break;
            }
            // Too few on the same side (an isolated speck, a sliver): count every neighbour.
            const std::vector<float>& use = kept.size() >= std::min<size_t>(3, k) ? kept : all;
            const size_t m = std::min(use.size(), k);
            points.radii[i] = m > 0 ? radius_from(use, m) : 0.0f;
            distinct.clear();
            for (float v : kept)
                if (v > 0.f) distinct.push_back(v);
            if (distinct.size() >= kCloseNeighbours) {
                probed[i] = 1;
                close[i] = has_close_neighbour(distinct.data(), kCloseNeighbours);
            }
        }
    });
    if (close_share) {
        const size_t p = size_t(std::count(probed.begin(), probed.end(), uint8_t(1)));
        *close_share = p ? double(std::count(close.begin(), close.end(), uint8_t(1))) / double(p)
                         : kPoissonCloseShare;
    }
    return same;
}

// The sampling density varies slowly over a surface, but one point's estimate from k
// neighbours scatters by about 1 / sqrt(k) (p10-p90 0.71-1.28 of the true radius at k 8 on
// uniform samples), and a leaf's occluder disc grows with its radius, so the scatter's large
// radii hide segments that graze a surface. Each raw r^2 estimates the area per sample, so the
// passes diffuse r^2 over the symmetrised same-sheet neighbour graph with Metropolis weights
// 1 / (1 + max(deg i, deg j)): a doubly stochastic step, so the sum of r^2 (the surface area)
// is kept exactly while the scatter shrinks (averaging over the k-NN lists directly drifts low,
// as dense spots are everyone's neighbours). Never across surfaces: a thin plate's other face
// is not in the graph.
void smooth_radii(std::vector<float>& radii, const std::vector<uint32_t>& same, size_t k,
                  int passes) {
    const size_t n = radii.size();
    std::vector<size_t> start(n + 1, 0);
    for (size_t i = 0; i < n; ++i)
        for (size_t j = 0; j < k && same[i * k + j] != kNone; ++j)
            ++start[i + 1], ++start[same[i * k + j] + 1];
    std::partial_sum(start.begin(), start.end(), start.begin());
    std::vector<uint32_t> adj(start[n]);
    std::vector<size_t> fill(start.begin(), start.end() - 1);
    for (size_t i = 0; i < n; ++i)
        for (size_t j = 0; j < k && same[i * k + j] != kNone; ++j) {
            const uint32_t o = same[i * k + j];
            adj[fill[i]++] = o, adj[fill[o]++] = uint32_t(i);
        }
    // An edge listed by both ends appears twice: drop the repeats, so the weights are symmetric.
    std::vector<uint32_t> deg(n);
    for (size_t i = 0; i < n; ++i) {
        auto b = adj.begin() + std::ptrdiff_t(start[i]),
             e = adj.begin() + std::ptrdiff_t(start[i + 1]);
        std::sort(b, e);
        deg[i] = uint32_t(std::unique(b, e) - b);
    }
    std::vector<double> x(n), y(n);
    for (size_t i = 0; i < n; ++i) x[i] = double(radii[i]) * radii[i];
    for (int pass = 0; pass < passes; ++pass) {
        parallel_for_range<size_t>(n, 1024, [&](size_t chunk_begin, size_t chunk_end) {
            for (size_t i = chunk_begin; i < chunk_end; ++i) {
                double v = x[i];
                for (size_t e = start[i]; e < start[i] + deg[i]; ++e) {
                    const uint32_t o = adj[e];
                    v += (x[o] - x[i]) / double(1 + std::max(deg[i], deg[o]));
                }
                y[i] = v;
            }
        });
        std::swap(x, y);
    }
    for (size_t i = 0; i < n; ++i) radii[i] = float(std::sqrt(std::max(x[i], 0.0)));
}

}  // namespace

void estimate_radii(PointSet& points, const RadiusEstimationParams& params, const char* source) {
    const size_t n = points.positions.size();
    const std::string src = source ? source : "point cloud";
    if (n < 2) throw Error(fmt::format("{}: splat radii need at least 2 points, got {}", src, n));
    if (points.normals.size() != n)
        throw Error(fmt::format("{}: splat radii need normals ({} for {} points)", src,
                                points.normals.size(), n));
    if (params.k < 1 || params.candidates < params.k)
        throw Error(fmt::format("{}: radius estimation: need 1 <= k ({}) <= candidates ({})", src,
                                params.k, params.candidates));
    if (params.smoothing_passes < 0 || params.smoothing_passes > 1000)
        throw Error(fmt::format("{}: radius estimation: smoothing_passes {} out of range (0..1000)",
                                src, params.smoothing_passes));
    double share = kPoissonCloseShare;
    const bool correct =
        params.sampling_correction && params.k == kCloseNeighbours && params.candidates >= 32;
    // A noisy cloud's neighbours scatter off the plane: its roughness is still its own sheet.
    const float slack = roughness_of(estimate_surface_noise(points));
    const std::vector<uint32_t> same = raw_radii(points, params, correct ? &share : nullptr, slack);
    smooth_radii(points.radii, same, params.k, params.smoothing_passes);
    if (!correct) return;
    const float scale = even_sampling_radius_scale(share);
    for (float& r : points.radii) r *= scale;
}

float even_sampling_radius_scale(double close_share) {
    return float(kEvenRadiusScale + clumped_share(close_share) * (1.0 - kEvenRadiusScale));
}

double close_neighbour_share(const PointSet& points) {
    const std::vector<Vec3>& pts = points.positions;
    const size_t n = pts.size();
    if (n < 10 || points.normals.size() != n) return kPoissonCloseShare;
    constexpr size_t kCandidates = 32, kMostProbes = 100000;
    // A fixed stride over the points: the same probes whatever the thread count.
    const size_t stride = (n + kMostProbes - 1) / kMostProbes;
    const float slack = roughness_of(estimate_surface_noise(points));
    const Tally c = tally_neighbours(
        pts, std::min(kCandidates + 1, n), (n + stride - 1) / stride, stride,
        [&](size_t i, const uint32_t* idx, const float* d2, size_t got, Tally& acc) {
            std::array<float, kCloseNeighbours> kept;
            size_t m = 0;
            for (size_t j = 0; j < got && m < kCloseNeighbours; ++j) {
                if (idx[j] == i || d2[j] == 0.f) continue;  // itself, or a duplicate
                if (other_sheet(pts[i], points.normals[i], pts[idx[j]], points.normals[idx[j]],
                                slack))
                    continue;
                kept[m++] = d2[j];
            }
            if (m < kCloseNeighbours) return;  // a speck or a sliver: no density to read
            ++acc.total;
            acc.hits += has_close_neighbour(kept.data(), kCloseNeighbours);
        });
    return c.total ? double(c.hits) / double(c.total) : kPoissonCloseShare;
}

float delta_floor_of_share(double close_share) {
    return float(OctreeParams::kEvenDeltaFloor +
                 clumped_share(close_share) *
                     (OctreeParams::kDefaultDeltaFloor - OctreeParams::kEvenDeltaFloor));
}

float cloud_delta_floor(const PointSet& points) {
    return delta_floor_of_share(close_neighbour_share(points));
}

double normal_inconsistency(const PointSet& points, size_t k, size_t max_probes) {
    const std::vector<Vec3>& pts = points.positions;
    const size_t n = pts.size();
    if (n < 2 || points.normals.size() != n) return 0.0;
    const float slack = roughness_of(estimate_surface_noise(points));
    // A fixed stride over the points, as close_neighbour_share's: the same share whatever the
    // thread count, and a million-point cloud probed in a tenth of the time.
    const size_t stride = max_probes ? (n + max_probes - 1) / max_probes : 1;
    const Tally c =
        tally_neighbours(pts, std::min(k + 1, n), (n + stride - 1) / stride, stride,
                         [&](size_t i, const uint32_t* idx, const float*, size_t got, Tally& acc) {
                             for (size_t j = 0; j < got; ++j) {
                                 const uint32_t o = idx[j];
                                 if (o == i ||
                                     !detail::same_surface(pts[i], points.normals[i], pts[o],
                                                           points.normals[o], slack))
                                     continue;
                                 ++acc.total;
                                 acc.hits += dot(points.normals[i], points.normals[o]) < 0;
                             }
                         });
    return c.total ? double(c.hits) / double(c.total) : 0.0;
}

}  // namespace vmap
