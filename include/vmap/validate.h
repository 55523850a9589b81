// Ground truth for the V-map (`vmap validate`, docs/validation.md): for seeded random point pairs
// of a scene, the exact answer from the scene's triangles (both points face each other and no
// triangle blocks the segment: Embree occlusion rays) against the V-map's answer, per octree
// height. Also the practitioner's alternative, Embree rays along the leaf-centroid segments,
// timed next to the leaf-pair kernel.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "vmap/mesh.h"
#include "vmap/options.h"
#include "vmap/progress.h"
#include "vmap/scene.h"
#include "vmap/visibility.h"

namespace vmap {

// Truth against prediction for a set of pairs. "Visible" is the positive class: a false
// visible is a pair the V-map calls visible that is hidden (light leaks through walls).
struct Confusion {
    uint64_t true_visible = 0;   // truth visible, predicted visible
    uint64_t true_hidden = 0;    // truth hidden, predicted hidden
    uint64_t false_visible = 0;  // truth hidden, predicted visible
    uint64_t false_hidden = 0;   // truth visible, predicted hidden

    void add(bool truth, bool predicted) {
        if (truth)
            (predicted ? true_visible : false_hidden)++;
        else
            (predicted ? false_visible : true_hidden)++;
    }
    Confusion& operator+=(const Confusion& o) {
        true_visible += o.true_visible, true_hidden += o.true_hidden;
        false_visible += o.false_visible, false_hidden += o.false_hidden;
        return *this;
    }
    uint64_t total() const { return true_visible + true_hidden + false_visible + false_hidden; }
    // Fractions of total() (0 when empty).
    double agreement() const;
    double false_visible_rate() const;
    double false_hidden_rate() const;
};

struct ValidateParams {
    uint64_t points = 0;      // 0: the scene's own count
    std::string sampling;     // "uniform" or "blue-noise": the samples' pattern; "": the scene's
    uint64_t pairs = 200000;  // random point pairs (i != j), 1..1e9
    uint64_t pair_seed = 1;   // seed of the pair sample
    std::vector<int> heights{5, 6, 7, 8, 9, 10};  // octree max_height values, 1..21
    int leaf_points = 0;          // 0: the scene's octree.leaf_points, else the default
    VisibilityParams visibility;  // K, eps, tolerances of the predicate
    OccluderSearch occluders = OccluderSearch::kBoxes;
    Backend backend = Backend::kCpu;  // for the V-map build
    // "vmap": build the V-map and query it (the real thing). "direct": evaluate the leaf-pair
    // predicate on the sampled pairs' leaves only, with no V-map: the same answers (the V-map
    // stores the leaf-pair table exactly; tests/validate_test.cpp checks it), far faster, for
    // parameter sweeps.
    std::string predict = "vmap";
    // The Delta rule (the occluder disc radius of a leaf), direct mode only: Delta =
    // delta_scale * max(farthest point from the centroid, splat_floor * splat radius). The
    // octree's own rule is delta_scale 1 and its floor (src/octree/delta_rule.h); splat_floor < 0
    // means that floor.
    float delta_scale = 1.f;
    float splat_floor = -1.f;
    double bury_distance = 2e-3;  // of the room's largest extent (see buried_points)
    double ray_offset = 1e-4;     // truth rays skip this fraction of the room's largest extent at
                                  // both ends (so a ray does not hit the surface it starts on)
    // Leave the buried points out before sampling pairs: what not sampling covered surface
    // (the ceiling under the light, floor under a model) would give.
    bool drop_buried = false;
    // Eyes: `eyes` seeded points on the models (and as many uniform over all points), each
    // scored against every other point: where a user looks. 0: none.
    uint64_t eyes = 100;
    uint64_t eye_seed = 1;
    // The points the prediction is built from. "" : the scene's samples as they are (true
    // normals, splat radii from the sampling). "normals": the same points as a raw cloud with
    // their true normals and no radii; "bare": positions only (normals and radii estimated, as
    // for a scan). Either goes through load_point_cloud, as `vmap build cloud.ply` would.
    // "sensors" (with scan only): positions and each point's scanner position, as a scanner's
    // file holds them (normals estimated, then turned toward their scanner).
    std::string as_cloud;
    // With as_cloud: Gaussian noise of this many sample spacings (sqrt(pi) x the true splat
    // radius) per axis moves each point of the cloud the prediction is built from, as a
    // scanner's range noise would; the truth keeps the exact points on the surfaces. 0: none.
    double noise = 0;
    // Score a simulated scan (scan_scene) from this many scanner positions (seed scan_seed)
    // instead of the scene's samples: about `points` (or the scene's count) hits, through the
    // raw-cloud path as_cloud (default bare). 0: none.
    uint32_t scan = 0;
    uint64_t scan_seed = 1;
    // Raw clouds (as_cloud, cloud): the predicate's roughness from the cloud's measured noise
    // (estimate_surface_noise, roughness_of), as `vmap build` takes it; false: visibility's.
    bool measure_roughness = true;
    // A cloud file to score instead of the scene's samples (truth from the scene's triangles;
    // each point's true normal and model flag from the nearest point of a dense scene sample).
    std::string cloud;
    // Write the eyes of the first height to this .npz (docs/validation.md "Against hidden point
    // removal"): positions, normals, pred_normals (N x 3 float32), pred_radii (N float32),
    // on_model (N uint8), surface (N uint32: each point's scene surface, 0xffffffff none),
    // eyes_model, eyes_all (E uint32), truth_eyes_model, pred_eyes_model, truth_eyes_all,
    // pred_eyes_all (E x N uint8: truth 0/1; prediction 0 hidden, 1 visible, 2 same leaf as the
    // eye, which the figures leave out; the eye's own entry is 0 and 2), offset (the truth rays'
    // end offset, float64) and octree (max_height, height, leaves; int32). "": none.
    std::string dump_eyes;
    ProgressCallback progress;  // heights done (vmap/progress.h); false cancels

    // Throws vmap::Error naming `source` and the field for a value out of range.
    void check(const std::string& source) const;
};

// One octree height's outcome.
struct HeightResult {
    int max_height = 0;  // requested
    int height = 0;      // deepest leaf level reached
    int leaf_points = 0;
    int32_t leaves = 0;
    uint64_t links = 0;      // 0 in direct mode
    Confusion all;           // every pair whose points lie in different leaves
    Confusion facing;        // those of them whose points face each other (truth's facing test)
    Confusion live;          // those of them where neither point is buried (ValidationReport)
    Confusion model;         // the model-pair sample: one end on a model, the other anywhere
    Confusion eyes_model;    // eyes on the models against every point
    Confusion eyes_all;      // eyes uniform over the points against every point
    uint64_t same_leaf = 0;  // pairs sharing a leaf (the V-map says nothing of them)
    uint64_t same_leaf_visible = 0;  // ... of which truly visible
    double build_seconds = 0;        // octree (+ V-map in vmap mode)
    double predict_seconds = 0;      // queries (vmap) or leaf-pair evaluations (direct)
    WorkCounters work;               // of the V-map build (vmap) or the evaluations (direct)
    std::string backend;
};

struct ValidationReport {
    std::string scene, path;
    uint64_t points = 0, pairs = 0;
    uint64_t truth_facing = 0, truth_visible = 0;
    // Buried points: a triangle lies in front of the point within bury_distance along its
    // normal (ceiling under the light, floor under a model's base): hidden from almost
    // everything in truth, an artifact of sampling covered surface. Pairs with one are left
    // out of HeightResult::live.
    uint64_t buried_points = 0, live_pairs = 0;
    uint64_t dropped_points = 0;  // with drop_buried: points left out before sampling
    uint64_t model_points = 0;    // points on a model (a mesh of the scene, not the room)
    // The occluder discs' floor the octrees were built with: splat_floor when given, else the
    // scene's (scene_octree), or OctreeParams::kDefaultDeltaFloor for the raw-cloud modes.
    float delta_floor = 0;
    uint64_t model_pairs = 0;  // pairs of the model-pair sample (as many as `pairs`)
    uint64_t eyes = 0;         // eyes per set (0 when the scene has no model points)
    std::string source;        // what the prediction was built from, in words
    // Of the prediction's points: the fraction (by count) whose normal points to the side of the
    // true one, over all points and over model points (1 when the normals are the true ones).
    double normal_agreement = 1, normal_agreement_model = 1;
    double bury_distance = 0;
    uint64_t triangles = 0;
    double offset = 0;  // absolute ray offset, scene units
    double truth_seconds = 0;
    ValidateParams params;
    std::vector<HeightResult> rows;
};

// Runs the validation of one scene file. Throws vmap::Error naming the file or the field for a
// bad scene or parameters out of range (pairs, heights, leaf_points, K, tolerances, names).
ValidationReport validate_scene(const std::string& scene_path, const ValidateParams& params);

// The report as a Markdown section (a header, the settings, one table row per height for all
// pairs and for facing pairs), and as JSON text.
std::string validation_markdown(const ValidationReport& r);
std::string validation_json(const ValidationReport& r);

// ---- exact visibility from the triangles (Embree 3) ------------------------------------------

// An Embree scene of a scene's surfaces (every triangle, room and light included).
class ExactVisibility {
  public:
    // Throws vmap::Error (naming `source`) when Embree fails or there are no triangles.
    ExactVisibility(const std::vector<SceneSurface>& surfaces, const std::string& source);
    ~ExactVisibility();
    ExactVisibility(const ExactVisibility&) = delete;
    ExactVisibility& operator=(const ExactVisibility&) = delete;

    uint64_t triangles() const { return triangles_; }
    // Does a triangle cross segment a + t (b - a), t in [t0, t1]?
    bool occluded(Vec3 a, Vec3 b, float t0, float t1) const;
    // Truth for a point pair with normals: facing (n_a . (b - a) > 1e-6 |b - a| and likewise
    // at b: coplanar points on one wall do not face each other) and no triangle crossing the
    // segment more than `offset` (scene units) from either end. Pairs closer than 2 offset
    // that face each other are visible.
    bool visible(Vec3 a, Vec3 na, Vec3 b, Vec3 nb, float offset) const;
    // Occlusion of many segments, 16 rays a packet (rtcOccluded16), on all cores: out[k] for
    // segment from[k] -> to[k] over t in [t0, t1].
    void occluded_packets(const std::vector<Vec3>& from, const std::vector<Vec3>& to, float t0,
                          float t1, std::vector<uint8_t>& out) const;

    static bool facing(Vec3 a, Vec3 na, Vec3 b, Vec3 nb);

    // The nearest triangle along org + t dir, t in [t0, t1]: the index of its surface in the
    // list given to the constructor (-1: nothing hit), t, and the triangle's unit normal on the
    // side its winding makes outward.
    struct Hit {
        int32_t surface = -1;
        float t = 0;
        Vec3 normal;
    };
    Hit intersect(Vec3 org, Vec3 dir, float t0, float t1) const;

  private:
    void* device_ = nullptr;  // RTCDevice
    void* scene_ = nullptr;   // RTCScene
    uint64_t triangles_ = 0;
    std::vector<int32_t> surface_of_geometry_;  // Embree geometry id -> surface index
};

// Moves each position by Gaussian noise of `spacings` sample spacings per axis, point i's
// spacing being sqrt(pi) radii[i] (the side of a square of its disc's area): a scanner's range
// noise, the same for a seed on every machine (ValidateParams::noise, normals_accuracy --noise).
void add_surface_noise(std::vector<Vec3>& positions, const std::vector<float>& radii,
                       double spacings, uint64_t seed);

// ---- a simulated scan ------------------------------------------------------------------------

// What scanners standing in the scene record (src/validate/scan.cpp): each sweeps its beam over
// an equal-angle grid (elevation from nadir to zenith, azimuth all round, one angular step) and
// keeps the first triangle each beam hits.
struct ScanPoints {
    PointSet points;  // the hits: exact positions on the triangles, the normal of the side hit
                      // (the triangle's, turned toward the scanner), and a nominal splat radius
                      // sqrt(area / (pi * hits)) for all (the spacing an even sample would have)
    std::vector<Vec3> sensors;      // per point: the scanner that recorded it
    std::vector<uint32_t> surface;  // per point: its index into the scene's surfaces
    std::vector<Vec3> scanners;     // the scanners' positions
    double step = 0;                // the angular step, radians
};

// `scanners` seeded positions (1..64): in a room, on a tripod in its middle (15-85% of width and
// depth, 40-70% of height), the column below clear of every model's bounding box by 2% of the
// room; without a room, around the surfaces at 1.5 times their bounding box's diagonal. The step is
// chosen so that all scanners together record about `points` hits. Throws vmap::Error naming
// `source` for scanners out of range or points < 2, when no position is clear of the models,
// when the scanners would need over 4e9 beams (they see too little), or when fewer than 16
// points are hit (too few to estimate normals from).
ScanPoints scan_scene(const Scene& sc, const ExactVisibility& exact, uint32_t scanners,
                      uint64_t points, uint64_t seed, const std::string& source);

// ---- the practitioner's alternative: Embree rays for leaf-centroid segments -------------------

struct EmbreeTimingParams {
    uint64_t points = 0;  // 0: the scene's own
    int max_height = 8, leaf_points = 0;
    VisibilityParams visibility;
    uint64_t sample_pairs = 2000000;  // leaf pairs (a < b), seeded blocks of 8 x 32 (validate.cpp)
    int runs = 5;
};

struct Spread {
    double median = 0, lo = 0, hi = 0;
};

struct EmbreeTiming {
    std::string scene;
    uint64_t points = 0, triangles = 0;
    int height = 0, leaf_points = 0;
    int32_t leaves = 0;
    int threads = 0;
    uint64_t pairs = 0;   // sampled leaf pairs
    uint64_t facing = 0;  // of them facing (the ones that need a ray)
    uint64_t kernel_visible = 0, ray_visible = 0, agree = 0;
    WorkCounters kernel_work;  // one run of our kernel over the sample
    Spread kernel_s;           // our sphere-walk kernel: all sampled pairs
    Spread ray1_s;             // facing test + rtcOccluded1 per facing pair (TBB loop)
    Spread ray16_s;            // facing test + rtcOccluded16 packets of facing pairs
};

// Times, on all cores, the leaf-pair kernel and Embree rays over the same sampled leaf pairs of
// the scene's octree. Rays go from centroid a to centroid b over t in (eps, 1 - eps), the window
// where the kernel counts occluders; only facing pairs get a ray.
EmbreeTiming time_embree(const std::string& scene_path, const EmbreeTimingParams& p);
std::string embree_timing_markdown(const std::vector<EmbreeTiming>& rows);

}  // namespace vmap
