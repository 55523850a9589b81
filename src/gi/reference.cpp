// Path-traced reference radiosity (the contract is in include/vmap/gi_reference.h).
#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>
#include <numbers>

#include "util/progress.h"
#include "util/splitmix.h"
#include "vmap/error.h"
#include "vmap/gi_reference.h"
#include "vmap/parallel.h"
#include "vmap/validate.h"

namespace vmap {
namespace {

constexpr double kPi = std::numbers::pi;
// A path ends when no channel of its throughput (the product of the albedos met) is above this:
// what it could still add is below 1e-6 of the light it carries.
constexpr float kMinThroughput = 1e-6f;
constexpr int kMaxDepth = 1000;

// SplitMix64 as a stream: the state advances by the golden ratio, each output is mixed.
struct Rng {
    uint64_t state;
    static uint64_t mix(uint64_t x) { return detail::splitmix64_finalize(x); }
    float next() {
        state += detail::kSplitMixGamma;
        return float(mix(state) >> 40) * (1.0f / 16777216.0f);  // [0, 1), 24 bits
    }
};

struct Emitter {
    Vec3 a, b, c, n, emission;
    double area;
};

// The emitting triangles with their cumulative areas (to pick one by area).
struct Emitters {
    std::vector<Emitter> tris;
    std::vector<double> cdf;
    double area = 0;

    Emitters(const std::vector<SceneSurface>& surfaces, const std::string& source) {
        for (const SceneSurface& s : surfaces) {
            if (!(s.emission.x > 0 || s.emission.y > 0 || s.emission.z > 0)) continue;
            for (const auto& t : s.mesh.triangles) {
                const Vec3 a = s.mesh.vertices[t[0]], b = s.mesh.vertices[t[1]],
                           c = s.mesh.vertices[t[2]];
                const Vec3 x = cross(b - a, c - a);
                const double ar = 0.5 * double(length(x));
                if (!(ar > 0)) continue;
                tris.push_back({a, b, c, x / length(x), s.emission, ar});
                area += ar;
                cdf.push_back(area);
            }
        }
        if (tris.empty()) throw Error(fmt::format("{}: the scene has no emitting surface", source));
    }

    const Emitter& pick(float u, Vec3& p, Rng& rng) const {
        const double target = double(u) * area;
        size_t k = std::upper_bound(cdf.begin(), cdf.end(), target) - cdf.begin();
        const Emitter& e = tris[std::min(k, tris.size() - 1)];
        const float su = std::sqrt(rng.next()), v = rng.next();
        p = e.a * (1 - su) + e.b * (su * (1 - v)) + e.c * (su * v);
        return e;
    }
};

// A cosine-distributed direction about unit normal n (Duff et al.'s branchless basis).
Vec3 cosine_direction(Vec3 n, float u1, float u2) {
    const float sign = std::copysign(1.0f, n.z);
    const float a = -1.0f / (sign + n.z), b = n.x * n.y * a;
    const Vec3 t{1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x};
    const Vec3 s{b, sign + n.y * n.y * a, -n.y};
    const float r = std::sqrt(u1), phi = float(2 * kPi) * u2;
    const float z = std::sqrt(std::max(0.0f, 1.0f - u1));
    return t * (r * std::cos(phi)) + s * (r * std::sin(phi)) + n * z;
}

Vec3 mul(Vec3 a, Vec3 b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }

struct Tracer {
    const std::vector<SceneSurface>& surfaces;
    const ExactVisibility& scene;
    const Emitters& emitters;
    float eps;  // ray offset, scene units

    // Irradiance at x (normal n) from one emitter sample, with its shadow ray.
    Vec3 direct(Vec3 x, Vec3 n, Rng& rng, uint64_t& rays) const {
        Vec3 y;
        const Emitter& e = emitters.pick(rng.next(), y, rng);
        const Vec3 w = y - x;
        const float d2 = dot(w, w);
        if (!(d2 > eps * eps)) return {};
        const float d = std::sqrt(d2);
        const float cx = dot(n, w) / d, cy = -dot(e.n, w) / d;
        if (!(cx > 0) || !(cy > 0)) return {};
        ++rays;
        if (scene.occluded(x, y, eps / d, 1.0f - eps / d)) return {};
        return e.emission * float(emitters.area * double(cx) * cy / (kPi * d2));
    }

    // One path from x: adds the light found at vertex d (d + 1 bounces) to found[d].
    void path(Vec3 x, Vec3 n, Vec3 albedo, Rng& rng, Vec3* found, int depths,
              uint64_t& rays) const {
        Vec3 T = albedo;
        for (int d = 0; d < kMaxDepth; ++d) {
            const Vec3 h = mul(T, direct(x, n, rng, rays));
            found[std::min(d, depths - 1)] += h;
            const float u1 = rng.next(), u2 = rng.next();
            const Vec3 dir = cosine_direction(n, u1, u2);
            ++rays;
            const ExactVisibility::Hit hit = scene.intersect(x + n * eps, dir, 0.0f, 1e30f);
            if (hit.surface < 0 || dot(hit.normal, dir) >= 0) return;  // left, or a back face
            T = mul(T, surfaces[hit.surface].albedo);
            if (std::max({T.x, T.y, T.z}) < kMinThroughput) return;
            x = x + n * eps + dir * hit.t;
            n = hit.normal;
        }
    }
};

float scene_extent(const std::vector<SceneSurface>& surfaces) {
    Vec3 lo{1e30f, 1e30f, 1e30f}, hi{-1e30f, -1e30f, -1e30f};
    for (const SceneSurface& s : surfaces)
        for (const Vec3& v : s.mesh.vertices) {
            lo = {std::min(lo.x, v.x), std::min(lo.y, v.y), std::min(lo.z, v.z)};
            hi = {std::max(hi.x, v.x), std::max(hi.y, v.y), std::max(hi.z, v.z)};
        }
    return hi.x >= lo.x ? length(hi - lo) : 1.0f;
}

}  // namespace

ReferenceResult path_trace_radiosity(const std::vector<SceneSurface>& surfaces,
                                     const std::vector<ReferencePoint>& at,
                                     const ReferenceParams& params, const std::string& source) {
    if (params.samples < 2)
        throw Error(fmt::format("{}: reference: samples: {} (need >= 2)", source, params.samples));
    if (params.bounces < 1)
        throw Error(fmt::format("{}: reference: bounces: {} (need >= 1)", source, params.bounces));
    const auto t0 = std::chrono::steady_clock::now();
    const ExactVisibility scene(surfaces, source);
    const Emitters emitters(surfaces, source);
    const Tracer tr{surfaces, scene, emitters, 1e-5f * scene_extent(surfaces)};
    const int K = params.bounces, bins = K + 1;  // found[d] for d < K, then everything later
    ReferenceResult r;
    r.value.assign(bins, std::vector<Vec3>(at.size()));
    r.std_error = r.value;
    std::atomic<uint64_t> rays{0}, done{0};
    detail::Progress bar("reference", at.size(), &params.progress);
    std::mutex bar_mutex;
    const uint64_t seed = Rng::mix(params.seed ^ 0x7265665f67690000ULL);
    parallel_for(size_t(0), at.size(), [&](size_t i) {
        const ReferencePoint& p = at[i];
        std::vector<double> sum(3 * bins, 0.0), sum2(3 * bins, 0.0);
        std::vector<Vec3> found(bins);
        uint64_t my_rays = 0;
        for (uint32_t s = 0; s < params.samples; ++s) {
            Rng rng{Rng::mix(seed + Rng::mix((uint64_t(i) << 32) | s))};
            std::fill(found.begin(), found.end(), Vec3{});
            tr.path(p.position, p.normal, p.albedo, rng, found.data(), bins, my_rays);
            Vec3 acc = p.emission;  // cumulative: B after k + 1 bounces
            for (int k = 0; k < bins; ++k) {
                acc += found[k];
                const double v[3] = {acc.x, acc.y, acc.z};
                for (int c = 0; c < 3; ++c) sum[3 * k + c] += v[c], sum2[3 * k + c] += v[c] * v[c];
            }
        }
        const double n = params.samples;
        for (int k = 0; k < bins; ++k) {
            double m[3], se[3];
            for (int c = 0; c < 3; ++c) {
                m[c] = sum[3 * k + c] / n;
                const double var = std::max(0.0, (sum2[3 * k + c] / n - m[c] * m[c]) * n / (n - 1));
                se[c] = std::sqrt(var / n);
            }
            r.value[k][i] = Vec3{float(m[0]), float(m[1]), float(m[2])};
            r.std_error[k][i] = Vec3{float(se[0]), float(se[1]), float(se[2])};
        }
        rays += my_rays;
        const uint64_t finished = ++done;
        if (std::unique_lock lock(bar_mutex, std::try_to_lock); lock) bar.set(finished);
    });
    r.rays = rays.load();
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return r;
}

}  // namespace vmap
