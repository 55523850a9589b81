// Splat radii from the density of same-surface neighbours, and the normal consistency check.

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "scene/cloud_knn.h"
#include "vmap/error.h"
#include "vmap/normals.h"

namespace vmap {
namespace {

// The radius from the sorted squared distances of m same-surface neighbours. For samples of
// density rho on a surface, the j-th neighbour's squared distance has mean j / (pi rho), so each
// d_j^2 / j estimates 1 / (pi rho) = r^2 for the disc of area 1 / rho; their mean is less noisy
// than the k-th alone.
float radius_from(const std::vector<float>& d2, size_t m) {
    double sum = 0;
    for (size_t j = 0; j < m; ++j) sum += double(d2[j]) / double(j + 1);
    return float(std::sqrt(sum / double(m)));
}

}  // namespace

void estimate_radii(PointSet& points, const RadiusEstimationParams& params, const char* source) {
    const std::vector<Vec3>& pts = points.positions;
    const size_t n = pts.size();
    const std::string src = source ? source : "point cloud";
    if (n < 2) throw Error(fmt::format("{}: splat radii need at least 2 points, got {}", src, n));
    if (points.normals.size() != n)
        throw Error(fmt::format("{}: splat radii need normals ({} for {} points)", src,
                                points.normals.size(), n));
    if (params.k < 1 || params.candidates < params.k)
        throw Error(fmt::format("{}: radius estimation: need 1 <= k ({}) <= candidates ({})", src,
                                params.k, params.candidates));
    const detail::CloudAdaptor adaptor{pts};
    const detail::KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16));
    const size_t want = std::min(params.candidates + 1, n);
    points.radii.resize(n);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 256), [&](const auto& range) {
        std::vector<uint32_t> idx(want);
        std::vector<float> d2(want), kept, all;
        for (size_t i = range.begin(); i < range.end(); ++i) {
            const Vec3 p = pts[i], np = points.normals[i];
            const float q[3] = {p.x, p.y, p.z};
            const size_t got = tree.knnSearch(q, want, idx.data(), d2.data());
            kept.clear();
            all.clear();
            for (size_t j = 0; j < got; ++j) {
                if (idx[j] == i) continue;
                all.push_back(d2[j]);
                const Vec3 o = pts[idx[j]];
                if (detail::same_surface(p, np, o, points.normals[idx[j]])) kept.push_back(d2[j]);
                if (kept.size() == params.k) break;
            }
            // Too few on the same side (an isolated speck, a sliver): count every neighbour.
            const std::vector<float>& use =
                kept.size() >= std::min<size_t>(3, params.k) ? kept : all;
            const size_t m = std::min(use.size(), params.k);
            points.radii[i] = m > 0 ? radius_from(use, m) : 0.0f;
        }
    });
}

double normal_inconsistency(const PointSet& points, size_t k) {
    const std::vector<Vec3>& pts = points.positions;
    const size_t n = pts.size();
    if (n < 2 || points.normals.size() != n) return 0.0;
    const detail::CloudAdaptor adaptor{pts};
    const detail::KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16));
    const size_t want = std::min(k + 1, n);
    struct Count {
        uint64_t pairs = 0, opposed = 0;
    };
    const Count c = tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, n, 1024), Count{},
        [&](const auto& range, Count acc) {
            std::vector<uint32_t> idx(want);
            std::vector<float> d2(want);
            for (size_t i = range.begin(); i < range.end(); ++i) {
                const float q[3] = {pts[i].x, pts[i].y, pts[i].z};
                const size_t got = tree.knnSearch(q, want, idx.data(), d2.data());
                for (size_t j = 0; j < got; ++j) {
                    const uint32_t o = idx[j];
                    if (o == i ||
                        !detail::same_surface(pts[i], points.normals[i], pts[o], points.normals[o]))
                        continue;
                    ++acc.pairs;
                    acc.opposed += dot(points.normals[i], points.normals[o]) < 0;
                }
            }
            return acc;
        },
        [](Count a, Count b) {
            return Count{a.pairs + b.pairs, a.opposed + b.opposed};
        });
    return c.pairs ? double(c.opposed) / double(c.pairs) : 0.0;
}

}  // namespace vmap
