// Normals and splat radii for raw point clouds: estimation, orientation, and a sanity check.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "vmap/mesh.h"

namespace vmap {

// How the signs of normals are chosen (docs/design.md, "Raw clouds: orientation").
enum class Orientation {
    kAuto,       // free space decides: the side of each surface that faces the free space
                 // (flood-filled voxels, nesting rule), rays where both sides are free
    kViewpoint,  // toward NormalEstimationParams::viewpoint (the scanner's position)
    kInward,     // toward the cloud's centroid
    kOutward,    // away from the cloud's centroid
};

struct NormalEstimationParams {
    size_t k = 12;  // neighbours linked for orientation (the spanning tree, the sign checks)
    // The plane fit (weighted PCA, src/scene/normals.cpp): this many nearest candidates, weighted
    // by distance on the scale of the local spacing (the 6th nearest's distance), then re-fitted
    // `refits` times on the candidates of the point's own sheet (normals within 37 degrees and
    // the chord between the points consistent with both tangent planes), which drops the other
    // face of a thin part or an edge and a surface a few millimetres away. 0: one weighted fit.
    size_t fit_neighbours = 24;
    int refits = 2;
    // Then a second-order height function (a jet) is fitted on the same sheet's candidates and
    // its normal at the point taken (src/scene/normals.cpp jet_pass): closer on curved parts and
    // on noisy samples than the plane (docs/validation.md "Jet fits"). false: the plane's.
    bool jet = true;
    // Then a point whose neighbourhood a quadric cannot follow (a crease: a CAD part's edge, a
    // box's corner) takes the plane through it that holds the most of its neighbours, of those
    // its neighbours' normals give (src/scene/normals.cpp crease_pass; noise-free clouds only).
    bool creases = true;
    Orientation orientation = Orientation::kAuto;
    Vec3 viewpoint{};  // for Orientation::kViewpoint
};

// What orientation did, for the build's report.
struct OrientationReport {
    std::string method;        // in words, e.g. "free space (room: walls face inward)"
    size_t by_space = 0;       // points whose side the voxel topology decided
    size_t by_rays = 0;        // points decided by casting rays (both sides free or unknown)
    size_t by_shape = 0;       // points of open sheets decided by the sheet's shape (both sides
                               // free: the side away from what the sheet wraps around)
    size_t by_view = 0;        // points signed toward where a scanner stood (a bare scan: the
                               // places its spacing tells, or inside a room the free place
                               // that sees the most points)
    std::vector<Vec3> scanners;   // the places the points' spacing tells, when it does
    std::optional<Vec3> scanner;  // the place that sees the most, in a scan from inside a room
    size_t by_neighbours = 0;  // voted points turned to agree with their surface (the
                               // neighbour check of ray votes, then the votes' spread)
    size_t at_creases = 0;     // points at a crease that took the plane through them that holds
                               // the most of their neighbours (NormalEstimationParams::creases)
};

// Fills points.normals: a local plane fit of the nearest neighbours (nanoflann k-d tree; see
// NormalEstimationParams::fit_neighbours) gives each normal, then orient_normals chooses the signs.
// Existing normals are replaced. Throws vmap::Error (naming `source`) when it cannot: fewer than 3
// points, all points collinear or coincident, or non-finite coordinates.
void estimate_normals(PointSet& points, const NormalEstimationParams& params = {},
                      const char* source = "point cloud", OrientationReport* report = nullptr);

// Chooses the sign of every existing normal (points.normals must be set; their axes are kept)
// by params.orientation. kAuto needs splat radii for its rays and estimates them into a copy
// when points.radii is empty. Throws vmap::Error naming `source` for missing normals.
void orient_normals(PointSet& points, const NormalEstimationParams& params = {},
                    const char* source = "point cloud", OrientationReport* report = nullptr);

// Orients every normal toward one viewpoint (e.g. a PCD VIEWPOINT or the scanner's origin):
// n . (viewpoint - p) >= 0 afterwards.
void orient_toward(PointSet& points, Vec3 viewpoint);

// Orients normal i toward sensors[i] (per-point sensor positions, e.g. PLY sensor_x/y/z).
// Throws vmap::Error naming `source` when the sizes differ.
void orient_toward(PointSet& points, const std::vector<Vec3>& sensors,
                   const char* source = "point cloud");

struct RadiusEstimationParams {
    size_t k = 8;            // same-sheet neighbours the density is read from
    size_t candidates = 32;  // nearest neighbours searched for them
    // Then r^2 diffuses over the same-surface neighbour graph for this many passes, keeping
    // its sum (src/scene/radii.cpp: the density varies slowly, one estimate scatters). 0: raw.
    int smoothing_passes = 8;
    // The radius from neighbour distances assumes independent samples (E d_j^2 = j / (pi rho));
    // evenly spaced ones (blue noise, a scanner's grid) put the nearest neighbours farther, and
    // the radius reads about 12% large. With this set (and k 8, candidates >= 32: the
    // close-neighbour test's own), the radii are scaled by even_sampling_radius_scale of the
    // cloud's close-neighbour share.
    bool sampling_correction = true;
};

// Fills points.radii with splat radii (scene units): the radius of the disc of area 1 / density,
// the density counted over the k nearest neighbours on the point's own sheet, i.e. all but those
// off its tangent plane with a normal of the same axis (the other face of a thin plate or part),
// then r^2 diffused over those neighbours for RadiusEstimationParams::smoothing_passes passes.
// A curved part's neighbours count (its normals turn), the other face of a plate does not.
// Then scaled for how evenly the cloud is sampled (RadiusEstimationParams::sampling_correction).
// Needs points.normals (their signs do not matter). Throws vmap::Error naming `source` for
// missing normals or fewer than 2 points.
void estimate_radii(PointSet& points, const RadiusEstimationParams& params = {},
                    const char* source = "point cloud");

// How clumped a cloud's sampling is: the share of points whose nearest neighbour on their own
// sheet lies within half the radius r of the disc of area 1 / density (r from the 8 nearest on
// that sheet, as estimate_radii reads it; duplicates left out; at most 100,000 points probed, at
// a fixed stride). Independent uniform samples (a Poisson process on the surface) give about
// kPoissonCloseShare: measured on 120,000 of them on a plane (tests/normals_test.cpp CloudFloor;
// 0.156-0.167 on the shipped scenes' uniform samples). With the true density it would be
// 1 - exp(-1/4) = 0.221; the radius read from 8 neighbours scatters and grows with the nearest
// one's distance, which lowers it. Blue-noise samples, a scanner's grid or a voxel-filtered
// cloud give near 0 (0.002-0.004 on the blue-noise scenes). Needs normals (their signs do not
// matter); clouds of fewer than 10 points, or without normals, count as Poisson.
inline constexpr double kPoissonCloseShare = 0.161;
double close_neighbour_share(const PointSet& points);

// The occluder disc floor (OctreeParams::delta_floor) for a cloud of unknown sampling: the
// floor exists to close the holes that independent samples leave between their discs, so a
// Poisson-like cloud gets OctreeParams::kDefaultDeltaFloor (2.25), an evenly sampled one
// kEvenDeltaFloor (2.0, as the blue-noise samples of scene files), and one in between the
// linear mix by close_neighbour_share / kPoissonCloseShare (docs/validation.md "Raw clouds:
// the disc floor from the sampling").
float cloud_delta_floor(const PointSet& points);
// The same from a close_neighbour_share already measured.
float delta_floor_of_share(double close_share);

// What estimate_radii multiplies its radii by for a cloud of this close-neighbour share:
// kEvenRadiusScale for evenly spaced samples (share 0), 1 for independent ones (share >=
// kPoissonCloseShare), linear in between. kEvenRadiusScale: the true radius over the estimate's
// median on blue-noise samples (1 / 1.118 on the shipped and test scenes' clouds; tests/
// normals_test.cpp Radii.EvenSamplesGetTheirTrueRadius).
inline constexpr double kEvenRadiusScale = 0.8945;
float even_sampling_radius_scale(double close_share);

// The fraction of neighbouring point pairs on one smooth surface (near each other's tangent
// plane, normals within ~35 degrees of one axis) whose normals point to opposite sides: about 0
// for consistent normals. Needs normals; 0 for fewer than 2 points. Read at most `max_probes`
// points, at a fixed stride (0: every point): a share, which 100,000 points' neighbours give to
// well under a tenth of a point.
double normal_inconsistency(const PointSet& points, size_t k = 8, size_t max_probes = 100000);

// A scan's surface noise (range noise, registration jitter): points scattered off the surface
// they sample. sigma is the median, over at most kNoiseProbes points at a fixed stride, of the
// residual of a second-order height function (a jet) fitted by least squares to each one's
// kNoiseNeighbours nearest (all of them: noise must not be filtered out by same-sheet tests),
// over its k - 6 degrees of freedom: the noise's standard deviation along the normal on a smooth
// surface, and about 0 for exact samples of smooth or flat surfaces (creases, thin parts and
// contacts, where the neighbours span two sheets, are a minority the median leaves out). Shape
// the jet cannot follow (a mesh's facets) is told from noise by reading the nearest half too:
// noise reads the same there, shape less (src/scene/normals.cpp).
// spacing: sqrt(pi) x the median splat radius from the 8 nearest (estimate_radii's rule, all
// neighbours). Both in the cloud's units; zero for fewer than kNoiseNeighbours + 1 points or
// non-finite coordinates. Measured in docs/validation.md "Noisy scans".
struct SurfaceNoise {
    double sigma = 0;
    double spacing = 0;
};
inline constexpr size_t kNoiseNeighbours = 24;
inline constexpr size_t kNoiseProbes = 20000;
SurfaceNoise estimate_surface_noise(const PointSet& points);

// The predicate's roughness for a cloud of this noise (VisibilityParams::roughness): the step
// that two points' noise along the normal reaches at three standard deviations (3 sqrt 2
// sigma), or 0 when sigma is below kNoiseFloor sample spacings (exact samples, whose jet
// residuals are rounding and the facets of a mesh: their V-maps stay as they were).
inline constexpr double kRoughnessSigmas = 4.2426;  // 3 sqrt(2)
inline constexpr double kNoiseFloor = 0.02;
float roughness_of(const SurfaceNoise& noise);

// The k-d tree over positions that normal and radius estimation search (nanoflann, leaf size
// 16), for tools that score what they estimate (bench/normals_accuracy.cpp). It refers to
// `positions`, which must outlive it and stay unchanged.
class NearestPoints {
  public:
    explicit NearestPoints(const std::vector<Vec3>& positions);
    ~NearestPoints();
    NearestPoints(const NearestPoints&) = delete;
    NearestPoints& operator=(const NearestPoints&) = delete;
    // The k nearest positions to q (fewer when there are fewer), nearest first: their indices
    // into idx[0..k) and squared distances into d2[0..k). Returns how many were found.
    size_t find(Vec3 q, size_t k, uint32_t* idx, float* d2) const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace vmap
