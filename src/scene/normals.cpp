// Normal estimation: k-NN plane fits (PCA), oriented along a minimum spanning tree (Hoppe 1992).
//
// Everything that runs in parallel writes only to its own point's slots, and everything that
// depends on visiting order (spanning tree, sums over the cloud) runs serially, so the result
// does not depend on the number of threads.

#include "vmap/normals.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <limits>
#include <mutex>
#include <numeric>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "geom/morton.h"
#include "scene/cloud_knn.h"
#include "scene/free_space.h"
#include "util/small_solve.h"
#include "vmap/error.h"
#include "vmap/parallel.h"

namespace vmap {
namespace {

constexpr size_t kMinK = 3;
constexpr size_t kMaxK = 1000;
constexpr int kMaxRefits = 10;

// Spreads at or below this fraction of the coordinates' magnitude are rounding noise, not
// geometry: a plane fitted through them would be arbitrary. Storing a coordinate as float moves
// it by at most FLT_EPSILON / 2 of its magnitude, so collinear points stay inside this; it is
// kept that small so that fine sampling far from the origin still counts as a surface (1 mm
// spacing 1 km out spreads about 4 times the limit).
constexpr double kRoundingUlps = 2.0 * FLT_EPSILON;

// Edges touching a point without a plane of its own cost more than any real edge (which cost
// at most 1), so Prim's reaches such points last and they rarely relay orientation.
constexpr float kDegenerateEdgeWeight = 2.0f;

struct Dvec {
    double x = 0, y = 0, z = 0;
};

Dvec to_d(Vec3 v) { return {v.x, v.y, v.z}; }
Dvec operator-(Dvec a, Dvec b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
double ddot(Dvec a, Dvec b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
double max_abs(Vec3 v) {
    return std::max({std::fabs(double(v.x)), std::fabs(double(v.y)), std::fabs(double(v.z))});
}

// Symmetric 3x3 eigen-decomposition by cyclic Jacobi rotations. Small, unconditionally stable
// and exact enough for covariance matrices whose eigenvalues span many orders of magnitude
// (a flat neighbourhood's smallest one is near zero), which closed-form cubic roots are not.
struct Eigen3 {
    double values[3];  // ascending
    Dvec vectors[3];   // unit, vectors[i] belongs to values[i]
};

Eigen3 symmetric_eigen(const double m[3][3]) {
    double a[3][3];
    double v[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) a[i][j] = m[i][j];

    for (int sweep = 0; sweep < 50; ++sweep) {
        const double off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        const double diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        if (off == 0.0 || off <= 1e-36 * diag) break;
        for (int p = 0; p < 2; ++p) {
            for (int q = p + 1; q < 3; ++q) {
                const double apq = a[p][q];
                if (apq == 0.0) continue;
                // Rotation angle that zeroes a[p][q]; taking the smaller root of
                // t^2 + 2 theta t - 1 = 0 keeps |angle| <= pi/4, which is what makes it stable.
                const double theta = (a[q][q] - a[p][p]) / (2.0 * apq);
                const double t =
                    (theta >= 0 ? 1.0 : -1.0) / (std::fabs(theta) + std::sqrt(theta * theta + 1.0));
                const double c = 1.0 / std::sqrt(t * t + 1.0);
                const double s = t * c;
                for (int k = 0; k < 3; ++k) {  // a <- a * J
                    const double akp = a[k][p], akq = a[k][q];
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for (int k = 0; k < 3; ++k) {  // a <- J^T * a
                    const double apk = a[p][k], aqk = a[q][k];
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                a[p][q] = a[q][p] = 0.0;
                for (int k = 0; k < 3; ++k) {  // v <- v * J
                    const double vkp = v[k][p], vkq = v[k][q];
                    v[k][p] = c * vkp - s * vkq;
                    v[k][q] = s * vkp + c * vkq;
                }
            }
        }
    }

    int order[3] = {0, 1, 2};
    std::sort(order, order + 3,
              [&](int i, int j) { return a[i][i] < a[j][j] || (a[i][i] == a[j][j] && i < j); });
    Eigen3 e;
    for (int r = 0; r < 3; ++r) {
        const int i = order[r];
        e.values[r] = a[i][i];
        Dvec col{v[0][i], v[1][i], v[2][i]};
        const double len = std::sqrt(ddot(col, col));
        e.vectors[r] = {col.x / len, col.y / len, col.z / len};
    }
    return e;
}

std::string prefix(const char* source) {
    return std::string(source ? source : "point cloud") + ": ";
}

Dvec centroid_of(const std::vector<Vec3>& pts) {
    // Serial on purpose: a parallel reduction would round differently per thread count.
    Dvec c;
    for (const Vec3& p : pts) {
        c.x += p.x;
        c.y += p.y;
        c.z += p.z;
    }
    const double n = double(pts.size());
    return {c.x / n, c.y / n, c.z / n};
}

// Rejects clouds through which no plane can be fitted at all, so that the per-point fits below
// always have some 2D structure to find.
void check_not_degenerate(const std::vector<Vec3>& pts, Dvec c, const char* source) {
    const Vec3 first = pts[0];
    if (std::all_of(pts.begin(), pts.end(), [&](Vec3 p) { return p == first; })) {
        throw Error(prefix(source) + "all " + std::to_string(pts.size()) +
                    " points coincide, so no plane can be fitted to estimate normals; supply "
                    "normals with the points");
    }
    double cov[3][3] = {};
    double scale = 0;
    for (const Vec3& p : pts) {
        const Dvec d = to_d(p) - c;
        const double dv[3] = {d.x, d.y, d.z};
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) cov[i][j] += dv[i] * dv[j];
        scale = std::max(scale, max_abs(p));
    }
    // The dominant axis is the line's direction if the points are collinear; measure the
    // largest distance from that line rather than an eigenvalue ratio, so that a single point
    // off the line is enough to count as a plane.
    const Dvec axis = symmetric_eigen(cov).vectors[2];
    double off_line2 = 0;
    for (const Vec3& p : pts) {
        const Dvec d = to_d(p) - c;
        const double along = ddot(d, axis);
        off_line2 = std::max(off_line2, ddot(d, d) - along * along);
    }
    const double tol = kRoundingUlps * scale;
    if (off_line2 <= tol * tol) {
        throw Error(prefix(source) + "all " + std::to_string(pts.size()) +
                    " points are collinear, so no plane can be fitted to estimate normals; "
                    "supply normals with the points");
    }
}

// Per point: its k nearest neighbours (itself or a duplicate of it among them) and the
// unoriented normal of their best-fit plane.
struct LocalFits {
    size_t k = 0;
    std::vector<uint32_t> neighbours;  // k per point
    std::vector<Vec3> normals;         // the weighted fit over all candidates: oriented
    // The re-fits on the point's own sheet (estimate_normals' result). Orientation runs on
    // `normals`, whose axes turn smoothly across an edge, where the sheet fits turn by the
    // edge's full angle and leave the free-space probes and rays of a point right at the edge
    // grazing the other face; each sheet normal then takes the sign of its smooth one.
    std::vector<Vec3> sheet_normals;
    std::vector<uint8_t> degenerate;  // neighbourhood coincident or collinear: normal unknown
    // The points' measured scatter off their surfaces (estimate_surface_noise's sigma where
    // roughness_of sees one, else 0) and the slack off the tangent plane that the same-sheet
    // tests allow for it (the roughness, 3 sqrt 2 sigma).
    float noise = 0, slack = 0;
    size_t at_creases = 0;  // points the crease pass gave a plane through them
};

// The weighted least-squares plane normal of the given points (weights w, or all 1 when null),
// or nothing if they span no plane, or if their spread across their main direction is under
// min_aspect of the spread along it (a strip or a line, not a patch).
std::optional<Vec3> plane_normal(const std::vector<Vec3>& pts, const uint32_t* idx, size_t m,
                                 const float* w = nullptr, double min_aspect = 0) {
    Dvec mean;
    double scale = 0, wsum = 0;
    for (size_t j = 0; j < m; ++j) {
        const Vec3 p = pts[idx[j]];
        const double wj = w ? w[j] : 1.0;
        mean.x += wj * p.x;
        mean.y += wj * p.y;
        mean.z += wj * p.z;
        wsum += wj;
        scale = std::max(scale, max_abs(p));
    }
    if (!(wsum > 0)) return std::nullopt;
    mean = {mean.x / wsum, mean.y / wsum, mean.z / wsum};
    double cov[3][3] = {};
    for (size_t j = 0; j < m; ++j) {
        const Dvec d = to_d(pts[idx[j]]) - mean;
        const double wj = w ? w[j] : 1.0;
        const double dv[3] = {d.x, d.y, d.z};
        for (int a = 0; a < 3; ++a)
            for (int b = a; b < 3; ++b) cov[a][b] += wj * dv[a] * dv[b];
    }
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < a; ++b) cov[a][b] = cov[b][a];

    const Eigen3 e = symmetric_eigen(cov);
    // The middle eigenvalue is the spread across the points' main direction; if that is
    // rounding noise they lie on a line or coincide, and the smallest eigenvector is arbitrary.
    const double across = std::sqrt(std::max(e.values[1], 0.0) / wsum);
    if (across <= kRoundingUlps * scale) return std::nullopt;
    if (e.values[1] < min_aspect * e.values[2]) return std::nullopt;
    const Dvec v = e.vectors[0];
    return Vec3{float(v.x), float(v.y), float(v.z)};
}

// Fit weights fall off as exp(-d^2 / h^2), h the distance to the point's 6th nearest
// neighbour: about 1.4 sample spacings, wherever the density, so that the nearest points
// dominate the fit on a tight curve or a thin part, and the farther candidates still steady it
// on a flat or noisy one.
constexpr size_t kBandwidthNeighbour = 6;
constexpr size_t kNoisyReach = 2;

// Is q (fitted normal nq) on p's own sheet, for the re-fit? Their normal axes within about 37
// degrees (an edge's other face fails), and the chord from p to q consistent with both tangent
// planes: the mean of the two normals (signs aligned) within 0.25 of the chord's length off
// perpendicular (the other face of a thin part or plate, and another surface a few millimetres
// away, fail). On a curve the two planes tilt opposite ways and their offsets cancel, so a
// small sphere keeps its neighbours, which a test against p's plane alone would drop.
// On a noisy cloud the slack (LocalFits::slack) is allowed off the planes besides.
bool on_sheet(Vec3 p, Vec3 np, Vec3 q, Vec3 nq, float slack) {
    const float c = dot(np, nq);
    if (std::fabs(c) < 0.8f) return false;
    const Vec3 d = q - p;
    const float off = std::max(0.0f, 0.5f * std::fabs(dot(np + (c < 0 ? -nq : nq), d)) - slack);
    return off * off <= 0.0625f * length2(d);
}

// One pass of weighted plane fits over every point's `c` candidates (cand, d2: c per point,
// nearest first). Without `prev` all candidates count by distance; with it, only those on the
// point's sheet by the previous pass's normals (and the point itself), and a point whose
// re-fit spans no plane keeps its previous normal. Reads prev only, so the order of the
// points does not matter.
void fit_pass(const std::vector<Vec3>& pts, const std::vector<uint32_t>& cand,
              const std::vector<float>& d2, size_t c, const std::vector<Vec3>* prev,
              LocalFits& fits, std::vector<Vec3>& out) {
    // Noisy: the bandwidth at the c / kNoisyReach-th nearest (the 24th of 48).
    const size_t n = pts.size(),
                 band = std::min(c - 1, fits.noise > 0 ? c / kNoisyReach : kBandwidthNeighbour);
    parallel_for_range<size_t>(n, 256, [&](size_t chunk_begin, size_t chunk_end) {
        std::vector<float> w(c);
        for (size_t i = chunk_begin; i < chunk_end; ++i) {
            const uint32_t* nb = &cand[i * c];
            const float h2 = d2[i * c + band];
            size_t kept = 0;
            for (size_t j = 0; j < c; ++j) {
                w[j] = h2 > 0 ? std::exp(-d2[i * c + j] / h2) : 1.0f;
                if (prev && nb[j] != i &&
                    !on_sheet(pts[i], (*prev)[i], pts[nb[j]], (*prev)[nb[j]], fits.slack))
                    w[j] = 0;
                kept += w[j] > 0;
            }
            // A re-fit on fewer than 3 neighbours besides the point (one right at an edge,
            // whose fit leans between the faces, keeps almost none) is no plane to trust.
            std::optional<Vec3> normal;
            if (!prev || kept > kMinK) normal = plane_normal(pts, nb, c, w.data());
            if (!prev) {
                fits.degenerate[i] = !normal.has_value();
                out[i] = normal.has_value() ? *normal : Vec3{0, 0, 1};
            } else {
                out[i] = fits.degenerate[i] || !normal.has_value() ? (*prev)[i] : *normal;
            }
        }
    });
}

// Two unit vectors (u, v) that make a right-handed frame with the unit normal nz: u across the
// normal's smallest component.
std::pair<Vec3, Vec3> tangent_frame(Vec3 nz) {
    const Vec3 ax = std::fabs(nz.x) <= std::fabs(nz.y) && std::fabs(nz.x) <= std::fabs(nz.z)
                        ? Vec3{1, 0, 0}
                    : std::fabs(nz.y) <= std::fabs(nz.z) ? Vec3{0, 1, 0}
                                                         : Vec3{0, 0, 1};
    Vec3 u = ax - nz * dot(ax, nz);
    u = u / length(u);
    return {u, Vec3{nz.y * u.z - nz.z * u.y, nz.z * u.x - nz.x * u.z, nz.x * u.y - nz.y * u.x}};
}

// Adds w * (x^2, xy, y^2, x, y, 1) z to the normal equations of a quadric height fit.
void add_quadric_row(double (&a)[6][6], double (&b)[6], double w, double x, double y, double z) {
    const double phi[6] = {x * x, x * y, y * y, x, y, 1.0};
    for (int r = 0; r < 6; ++r) {
        b[r] += w * phi[r] * z;
        for (int k = 0; k < 6; ++k) a[r][k] += w * phi[r] * phi[k];
    }
}

// Jet fits (a second-order height function over the tangent plane, Cazals and Pouget 2005): in
// the frame of the point's sheet normal, z = a x^2 + b xy + c y^2 + d x + e y + f by weighted
// least squares over the candidates on its sheet, and the normal is the surface's at the point,
// (-d, -e, 1). A plane fit leans toward the side with more neighbours on a curve (a rim, a
// thin leg or horn sampled by a few points across, a neighbourhood cut by a crease), where a
// quadric follows the curve. Weights as the plane fit's with the bandwidth of the
// kJetBandwidthNeighbour-th nearest (six unknowns need more points in reach than a plane's
// three); a point with fewer than kJetMinNeighbours on its sheet, a singular system or a
// surface steeper than 45 degrees in that frame keeps its plane normal.
constexpr size_t kJetBandwidthNeighbour = 12;
constexpr size_t kJetMinNeighbours = 10;

void jet_pass(const std::vector<Vec3>& pts, const std::vector<uint32_t>& cand,
              const std::vector<float>& d2, size_t c, LocalFits& fits) {
    // Noisy: the bandwidth twice as far (kNoisyReach), as the plane fits'.
    const size_t n = pts.size(),
                 band = std::min(c - 1, fits.noise > 0 ? kNoisyReach * kJetBandwidthNeighbour
                                                       : kJetBandwidthNeighbour);
    std::vector<Vec3> out(n);
    parallel_for_range<size_t>(n, 256, [&](size_t chunk_begin, size_t chunk_end) {
        for (size_t i = chunk_begin; i < chunk_end; ++i) {
            const Vec3 nz = fits.sheet_normals[i];
            out[i] = nz;
            const float h2 = d2[i * c + band];
            if (fits.degenerate[i] || !(h2 > 0)) continue;
            const auto [u, v] = tangent_frame(nz);
            const double s = 1.0 / std::sqrt(double(h2));  // coordinates in bandwidths
            double a[6][6] = {}, b[6] = {};
            size_t kept = 0;
            const uint32_t* nb = &cand[i * c];
            for (size_t j = 0; j < c; ++j) {
                if (nb[j] != i &&
                    !on_sheet(pts[i], nz, pts[nb[j]], fits.sheet_normals[nb[j]], fits.slack))
                    continue;
                const double w = std::exp(-double(d2[i * c + j]) / double(h2));
                const Vec3 d = pts[nb[j]] - pts[i];
                const double x = s * dot(d, u), y = s * dot(d, v), z = s * dot(d, nz);
                add_quadric_row(a, b, w, x, y, z);
                kept += nb[j] != i;
            }
            if (kept < kJetMinNeighbours || !detail::solve_small(a, b)) continue;
            const double gx = b[3], gy = b[4];
            if (gx * gx + gy * gy > 1.0) continue;
            const Vec3 m = nz - u * float(gx) - v * float(gy);
            out[i] = m / length(m);
        }
    });
    fits.sheet_normals.swap(out);
}

// Creases. On a surface with a crease (a CAD part's edge, a box's corner, a rim turned sharply)
// every fit above leans: the candidates on the far side of the crease pull the plane, and the
// quadric cannot follow a kink, while the re-fits' same-sheet test keeps the far face whenever
// the leaning normals sit within its angle of both faces. A point on one face lies exactly in
// that face's plane, and so do the candidates on its side: so where the quadric over all the
// candidates (weighted as the plane fits, in the frame of the point's normal) misses them by
// more than kCreaseResidual bandwidths RMS, the point takes, among its candidates' normals (its
// own among them), the plane through itself that holds the most weight within kCreaseTolerance
// bandwidths, re-fitted on the candidates it holds, if that plane holds at least kCreaseShare of
// the weight: on a crease the point's own face holds about half of it or more. A smooth curve,
// sampled finely enough for the quadric to follow it, stays as it was, and so does a point
// whose own plane holds the most, or a faceted curve (faces about as wide as the spacing, as on
// low-poly animals), where no plane through the point holds that much.
// Noisy clouds are left out: there a point is not on its plane, and the tolerance would
// have to grow with the noise until it held both faces (docs/validation.md "Raw clouds:
// creases").
constexpr double kCreaseResidual = 0.05;
constexpr double kCreaseTolerance = 0.03;
constexpr double kCreaseShare = 0.45;
constexpr size_t kCreaseMinInliers = 5;
// ... and the points it holds must make a patch, not a strip: their spread across their main
// direction at least this share of the spread along it (in variance; a half disc gives about
// 0.36). A scan's points lie in lines, and a line of them holds every plane through it.
constexpr double kCreaseMinAspect = 0.1;

void crease_pass(const std::vector<Vec3>& pts, const std::vector<uint32_t>& cand,
                 const std::vector<float>& d2, size_t c, LocalFits& fits) {
    if (fits.noise > 0) return;
    const size_t n = pts.size(), band = std::min(c - 1, kBandwidthNeighbour);
    std::vector<Vec3> out = fits.sheet_normals;
    std::vector<uint8_t> moved(n, 0);
    parallel_for_range<size_t>(n, 256, [&](size_t chunk_begin, size_t chunk_end) {
        std::vector<float> w(c);
        std::vector<Vec3> d(c);                   // offsets from the point
        std::vector<std::array<double, 3>> l(c);  // the same in bandwidths, in its frame
        std::vector<uint32_t> inliers(c);
        std::vector<float> wi(c);
        for (size_t i = chunk_begin; i < chunk_end; ++i) {
            const float h2 = d2[i * c + band];
            if (fits.degenerate[i] || !(h2 > 0)) continue;
            const Vec3 nz = fits.sheet_normals[i];
            const auto [u, v] = tangent_frame(nz);
            const double s = 1.0 / std::sqrt(double(h2));  // coordinates in bandwidths
            const uint32_t* nb = &cand[i * c];
            double a[6][6] = {}, b[6] = {}, wsum = 0;
            for (size_t j = 0; j < c; ++j) {
                w[j] = std::exp(-d2[i * c + j] / h2);
                d[j] = pts[nb[j]] - pts[i];
                l[j] = {s * dot(d[j], u), s * dot(d[j], v), s * dot(d[j], nz)};
                add_quadric_row(a, b, w[j], l[j][0], l[j][1], l[j][2]);
                wsum += w[j];
            }
            if (!detail::solve_small(a, b)) continue;
            double r2 = 0;
            for (size_t j = 0; j < c; ++j) {
                const auto [x, y, z] = l[j];
                const double r =
                    z - (b[0] * x * x + b[1] * x * y + b[2] * y * y + b[3] * x + b[4] * y + b[5]);
                r2 += w[j] * r * r;
            }
            if (r2 <= kCreaseResidual * kCreaseResidual * wsum) continue;
            const float tol = float(kCreaseTolerance / s);
            auto held = [&](Vec3 nj) {
                double score = 0;
                for (size_t q = 0; q < c; ++q)
                    if (std::fabs(dot(d[q], nj)) < tol) score += w[q];
                return score;
            };
            double best = held(nz);
            size_t pick = c;
            for (size_t j = 0; j < c; ++j) {
                if (nb[j] == i || fits.degenerate[nb[j]]) continue;
                const double score = held(fits.sheet_normals[nb[j]]);
                if (score > best) best = score, pick = j;
            }
            if (pick == c || best < kCreaseShare * wsum) continue;
            const Vec3 nj = fits.sheet_normals[nb[pick]];
            size_t m = 0;
            for (size_t q = 0; q < c; ++q)
                if (std::fabs(dot(d[q], nj)) < tol) inliers[m] = nb[q], wi[m++] = w[q];
            if (m < kCreaseMinInliers) continue;
            if (const auto normal =
                    plane_normal(pts, inliers.data(), m, wi.data(), kCreaseMinAspect))
                out[i] = *normal, moved[i] = 1;
        }
    });
    fits.sheet_normals.swap(out);
    fits.at_creases = size_t(std::count(moved.begin(), moved.end(), uint8_t(1)));
}

// The k nearest neighbours of every point (fits.neighbours: the graph orientation runs on)
// and, when `fit` is set, each point's normal: a weighted plane fit of its params.fit_neighbours
// nearest, re-fitted params.refits times on the neighbours of its own sheet (otherwise
// fits.normals is left to the caller).
LocalFits fit_local_planes(const std::vector<Vec3>& pts, const NormalEstimationParams& params,
                           bool fit = true) {
    const size_t n = pts.size();
    LocalFits fits;
    const size_t kk = fits.k = std::min(params.k, n);
    PointSet at;
    at.positions = pts;
    const SurfaceNoise sn = estimate_surface_noise(at);
    fits.slack = roughness_of(sn);
    fits.noise = fits.slack > 0 ? float(sn.sigma) : 0.f;
    // On a noisy cloud the plane fits reach twice as far (kNoisyReach): the normal's error
    // from the noise falls with the fit's reach and with the points it weighs (on the bunny's
    // room at a quarter spacing of noise, 3.1 -> 2.0 degrees at the median; its curved object
    // unchanged: docs/validation.md "Noisy scans").
    const size_t reach = fits.noise > 0 ? kNoisyReach : 1;
    const size_t c = fit ? std::min(std::max(params.k, reach * params.fit_neighbours), n) : kk;
    fits.neighbours.resize(n * kk);
    fits.degenerate.assign(n, 0);
    std::vector<uint32_t> cand(n * c);
    std::vector<float> d2(n * c);

    const detail::CloudAdaptor adaptor{pts};
    const detail::KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16));
    parallel_for_range<size_t>(n, 256, [&](size_t chunk_begin, size_t chunk_end) {
        for (size_t i = chunk_begin; i < chunk_end; ++i) {
            uint32_t* nb = &cand[i * c];
            const float query[3] = {pts[i].x, pts[i].y, pts[i].z};
            const size_t found = tree.knnSearch(query, c, nb, &d2[i * c]);
            // The tree holds n >= c points so it always finds c; fill defensively regardless.
            for (size_t j = found; j < c; ++j) nb[j] = uint32_t(i), d2[i * c + j] = 0;
            std::copy(nb, nb + kk, &fits.neighbours[i * kk]);
        }
    });
    if (!fit) return fits;
    fits.normals.resize(n);
    fit_pass(pts, cand, d2, c, nullptr, fits, fits.normals);
    fits.sheet_normals = fits.normals;
    std::vector<Vec3> next(n);
    for (int pass = 0; pass < params.refits; ++pass) {
        fit_pass(pts, cand, d2, c, &fits.sheet_normals, fits, next);
        fits.sheet_normals.swap(next);
    }
    if (params.jet) jet_pass(pts, cand, d2, c, fits);
    if (params.creases) crease_pass(pts, cand, d2, c, fits);
    return fits;
}

// Symmetrised k-NN graph in compressed rows. An edge listed by both ends appears twice;
// Prim's copes, and skipping the deduplication keeps this a single serial pass.
struct Graph {
    std::vector<size_t> offsets;  // n + 1
    std::vector<uint32_t> adjacent;
};

Graph symmetrise(const LocalFits& fits, size_t n) {
    Graph g;
    g.offsets.assign(n + 1, 0);
    const size_t k = fits.k;
    for (size_t i = 0; i < n; ++i) {
        for (size_t j = 0; j < k; ++j) {
            const uint32_t o = fits.neighbours[i * k + j];
            if (o == i) continue;
            ++g.offsets[i + 1];
            ++g.offsets[o + 1];
        }
    }
    std::partial_sum(g.offsets.begin(), g.offsets.end(), g.offsets.begin());
    g.adjacent.resize(g.offsets[n]);
    std::vector<size_t> fill(g.offsets.begin(), g.offsets.end() - 1);
    for (size_t i = 0; i < n; ++i) {
        for (size_t j = 0; j < k; ++j) {
            const uint32_t o = fits.neighbours[i * k + j];
            if (o == i) continue;
            g.adjacent[fill[i]++] = o;
            g.adjacent[fill[o]++] = uint32_t(i);
        }
    }
    return g;
}

// Binary min-heap of points keyed by (weight, point), with decrease-key: each point sits in
// it at most once, where a plain priority queue would pile up stale entries for points that
// many neighbours reach. The point index breaks ties, so equal weights come out in a fixed order.
class PointHeap {
  public:
    explicit PointHeap(size_t n) : slot_(n, kAbsent) {}

    bool empty() const { return items_.empty(); }

    // Inserts `point` with key `weight`, or lowers its key to `weight`; returns whether it did
    // either (false when the point is already queued with a key no larger).
    bool push_or_lower(uint32_t point, float weight) {
        uint32_t i = slot_[point];
        if (i == kAbsent) {
            i = uint32_t(items_.size());
            items_.push_back({weight, point});
        } else if (weight < items_[i].weight) {
            items_[i].weight = weight;
        } else {
            return false;
        }
        sift_up(i);
        return true;
    }

    uint32_t pop() {
        const uint32_t top = items_[0].point;
        slot_[top] = kAbsent;
        items_[0] = items_.back();
        items_.pop_back();
        if (!items_.empty()) sift_down(0);
        return top;
    }

  private:
    struct Item {
        float weight;
        uint32_t point;
    };
    static constexpr uint32_t kAbsent = std::numeric_limits<uint32_t>::max();

    static bool before(const Item& a, const Item& b) {
        return a.weight < b.weight || (a.weight == b.weight && a.point < b.point);
    }
    void place(uint32_t i, const Item& item) {
        items_[i] = item;
        slot_[item.point] = i;
    }
    void sift_up(uint32_t i) {
        const Item item = items_[i];
        while (i > 0) {
            const uint32_t up = (i - 1) / 2;
            if (!before(item, items_[up])) break;
            place(i, items_[up]);
            i = up;
        }
        place(i, item);
    }
    void sift_down(uint32_t i) {
        const Item item = items_[i];
        const uint32_t size = uint32_t(items_.size());
        for (;;) {
            uint32_t child = 2 * i + 1;
            if (child >= size) break;
            if (child + 1 < size && before(items_[child + 1], items_[child])) ++child;
            if (!before(items_[child], item)) break;
            place(i, items_[child]);
            i = child;
        }
        place(i, item);
    }

    std::vector<Item> items_;
    std::vector<uint32_t> slot_;  // where each point is in items_, or kAbsent
};

// Edge weight for propagation: 1 - |cos| between the normals, and more (used last) for a pair
// that is not on one surface side, such as the two faces of a plate thinner than the spacing.
float edge_weight(const std::vector<Vec3>& pts, const std::vector<Vec3>& normals,
                  const std::vector<uint8_t>& degenerate, uint32_t a, uint32_t b, float slack) {
    if (degenerate[a] || degenerate[b]) return kDegenerateEdgeWeight;
    const float w = 1.0f - std::fabs(dot(normals[a], normals[b]));
    return detail::same_surface(pts[a], normals[a], pts[b], normals[b], slack) ? w : w + 1.0f;
}

// Orients the normals that `fixed` leaves free, in place: Prim's algorithm over the neighbour
// graph (Hoppe et al. 1992) grown from every fixed point at once, flipping each newly reached
// normal to agree with the one it was reached from. A component without a fixed point starts
// from its point farthest from the centroid (where "outward" is least ambiguous), pointing away.
void propagate(const std::vector<Vec3>& pts, Dvec centroid, const Graph& g,
               const std::vector<uint8_t>& degenerate, const std::vector<uint8_t>& fixed,
               std::vector<Vec3>& normals, float slack) {
    const size_t n = pts.size();
    std::vector<uint8_t> in_tree(n, 0);
    std::vector<uint32_t> parent(n);
    PointHeap heap(n);

    auto reach = [&](uint32_t v) {
        in_tree[v] = 1;
        for (size_t e = g.offsets[v]; e < g.offsets[v + 1]; ++e) {
            const uint32_t u = g.adjacent[e];
            if (!in_tree[u] &&
                heap.push_or_lower(u, edge_weight(pts, normals, degenerate, v, u, slack)))
                parent[u] = v;
        }
    };
    auto grow = [&]() {
        while (!heap.empty()) {
            const uint32_t v = heap.pop();
            const Vec3 from = normals[parent[v]];
            if (degenerate[v]) {
                normals[v] = from;
            } else if (dot(normals[v], from) < 0) {
                normals[v] = -normals[v];
            }
            reach(v);
        }
    };
    // All fixed points join the tree before any is expanded, so none is queued to be re-signed.
    for (uint32_t v = 0; v < n; ++v) in_tree[v] = fixed[v] && !degenerate[v];
    for (uint32_t v = 0; v < n; ++v)
        if (in_tree[v]) reach(v);
    grow();

    std::vector<double> far2(n);
    for (size_t i = 0; i < n; ++i) {
        const Dvec d = to_d(pts[i]) - centroid;
        far2[i] = ddot(d, d);
    }
    std::vector<uint32_t> by_distance(n);
    std::iota(by_distance.begin(), by_distance.end(), 0u);
    std::sort(by_distance.begin(), by_distance.end(), [&](uint32_t a, uint32_t b) {
        return far2[a] > far2[b] || (far2[a] == far2[b] && a < b);
    });
    // Every point farther out than the first unvisited one lies in a component already
    // finished, so that point is the farthest of its own component.
    for (const uint32_t root : by_distance) {
        if (in_tree[root]) continue;
        const Dvec away = to_d(pts[root]) - centroid;
        if (degenerate[root]) {
            const double len = std::sqrt(ddot(away, away));
            normals[root] =
                len > 0 ? Vec3{float(away.x / len), float(away.y / len), float(away.z / len)}
                        : Vec3{0, 0, 1};
        } else if (ddot(to_d(normals[root]), away) < 0) {
            normals[root] = -normals[root];
        }
        reach(root);
        grow();
    }
}

// A ray-decided sign that most of its same-surface neighbours contradict is a local mistake
// (a surface a few millimetres from another, seen by rays as the near side): it takes theirs.
// Space-decided neighbours count twice, undecided ones not at all. Computed on a snapshot, so
// the result does not depend on visiting order.
size_t agree_with_neighbours(const std::vector<Vec3>& pts, const LocalFits& fits,
                             const detail::SideVotes& votes, std::vector<Vec3>& normals) {
    const size_t n = pts.size(), k = fits.k;
    std::vector<uint8_t> flip(n, 0);
    parallel_for_range<size_t>(n, 1024, [&](size_t chunk_begin, size_t chunk_end) {
        for (size_t i = chunk_begin; i < chunk_end; ++i) {
            if (votes.cue[i] != detail::SideCue::kRays || fits.degenerate[i]) continue;
            float agree = 0, disagree = 0;
            for (size_t j = 0; j < k; ++j) {
                const uint32_t o = fits.neighbours[i * k + j];
                if (o == i || fits.degenerate[o] || votes.cue[o] == detail::SideCue::kNone)
                    continue;
                if (!detail::same_surface(pts[i], normals[i], pts[o], normals[o], fits.slack))
                    continue;
                const float w = votes.cue[o] == detail::SideCue::kSpace ? 2.0f : 1.0f;
                (dot(normals[i], normals[o]) > 0 ? agree : disagree) += w;
            }
            flip[i] = disagree > 2 * agree;
        }
    });
    size_t flipped = 0;
    for (size_t i = 0; i < n; ++i)
        if (flip[i]) {
            normals[i] = -normals[i];
            ++flipped;
        }
    return flipped;
}

// The votes spread along the surface: kVoteRounds rounds in which every point's belief becomes
// the mean of its own vote and its linked neighbours' beliefs, each signed by whether the two
// normals agree (links: same-surface neighbours whose normal axes lie within about 37 degrees).
// A point then faces the side its belief chooses. Over a few rounds a point hears a surface
// patch some kVoteRounds spacings wide, weighted by confidence, so a small patch of wrong votes
// (rays misled by a surface a few millimetres away, the inside of a thin part) inside a larger
// right one turns, while a narrow contact (an object on the floor, touching another) passes
// little: the two stay decided by their own points.
constexpr int kVoteRounds = 8;
constexpr float kVoteLinkCos = 0.8f;
// ... and a link's chord leaves each tangent plane by at most this many splat radii: the other
// face of a plate thinner than the spacing (within the same-surface test's angle at longer
// chords) stays out, whose votes are right with the opposite sign.
constexpr float kVoteLinkOffset = 0.5f;

size_t spread_votes(const std::vector<Vec3>& pts, const std::vector<float>& radii, const Graph& g,
                    const std::vector<uint8_t>& degenerate, const detail::SideVotes& votes,
                    std::vector<uint8_t>& fixed, std::vector<Vec3>& normals, float slack) {
    const size_t n = pts.size();
    // Belief along each point's current normal (already signed by its own vote).
    std::vector<float> own(n, 0.0f);
    for (size_t i = 0; i < n; ++i) own[i] = fixed[i] ? votes.weight[i] : 0.0f;
    std::vector<float> cur = own, next(n);
    auto linked = [&](uint32_t i, uint32_t j) {
        const Vec3 d = pts[j] - pts[i];
        const float reach = kVoteLinkOffset * std::min(radii[i], radii[j]) + slack;
        return !degenerate[j] && std::fabs(dot(normals[i], normals[j])) >= kVoteLinkCos &&
               std::fabs(dot(normals[i], d)) <= reach && std::fabs(dot(normals[j], d)) <= reach &&
               detail::same_surface(pts[i], normals[i], pts[j], normals[j], slack);
    };
    for (int round = 0; round < kVoteRounds; ++round) {
        parallel_for_range<size_t>(n, 1024, [&](size_t chunk_begin, size_t chunk_end) {
            for (size_t i = chunk_begin; i < chunk_end; ++i) {
                float sum = own[i];
                int count = 1;
                if (!degenerate[i])
                    for (size_t e = g.offsets[i]; e < g.offsets[i + 1]; ++e) {
                        const uint32_t j = g.adjacent[e];
                        if (!linked(uint32_t(i), j)) continue;
                        sum += dot(normals[i], normals[j]) > 0 ? cur[j] : -cur[j];
                        ++count;
                    }
                next[i] = sum / float(count);
            }
        });
        std::swap(cur, next);
    }
    size_t turned = 0;
    for (size_t i = 0; i < n; ++i) {
        if (degenerate[i] || cur[i] == 0) continue;
        if (cur[i] < 0) {
            normals[i] = -normals[i];
            turned += fixed[i];
        }
        fixed[i] = 1;
    }
    return turned;
}

// Open sheets by their shape. A sheet whose two sides are both free space inside the scene (an
// open box, a dome open below, a mask open at the back: SideVotes::open) gives the voxels
// nothing to decide by, and the rays go wrong wherever the sheet's concave side sees out
// through its opening while its convex side meets a wall nearby. What a modeller's winding
// says there is the convention "outward": away from what the sheet wraps around (the share of
// the area facing away from the mesh's own centroid, scripts/mesh-winding.py: 1.000 for the
// open box, 0.95 for the helmet, 0.89 for the mushroom and the lion mask). So the open points are
// joined into sheets over same-surface links, and a sheet that wraps around its centroid votes each
// point's side away from it, weighted by how squarely the point faces it, |(p - c) . n| / rms |p -
// c|, in place of its rays. Left to the rays:
// - sheets too flat for their centroid to say anything: the "wrap", mean |(p - c) . n| / rms
//   (the weight before its cap at 1), below kMinWrap (a plate's face or a table's top wraps an
//   order of magnitude less on the test scenes, the open meshes about twice as much or more; a
//   sphere gives 1);
// - sheets whose points mostly have a surface within the voxel probe's reach behind them
//   (SideVotes::open == 2): both sides are free only because the probe walked through a part
//   thinner than its reach (an animal's leg or ear, a plate, a thin-walled bowl), whose inner
//   faces face toward the centroid, not away; the rays see the other face there and decide
//   right. The open meshes have a minority of such points (at creases and rims), the thin
//   parts and plates of the test scenes most (docs/validation.md "4. Open sheets");
// - sheets of fewer than kMinSheet points (kVoteRounds squared): a patch the spread of the
//   neighbours' votes reaches across anyway, whose centroid is noise.
// In a scan from several scanners that the spacing search could not tell apart
// (SideVotes::scanned, no SideVotes::scanners; a scan too noisy to search is left as it was), most
// "open" sheets are closed shells whose shadows (an underside, a hollow no scanner saw into) let
// the voxels' free space in: "away from the centroid" is then right on the convex parts only (a
// dragon's belly, a curled tail face toward it). There the shape's vote is added to the rays'
// (weight times side, each), so a clear ray contrast outvotes the centroid: objects' signs on the
// means of seventeen scenes 91.85% -> 93.80% at four scanners and 93.32% -> 95.11% at eight
// (docs/validation.md "Scans: shells opened by shadows"). Where a scanner was found, or in samples,
// the open sheets are open meshes, for which the rays are wrong on the concave side that sees out
// through the opening: the shape alone (the sum cost test-many and test-tight four points each on
// their even samples).
// Serial (the sheets are found in index order and summed in it), so the result does not
// depend on the number of threads. Returns the points it decided.
constexpr double kMinWrap = 0.25;
constexpr double kMaxThinShare = 0.5;
constexpr size_t kMinSheet = size_t(kVoteRounds) * kVoteRounds;

size_t shape_votes(const std::vector<Vec3>& pts, const Graph& g,
                   const std::vector<uint8_t>& degenerate, const std::vector<Vec3>& normals,
                   detail::SideVotes& votes, float slack) {
    const size_t n = pts.size();
    std::vector<uint8_t> seen(n, 0);
    std::vector<uint32_t> stack, sheet;
    size_t decided = 0;
    // A scan whose scanners the spacing could not single out (several overlapping): its "open"
    // sheets are mostly closed shells opened by shadows, where the shape's vote is added to the
    // rays' (see above).
    const bool shells = votes.scanned && votes.scanners.empty();
    for (uint32_t seed = 0; seed < n; ++seed) {
        if (!votes.open[seed] || degenerate[seed] || seen[seed]) continue;
        // The sheet: open points reached from the seed over same-surface neighbours.
        sheet.clear();
        seen[seed] = 1;
        stack.push_back(seed);
        while (!stack.empty()) {
            const uint32_t v = stack.back();
            stack.pop_back();
            sheet.push_back(v);
            for (size_t e = g.offsets[v]; e < g.offsets[v + 1]; ++e) {
                const uint32_t u = g.adjacent[e];
                if (seen[u] || !votes.open[u] || degenerate[u] ||
                    !detail::same_surface(pts[v], normals[v], pts[u], normals[u], slack))
                    continue;
                seen[u] = 1;
                stack.push_back(u);
            }
        }
        if (sheet.size() < kMinSheet) continue;
        std::sort(sheet.begin(), sheet.end());  // sums in index order
        const double count = double(sheet.size());
        Dvec c;
        size_t thin = 0;
        for (const uint32_t m : sheet) {
            c.x += pts[m].x;
            c.y += pts[m].y;
            c.z += pts[m].z;
            thin += votes.open[m] == 2;
        }
        c = {c.x / count, c.y / count, c.z / count};
        double r2 = 0;
        for (const uint32_t m : sheet) {
            const Dvec d = to_d(pts[m]) - c;
            r2 += ddot(d, d);
        }
        const double rms = std::sqrt(r2 / count);
        if (!(rms > 0) || double(thin) > kMaxThinShare * count) continue;
        double wrap = 0;
        for (const uint32_t m : sheet) wrap += std::fabs(ddot(to_d(pts[m]) - c, to_d(normals[m])));
        if (wrap / count < kMinWrap * rms) continue;
        for (const uint32_t m : sheet) {
            const double off = ddot(to_d(pts[m]) - c, to_d(normals[m]));
            if (off == 0 || votes.cue[m] == detail::SideCue::kView) continue;
            float v = float(std::min(1.0, std::fabs(off) / rms)) * (off > 0 ? 1.f : -1.f);
            if (shells && votes.cue[m] == detail::SideCue::kRays)
                v += votes.weight[m] * float(votes.sign[m]);
            votes.sign[m] = int8_t(v > 0 || (v == 0 && off > 0) ? 1 : -1);
            votes.cue[m] = detail::SideCue::kShape;
            votes.weight[m] = std::fabs(v);
            ++decided;
        }
    }
    return decided;
}

// Point indices in Morton (Z-curve) order. Working on the points in this order keeps
// neighbours near each other in memory, which is most of the speed of the k-NN queries and of
// the spanning tree on clouds stored in scan or random order.
std::vector<uint32_t> spatial_order(const std::vector<Vec3>& pts) {
    Vec3 lo = pts[0], hi = pts[0];
    for (const Vec3& p : pts) {
        lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
        hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
    }
    const double extent = std::max({double(hi.x) - lo.x, double(hi.y) - lo.y, double(hi.z) - lo.z});
    const double to_cell = extent > 0 ? double((1 << 21) - 1) / extent : 0.0;
    auto cell = [&](float v, float l) { return uint64_t((double(v) - l) * to_cell); };

    const size_t n = pts.size();
    std::vector<std::pair<uint64_t, uint32_t>> keyed(n);
    parallel_for_range<size_t>(n, 4096, [&](size_t chunk_begin, size_t chunk_end) {
        for (size_t i = chunk_begin; i < chunk_end; ++i) {
            const Vec3 p = pts[i];
            const uint64_t code = detail::spread_bits(cell(p.x, lo.x)) << 2 |
                                  detail::spread_bits(cell(p.y, lo.y)) << 1 |
                                  detail::spread_bits(cell(p.z, lo.z));
            keyed[i] = {code, uint32_t(i)};
        }
    });
    // Keys are unique (the index is part of them), so the order is the same however sorted.
    std::sort(keyed.begin(), keyed.end());
    std::vector<uint32_t> order(n);
    for (size_t r = 0; r < n; ++r) order[r] = keyed[r].second;
    return order;
}

Vec3 unit_or(Vec3 v, Vec3 fallback) {
    const float len = length(v);
    return len > 0 && std::isfinite(len) ? v / len : fallback;
}

// Signs of fits.normals (points in spatial order) by params.orientation, reported in words.
void orient_fits(const std::vector<Vec3>& pts, Dvec centroid, LocalFits& fits,
                 std::vector<float> radii, const NormalEstimationParams& params,
                 OrientationReport& rep) {
    const size_t n = pts.size();
    std::vector<uint8_t> fixed(n, 0);
    std::vector<Vec3>& normals = fits.normals;
    const Vec3 c{float(centroid.x), float(centroid.y), float(centroid.z)};
    auto fix_toward = [&](size_t i, Vec3 target) {
        if (fits.degenerate[i]) return;
        if (dot(normals[i], target - pts[i]) < 0) normals[i] = -normals[i];
        fixed[i] = 1;
    };
    const Vec3 vp = params.viewpoint;
    switch (params.orientation) {
        case Orientation::kViewpoint:
            for (size_t i = 0; i < n; ++i) fix_toward(i, vp);
            rep.method = fmt::format("toward the viewpoint ({}, {}, {})", vp.x, vp.y, vp.z);
            break;
        case Orientation::kInward:
            for (size_t i = 0; i < n; ++i) fix_toward(i, c);
            rep.method = "toward the centroid (inward)";
            break;
        case Orientation::kOutward:
            for (size_t i = 0; i < n; ++i) fix_toward(i, 2.0f * pts[i] - c);
            rep.method = "away from the centroid (outward)";
            break;
        case Orientation::kAuto: {
            if (radii.empty()) {
                PointSet tmp;
                tmp.positions = pts;
                tmp.normals = normals;
                // Raw radii: the free-space grid's cell is one sample spacing, which duplicates
                // and the smoothing's averaging would shrink (docs/validation.md).
                RadiusEstimationParams rp;
                rp.smoothing_passes = 0;
                rp.sampling_correction = false;  // the grid's cell as measured for these rules
                estimate_radii(tmp, rp);
                radii = std::move(tmp.radii);
            }
            detail::SideVotes votes = detail::vote_sides(pts, normals, radii, fits.noise);
            const Graph g = symmetrise(fits, n);
            shape_votes(pts, g, fits.degenerate, normals, votes, fits.slack);
            for (size_t i = 0; i < n; ++i) {
                if (fits.degenerate[i] || votes.cue[i] == detail::SideCue::kNone) continue;
                if (votes.sign[i] < 0) normals[i] = -normals[i];
                fixed[i] = 1;
                ++(votes.cue[i] == detail::SideCue::kSpace  ? rep.by_space
                   : votes.cue[i] == detail::SideCue::kRays ? rep.by_rays
                   : votes.cue[i] == detail::SideCue::kView ? rep.by_view
                                                            : rep.by_shape);
            }
            rep.by_neighbours = agree_with_neighbours(pts, fits, votes, normals);
            rep.by_neighbours +=
                spread_votes(pts, radii, g, fits.degenerate, votes, fixed, normals, fits.slack);
            rep.method = votes.method;
            rep.scanner = votes.view;
            rep.scanners = votes.scanners;
            propagate(pts, centroid, g, fits.degenerate, fixed, normals, fits.slack);
            return;
        }
    }
    propagate(pts, centroid, symmetrise(fits, n), fits.degenerate, fixed, normals, fits.slack);
}

void check_cloud(const std::vector<Vec3>& pts, const NormalEstimationParams& params,
                 const char* source) {
    const size_t k = params.k;
    const size_t n = pts.size();
    if (n < 3) {
        throw Error(prefix(source) + "normal estimation needs at least 3 points, got " +
                    std::to_string(n));
    }
    if (k < kMinK || k > kMaxK) {
        throw Error(
            prefix(source) + "normal estimation: k (neighbours per plane fit) must be in [" +
            std::to_string(kMinK) + ", " + std::to_string(kMaxK) + "], got " + std::to_string(k));
    }
    if (params.fit_neighbours < kMinK || params.fit_neighbours > kMaxK) {
        throw Error(prefix(source) + "normal estimation: fit_neighbours must be in [" +
                    std::to_string(kMinK) + ", " + std::to_string(kMaxK) + "], got " +
                    std::to_string(params.fit_neighbours));
    }
    if (params.refits < 0 || params.refits > kMaxRefits) {
        throw Error(prefix(source) + "normal estimation: refits must be in [0, " +
                    std::to_string(kMaxRefits) + "], got " + std::to_string(params.refits));
    }
    if (n > size_t(std::numeric_limits<uint32_t>::max())) {
        throw Error(prefix(source) + "normal estimation supports at most " +
                    std::to_string(std::numeric_limits<uint32_t>::max()) + " points, got " +
                    std::to_string(n));
    }
    for (size_t i = 0; i < n; ++i) {
        if (!is_finite(pts[i])) {
            throw Error(prefix(source) + "point " + std::to_string(i) +
                        " has a non-finite coordinate; cannot estimate normals");
        }
    }
}

template <class T>
std::vector<T> permuted(const std::vector<T>& v, const std::vector<uint32_t>& order) {
    std::vector<T> out;
    if (v.empty()) return out;
    out.resize(order.size());
    for (size_t r = 0; r < order.size(); ++r) out[r] = v[order[r]];
    return out;
}

}  // namespace

void estimate_normals(PointSet& points, const NormalEstimationParams& params, const char* source,
                      OrientationReport* report) {
    const std::vector<Vec3>& pts = points.positions;
    const size_t n = pts.size();
    check_cloud(pts, params, source);
    const Dvec centroid = centroid_of(pts);
    check_not_degenerate(pts, centroid, source);

    const std::vector<uint32_t> order = spatial_order(pts);
    const std::vector<Vec3> sorted = permuted(pts, order);
    LocalFits fits = fit_local_planes(sorted, params);
    OrientationReport rep;
    rep.at_creases = fits.at_creases;
    if (params.orientation == Orientation::kAuto)
        orient_fits(sorted, centroid, fits, permuted(points.radii, order), params, rep);
    points.normals.resize(n);
    // Rules that sign each point by its position alone sign the sheet normals directly.
    if (params.orientation != Orientation::kAuto) {
        fits.normals = fits.sheet_normals;
        orient_fits(sorted, centroid, fits, {}, params, rep);
    }
    for (size_t r = 0; r < n; ++r) {
        const Vec3 sheet = fits.sheet_normals[r], smooth = fits.normals[r];
        points.normals[order[r]] =
            fits.degenerate[r] ? smooth : (dot(sheet, smooth) < 0 ? -sheet : sheet);
    }
    if (report) *report = rep;
}

void orient_normals(PointSet& points, const NormalEstimationParams& params, const char* source,
                    OrientationReport* report) {
    const std::vector<Vec3>& pts = points.positions;
    const size_t n = pts.size();
    if (points.normals.size() != n) {
        throw Error(prefix(source) + "orienting normals needs one per point (" +
                    std::to_string(points.normals.size()) + " for " + std::to_string(n) +
                    " points)");
    }
    check_cloud(pts, params, source);
    const std::vector<uint32_t> order = spatial_order(pts);
    const std::vector<Vec3> sorted = permuted(pts, order);
    LocalFits fits = fit_local_planes(sorted, params, false);
    fits.normals = permuted(points.normals, order);
    for (size_t r = 0; r < n; ++r) {
        const float len = length(fits.normals[r]);
        fits.degenerate[r] = !(len > 0 && std::isfinite(len));
        fits.normals[r] = unit_or(fits.normals[r], Vec3{0, 0, 1});
    }
    OrientationReport rep;
    orient_fits(sorted, centroid_of(pts), fits, permuted(points.radii, order), params, rep);
    for (size_t r = 0; r < n; ++r) {
        Vec3& out = points.normals[order[r]];
        out = fits.degenerate[r] ? fits.normals[r] : (dot(out, fits.normals[r]) < 0 ? -out : out);
    }
    if (report) *report = rep;
}

void orient_toward(PointSet& points, Vec3 viewpoint) {
    for (size_t i = 0; i < points.normals.size() && i < points.size(); ++i)
        if (dot(points.normals[i], viewpoint - points.positions[i]) < 0)
            points.normals[i] = -points.normals[i];
}

void orient_toward(PointSet& points, const std::vector<Vec3>& sensors, const char* source) {
    if (sensors.size() != points.size() || points.normals.size() != points.size()) {
        throw Error(prefix(source) + std::to_string(sensors.size()) + " sensor positions and " +
                    std::to_string(points.normals.size()) + " normals for " +
                    std::to_string(points.size()) + " points");
    }
    for (size_t i = 0; i < points.size(); ++i)
        if (dot(points.normals[i], sensors[i] - points.positions[i]) < 0)
            points.normals[i] = -points.normals[i];
}

// The jet z = a x^2 + b xy + c y^2 + d x + e y + f through the kept points (x, y, z), least
// squares; false when singular.
template <size_t K>
bool jet_through(const double (&xyz)[K][3], const bool (&keep)[K], double (&coef)[6]) {
    double a[6][6] = {};
    std::fill(coef, coef + 6, 0.0);
    for (size_t j = 0; j < K; ++j) {
        if (!keep[j]) continue;
        const double x = xyz[j][0], y = xyz[j][1];
        const double phi[6] = {x * x, x * y, y * y, x, y, 1.0};
        for (int r = 0; r < 6; ++r) {
            coef[r] += phi[r] * xyz[j][2];
            for (int c = 0; c < 6; ++c) a[r][c] += phi[r] * phi[c];
        }
    }
    return detail::solve_small(a, coef);
}
template <size_t K>
void jet_residuals(const double (&xyz)[K][3], const double (&c)[6], double (&res)[K]) {
    for (size_t j = 0; j < K; ++j) {
        const double x = xyz[j][0], y = xyz[j][1];
        res[j] =
            xyz[j][2] - (c[0] * x * x + c[1] * x * y + c[2] * y * y + c[3] * x + c[4] * y + c[5]);
    }
}

constexpr double kTwoSheetGap = 0.3;
constexpr double kHalfNoiseRatio = 0.96, kHalfShapeRatio = 0.8;
constexpr size_t kFirstPlane = 8;

// One probe of estimate_surface_noise: the noise's standard deviation along the normal at the
// point nb[0] (the query itself, at distance 0) from its kNoiseNeighbours nearest nb (squared
// distances d2), or nothing where no fit can be made.
// The jet (z = a x^2 + b xy + c y^2 + d x + e y + f over a plane's frame) through the
// neighbours, unweighted: with 6 unknowns, the residual's mean square over k - 6 degrees of
// freedom is the noise's variance along the normal. Two sheets in reach (the other face of a
// plate, a surface a spacing or two away) put the heights along the plane's normal in two
// clusters: the widest gap between the sorted heights is more than kTwoSheetGap of their range
// (Gaussian noise and a smooth curve leave a gap that wide at a few probes in a hundred, which
// the median does not feel). Then only the cluster of the point itself (its own sheet) is
// kept, its plane fitted again (the first, pulled by both sheets, tilts and smears them) and
// split again; the jet is fitted through what is left.
struct NoiseProbe {
    double whole, half;  // the residual's deviation through the sheet's K, its nearest K / 2
};
template <size_t K>
std::optional<NoiseProbe> probe_noise(const std::vector<Vec3>& pts, const uint32_t* nb,
                                      const float* d2) {
    if (!(d2[K - 1] > 0)) return std::nullopt;
    const double s = 1.0 / std::sqrt(double(d2[K - 1]));  // coordinates in neighbourhood radii
    double xyz[K][3];
    // The neighbours' coordinates in the frame of the plane through those kept (and among
    // them the first `first` only); false when they span no plane.
    auto frame = [&](const bool* keep, size_t first) {
        uint32_t idx[K];
        size_t c = 0;
        for (size_t j = 0; j < first; ++j)
            if (keep[j]) idx[c++] = nb[j];
        const std::optional<Vec3> nz = plane_normal(pts, idx, c);
        if (!nz) return false;
        const Vec3 ax = std::fabs(nz->x) <= std::fabs(nz->y) && std::fabs(nz->x) <= std::fabs(nz->z)
                            ? Vec3{1, 0, 0}
                        : std::fabs(nz->y) <= std::fabs(nz->z) ? Vec3{0, 1, 0}
                                                               : Vec3{0, 0, 1};
        Vec3 u = ax - *nz * dot(ax, *nz);
        u = u / length(u);
        const Vec3 v = cross(*nz, u);
        for (size_t j = 0; j < K; ++j) {
            const Vec3 d = pts[nb[j]] - pts[nb[0]];
            xyz[j][0] = s * dot(d, u), xyz[j][1] = s * dot(d, v), xyz[j][2] = s * dot(d, *nz);
        }
        return true;
    };
    // Keeps, of those kept, the point's own side of the widest gap between heights when it
    // is wider than kTwoSheetGap of their range; false when there is no such gap.
    auto split = [&](bool* keep, size_t& m) {
        double z[K];
        size_t c = 0;
        for (size_t j = 0; j < K; ++j)
            if (keep[j]) z[c++] = xyz[j][2];
        std::sort(z, z + c);
        double widest = 0, at = 0;
        for (size_t j = 1; j < c; ++j)
            if (z[j] - z[j - 1] > widest) widest = z[j] - z[j - 1], at = 0.5 * (z[j] + z[j - 1]);
        if (!(widest > kTwoSheetGap * (z[c - 1] - z[0]))) return false;
        const bool above = xyz[0][2] > at;
        m = 0;
        for (size_t j = 0; j < K; ++j) m += keep[j] = keep[j] && (xyz[j][2] > at) == above;
        return true;
    };
    bool keep[K];
    size_t m = K;
    // Two sheets seen in the frame of all the neighbours (both faces of a plate thinner than
    // the spacing: a thin slab) or of the nearest kFirstPlane (a sheet a spacing or two away:
    // through all, the two make a thick slab the plane tilts across). Then the point's own
    // sheet is fitted again, and split again if it still holds two.
    bool two = false;
    for (size_t first : {K, kFirstPlane}) {
        std::fill(keep, keep + K, true);
        m = K;
        if (!frame(keep, first)) continue;
        if ((two = split(keep, m))) break;
    }
    if (two) {
        for (int round = 0; round < 2; ++round) {
            if (m < K / 2 || !frame(keep, K)) return std::nullopt;
            if (!split(keep, m)) break;
        }
        if (m < K / 2) return std::nullopt;
    } else {
        std::fill(keep, keep + K, true);
        m = K;
        if (!frame(keep, K)) return std::nullopt;
    }
    // The jet through the point's sheet, then through the nearest half of it (the same frame):
    // noise reads the same through both, shape a jet cannot follow less through the half.
    auto sigma_of = [&](const bool* use, size_t count) -> std::optional<double> {
        bool u[K];
        std::copy(use, use + K, u);
        double coef[6], res[K];
        if (count < 9 || !jet_through(xyz, u, coef)) return std::nullopt;
        jet_residuals(xyz, coef, res);
        double ssr = 0;
        for (size_t j = 0; j < K; ++j)
            if (u[j]) ssr += res[j] * res[j];
        return std::sqrt(ssr / double(count - 6)) / s;
    };
    const std::optional<double> whole = sigma_of(keep, m);
    if (!whole) return std::nullopt;
    bool near[K];  // the nearest K / 2 of the point's sheet (nb is nearest first)
    size_t h = 0;
    for (size_t j = 0; j < K; ++j) {
        near[j] = keep[j] && h < K / 2;
        h += near[j];
    }
    const std::optional<double> half = sigma_of(near, h);
    if (!half) return std::nullopt;
    return NoiseProbe{*whole, *half};
}

namespace {

SurfaceNoise measure_surface_noise(const PointSet& points) {
    const std::vector<Vec3>& pts = points.positions;
    const size_t n = pts.size();
    SurfaceNoise out;
    if (n < kNoiseNeighbours + 1) return out;
    for (const Vec3& p : pts)
        if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) return out;
    const detail::CloudAdaptor adaptor{pts};
    const detail::KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16));
    // At most kNoiseProbes points, at a fixed stride: the same answer on every run.
    const size_t probes = std::min(n, kNoiseProbes), stride = n / probes;
    std::vector<double> sigma(probes, -1), sigma_half(probes, -1), spacing2(probes, -1);
    parallel_for_range<size_t>(probes, 64, [&](size_t chunk_begin, size_t chunk_end) {
        uint32_t nb[kNoiseNeighbours];
        float d2[kNoiseNeighbours];
        for (size_t k = chunk_begin; k < chunk_end; ++k) {
            const size_t i = k * stride;
            const float query[3] = {pts[i].x, pts[i].y, pts[i].z};
            if (tree.knnSearch(query, kNoiseNeighbours, nb, d2) < kNoiseNeighbours) continue;
            // The density as estimate_radii reads it (8 nearest, all of them): r^2 = mean of
            // d_j^2 / j, a spacing of sqrt(pi) r.
            double r2 = 0;
            for (size_t j = 1; j <= 8; ++j) r2 += double(d2[j]) / double(j);
            spacing2[k] = M_PI * r2 / 8;
            if (const std::optional<NoiseProbe> pr = probe_noise<kNoiseNeighbours>(pts, nb, d2))
                sigma[k] = pr->whole, sigma_half[k] = pr->half;
        }
    });
    auto median = [](std::vector<double> v) {
        std::erase_if(v, [](double x) { return !(x >= 0); });
        if (v.empty()) return 0.0;
        std::nth_element(v.begin(), v.begin() + ptrdiff_t(v.size() / 2), v.end());
        return v[v.size() / 2];
    };
    // Noise or shape: noise reads the same through the nearest half of a point's sheet (the
    // median residual there is kHalfNoiseRatio of the whole's: Gaussian noise on the bunny's
    // cloud at 0.05-0.5 spacings, 0.95-0.97), the shape a jet cannot follow (a mesh's facets, a
    // curve tighter than the spacing) less (0.53-0.76 on exact samples of eight meshes, whose
    // whole reads 0.02-0.07 spacings of "noise"). With both, whole^2 = n^2 + g^2 and half^2 =
    // a^2 n^2 + b^2 g^2 (a the noise's ratio, b at most kHalfShapeRatio): n^2 = (half^2 - b^2
    // whole^2) / (a^2 - b^2), which leaves shape alone at 0 and noise alone whole.
    const double whole = median(sigma), half = median(sigma_half);
    const double a2 = kHalfNoiseRatio * kHalfNoiseRatio, b2 = kHalfShapeRatio * kHalfShapeRatio;
    out.sigma =
        std::min(whole, std::sqrt(std::max(0.0, (half * half - b2 * whole * whole) / (a2 - b2))));
    out.spacing = std::sqrt(median(spacing2));
    return out;
}

}  // namespace

SurfaceNoise estimate_surface_noise(const PointSet& points) {
    // A pure function of the positions, which a raw cloud's build asks for several times (the
    // normals' fits, the radii, the disc floor's share, the input's report; about 0.05 s each
    // for 40,000 points): the last answers are kept, keyed by the positions' count and a 64-bit
    // hash of their bytes (a copy of them would hold a large cloud's memory for nothing).
    struct Memo {
        size_t n = 0;
        size_t hash = 0;
        SurfaceNoise noise;
    };
    static std::mutex mutex;
    static std::array<Memo, 2> memo;
    static size_t next = 0;
    const std::vector<Vec3>& pts = points.positions;
    const size_t n = pts.size();
    const size_t hash = std::hash<std::string_view>{}(
        std::string_view(reinterpret_cast<const char*>(pts.data()), n * sizeof(Vec3)));
    {
        const std::lock_guard<std::mutex> lock(mutex);
        for (const Memo& m : memo)
            if (n > 0 && m.n == n && m.hash == hash) return m.noise;
    }
    const SurfaceNoise out = measure_surface_noise(points);
    const std::lock_guard<std::mutex> lock(mutex);
    memo[next] = {n, hash, out};
    next = (next + 1) % memo.size();
    return out;
}

float roughness_of(const SurfaceNoise& noise) {
    if (!(noise.spacing > 0) || !(noise.sigma >= kNoiseFloor * noise.spacing)) return 0.f;
    return float(kRoughnessSigmas * noise.sigma);
}

}  // namespace vmap
