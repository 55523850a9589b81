// A simulated terrestrial scan of a scene (include/vmap/validate.h, scan_scene): what a scanner
// standing in the room records, for `vmap validate --scan`.
//
// A scanner sweeps its beam over an equal-angle grid (a step in elevation from nadir to zenith, the
// same step in azimuth) and keeps the first surface each beam hits. Unlike the scenes' even
// samples, its points crowd near the scanner and near the poles of its sweep, thin out with
// distance and obliquity (a wall seen at grazing angle gets rows of points far apart across the
// rows and close along them), leave shadows behind every object and see only the side of a surface
// that faces it. Several scanners overlap their patterns as registered scans do.
#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "vmap/error.h"
#include "vmap/validate.h"

namespace vmap {
namespace {

struct Box {
    Vec3 lo{1e30f, 1e30f, 1e30f}, hi{-1e30f, -1e30f, -1e30f};
    void add(Vec3 p) {
        lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
        hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
    }
};

// Seeded scanner positions. In a room: a scanner on a tripod, in the middle of the room (15-85%
// of its width and depth) at 40-70% of its height, its tripod's column down to the floor at
// least 2% of the room's size clear of every model's bounding box (not under a table, not over
// an object). A scene without a room: around its bounding box, on a sphere of 1.5 times its
// diagonal.
std::vector<Vec3> scanner_positions(const Scene& sc, uint32_t count, uint64_t seed,
                                    const std::string& source) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    std::vector<Box> models;
    Box all;
    for (const SceneSurface& s : sc.surfaces) {
        Box b;
        for (const Vec3& v : s.mesh.vertices) b.add(v), all.add(v);
        if (s.is_model && !s.mesh.vertices.empty()) models.push_back(b);
    }
    std::vector<Vec3> out;
    if (!sc.has_room) {
        const Vec3 c = (all.lo + all.hi) * 0.5f;
        const float r = 1.5f * length(all.hi - all.lo);
        std::normal_distribution<float> g(0.f, 1.f);
        while (out.size() < count) {
            const Vec3 d{g(rng), g(rng), g(rng)};
            const float len = length(d);
            if (len > 1e-3f) out.push_back(c + d * (r / len));
        }
        return out;
    }
    const Vec3 s = sc.room_size;
    const float margin = 0.02f * std::max({s.x, s.y, s.z});
    for (int tries = 0; out.size() < count; ++tries) {
        if (tries > 100000)
            throw Error(fmt::format("{}: scan: no room for a scanner clear of the models", source));
        const Vec3 p{s.x * (0.15f + 0.7f * u(rng)), s.y * (0.4f + 0.3f * u(rng)),
                     s.z * (0.15f + 0.7f * u(rng))};
        // The column from the floor to the scanner against each box, grown by the margin.
        auto blocks = [&](const Box& b) {
            return p.x > b.lo.x - margin && p.x < b.hi.x + margin && p.z > b.lo.z - margin &&
                   p.z < b.hi.z + margin && b.lo.y < p.y + margin;
        };
        if (std::none_of(models.begin(), models.end(), blocks)) out.push_back(p);
    }
    return out;
}

// One sweep of every scanner at angular step `step` (radians); azimuths start at a seeded
// offset per scanner. Hits in scanner, row, column order (the same on every thread count).
ScanPoints sweep(const ExactVisibility& exact, const std::vector<Vec3>& scanners, double step,
                 uint64_t seed) {
    const int rows = std::max(1, int(std::lround(M_PI / step)));
    const int cols = std::max(1, int(std::lround(2 * M_PI / step)));
    std::mt19937_64 rng(seed ^ 0x5ca9ULL);
    std::uniform_real_distribution<double> u(0.0, 2 * M_PI);
    ScanPoints out;
    for (const Vec3& o : scanners) {
        const double phi0 = u(rng);
        std::vector<ScanPoints> per_row(rows);
        tbb::parallel_for(0, rows, [&](int i) {
            ScanPoints& row = per_row[i];
            const double theta = -M_PI / 2 + (i + 0.5) * M_PI / rows;
            for (int j = 0; j < cols; ++j) {
                const double phi = phi0 + (j + 0.5) * 2 * M_PI / cols;
                const Vec3 d{float(std::cos(theta) * std::cos(phi)), float(std::sin(theta)),
                             float(std::cos(theta) * std::sin(phi))};
                const ExactVisibility::Hit h = exact.intersect(o, d, 0.f, 1e30f);
                if (h.surface < 0 || !(h.t > 0)) continue;
                Vec3 n = h.normal;
                if (dot(n, d) > 0) n = n * -1.f;  // the side the beam came from
                row.points.positions.push_back(o + d * h.t);
                row.points.normals.push_back(n);
                row.sensors.push_back(o);
                row.surface.push_back(uint32_t(h.surface));
            }
        });
        for (ScanPoints& r : per_row) {
            auto append = [](auto& to, const auto& from) {
                to.insert(to.end(), from.begin(), from.end());
            };
            append(out.points.positions, r.points.positions);
            append(out.points.normals, r.points.normals);
            append(out.sensors, r.sensors);
            append(out.surface, r.surface);
        }
    }
    return out;
}

}  // namespace

ScanPoints scan_scene(const Scene& sc, const ExactVisibility& exact, uint32_t scanners,
                      uint64_t points, uint64_t seed, const std::string& source) {
    if (scanners < 1 || scanners > 64)
        throw Error(fmt::format("{}: scan: {} scanners out of range (1..64)", source, scanners));
    if (points < 2) throw Error(fmt::format("{}: scan: {} points: too few", source, points));
    const std::vector<Vec3> at = scanner_positions(sc, scanners, seed, source);
    // A coarse sweep (one degree) counts the hits; the step then scales so that all scanners
    // together record about `points` (hits grow as 1 / step^2).
    const double pilot = M_PI / 180;
    const size_t hits = sweep(exact, at, pilot, seed).points.size();
    if (hits == 0) throw Error(fmt::format("{}: scan: the scanners' beams hit nothing", source));
    const double step = pilot * std::sqrt(double(hits) / double(points));
    // The beams the step asks for: a scene the pilot barely hits, with many points asked,
    // would take billions.
    const double beams = double(at.size()) * (M_PI / step) * (2 * M_PI / step);
    if (beams > 4e9)
        throw Error(
            fmt::format("{}: scan: {:.3g} beams for {} points ({} pilot hits): the "
                        "scanners see too little of the scene",
                        source, beams, points, hits));
    ScanPoints out = sweep(exact, at, step, seed);
    // Normals and radii are estimated from neighbours: a handful of hits says nothing.
    constexpr size_t kMinHits = 16;
    if (out.points.size() < kMinHits)
        throw Error(
            fmt::format("{}: scan: {} hits for points {}, fewer than {}: ask for more "
                        "points",
                        source, out.points.size(), points, kMinHits));
    out.scanners = at;
    out.step = step;
    // Every point's disc as if the scan's points covered the surfaces evenly: the "sample
    // spacing" that --noise counts in.
    const double area = scene_area(sc);
    const size_t n = out.points.size();
    out.points.radii.assign(n, float(std::sqrt(area / (M_PI * double(std::max<size_t>(n, 1))))));
    return out;
}

}  // namespace vmap
