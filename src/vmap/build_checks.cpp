// Input checks around build_vmap (src/vmap/build_checks.h).
#include "vmap/build_checks.h"

#include <fmt/format.h>

#include <utility>

#include "octree/records.h"
#include "visibility/leaf_pair.h"
#include "vmap/normals.h"

namespace vmap::detail {

void prepare_points(PointSet& points, BuildStats& stats, const std::string& source) {
    const size_t n = points.size();
    if (n < 2 || points.normals.size() != n) return;
    if (!points.has_radii()) {
        estimate_radii(points, {}, source.c_str());
        stats.warnings.push_back(
            "no splat radii given: estimated from the spacing of same-surface neighbours");
    }
}

// Reached without finish() only when the build failed or was cancelled: the check's result is
// not wanted, so a task not yet started is skipped and a running one stops early (with one
// thread the task would otherwise run whole here, after the construction, before the error
// gets out).
NormalsCheck::~NormalsCheck() {
    try {
        if (started_) group_.cancel();
        group_.wait();
    } catch (...) {  // (a destructor must not throw; finish() reports the error when called)
    }
}

void NormalsCheck::start(const PointSet& points) {
    const size_t n = points.size();
    if (n < 2 || points.normals.size() != n) return;
    started_ = true;
    group_.run([this, &points] { opposed_ = normal_inconsistency(points); });
}

void NormalsCheck::finish(BuildStats& stats) {
    if (!std::exchange(started_, false)) return;
    group_.wait();
    if (opposed_ > kInconsistent) {
        stats.warnings.push_back(fmt::format(
            "normals look inconsistent: {:.1f}% of neighbouring points on one surface have "
            "opposite normals (consistent normals give about 0%); re-estimate them (vmap build "
            "--normals estimate) or give the scanner position (--viewpoint)",
            100.0 * opposed_));
    }
}

double flipped_facing_share(const Octree& t, const VisibilityParams& vp) {
    const std::vector<LeafDisc>& leaves = leaf_discs(t);
    const uint64_t n = leaves.size();
    if (n < 2) return 0;
    uint64_t x = 0x9e3779b97f4a7c15ull, tried = 0, facing = 0;
    auto next = [&] {  // a fixed sequence (64-bit LCG, high bits): the same share every run
        x = x * 6364136223846793005ull + 1442695040888963407ull;
        return (x >> 32) % n;
    };
    for (int i = 0; i < kFlipProbePairs; ++i) {
        const uint64_t a = next(), b = next();
        if (a == b) continue;
        LeafDisc la = leaves[a], lb = leaves[b];
        la.normal = la.normal * -1.f;
        lb.normal = lb.normal * -1.f;
        ++tried;
        facing += pair_faces(la, lb, vp);
    }
    return tried > 0 ? double(facing) / double(tried) : 0.0;
}

void check_facing(BuildStats& stats, const Octree& t, const VisibilityParams& vp) {
    // Facing leaf pairs of all: those walked that faced, and those decided all visible at node
    // level (which face by the proof); pairs decided none visible did not.
    const WorkCounters& w = stats.work;
    uint64_t facing = w.facing_pairs, all = std::max(stats.leaf_pairs, w.pairs);
    for (const ConstructionLevel& l : stats.levels) facing += l.leaf_pairs_visible;
    if (all == 0 || double(facing) >= kFewFacing * double(all)) return;
    const double share = double(facing) / double(all);
    // Flipped normals would face where these do not: the normals point away from each other,
    // which a room whose walls face out and a convex object seen from outside share (only the
    // user knows which it is). Where flipping would not help either, the points lie on a flat
    // surface (or an open one bent away from both sides), where flipping is the wrong advice.
    const double flipped = flipped_facing_share(t, vp);
    const char* why =
        flipped >= kFewFacing && flipped >= 4 * share
            ? "the normals point away from each other, as on a lone convex object seen from "
              "outside (where nothing sees anything) or on a room whose walls face out (then try "
              "--normals flip, --normals inward or --viewpoint)"
            : "the points lie on one flat surface (or on open ones turned away from each "
              "other), where nothing sees anything whichever way the normals point; if the "
              "scene is not such, check the normals";
    stats.warnings.push_back(fmt::format(
        "only {:.2f}% of leaf pairs face each other, and {:.2f}% would with every normal "
        "flipped: {}",
        100.0 * share, 100.0 * flipped, why));
}

}  // namespace vmap::detail
