// What build_vmap checks and fills in about its input points before and after the build:
// missing splat radii, normals that look inconsistent, and leaf pairs that almost never face.
#pragma once

#include <tbb/task_group.h>

#include <string>

#include "vmap/visibility_map.h"

namespace vmap::detail {

// Below this share of facing leaf pairs the normals most likely point away from the scene.
constexpr double kFewFacing = 0.02;
// Above this share of neighbouring same-surface pairs with opposite normals, the normals look
// inconsistent (correct ones give about 0; independent random signs give 0.5).
constexpr double kInconsistent = 0.05;

// Estimates radii when points have none (estimate_radii), recorded in stats.warnings. Points
// without normals are left to the octree to reject.
void prepare_points(PointSet& points, BuildStats& stats, const std::string& source);

// The normals' consistency check (normal_inconsistency), which only warns, run beside the
// construction instead of before it: on a 300,000-point scene it builds two k-d trees one thread
// at a time (0.25 s of the dragon's 0.3 s octree step on 2 cores). start() runs the check as a
// task of the current arena on `points`, which must stay as they are, where they are, until
// finish(); finish() waits for it and records the warning, if any, in stats.warnings. Without
// start(), finish() does nothing.
class NormalsCheck {
  public:
    NormalsCheck() = default;
    NormalsCheck(const NormalsCheck&) = delete;
    NormalsCheck& operator=(const NormalsCheck&) = delete;
    ~NormalsCheck();
    void start(const PointSet& points);
    void finish(BuildStats& stats);

  private:
    tbb::task_group group_;
    double opposed_ = 0;
    bool started_ = false;
};

// Leaf pairs probed by flipped_facing_share.
constexpr int kFlipProbePairs = 1 << 16;

// The share of leaf pairs of t that would face each other with every normal flipped, estimated
// over kFlipProbePairs pairs drawn by a fixed sequence.
double flipped_facing_share(const Octree& t, const VisibilityParams& vp);

// Adds a warning when fewer than kFewFacing of the leaf pairs face each other: that the normals
// point away from each other (a room facing out, or a convex object seen from outside) where
// flipping them would make many more face, else that the surface is flat (nothing to see
// whichever way the normals point).
void check_facing(BuildStats& stats, const Octree& t, const VisibilityParams& vp);

}  // namespace vmap::detail
