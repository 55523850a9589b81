// Input checks around build_vmap (src/vmap/build_checks.h).
#include "vmap/build_checks.h"

#include <fmt/format.h>

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
    const double opposed = normal_inconsistency(points);
    if (opposed > kInconsistent) {
        stats.warnings.push_back(fmt::format(
            "normals look inconsistent: {:.1f}% of neighbouring points on one surface have "
            "opposite normals (consistent normals give about 0%); re-estimate them (vmap build "
            "--normals estimate) or give the scanner position (--viewpoint)",
            100.0 * opposed));
    }
}

void check_facing(BuildStats& stats) {
    // Facing leaf pairs of all: those walked that faced, and those decided all visible at node
    // level (which face by the proof); pairs decided none visible did not.
    const WorkCounters& w = stats.work;
    uint64_t facing = w.facing_pairs, all = std::max(stats.leaf_pairs, w.pairs);
    for (const ConstructionLevel& l : stats.levels) facing += l.leaf_pairs_visible;
    if (all == 0 || double(facing) >= kFewFacing * double(all)) return;
    stats.warnings.push_back(fmt::format(
        "only {:.2f}% of leaf pairs face each other: the normals probably point away from the "
        "scene (a room's walls facing out?); try --normals flip, --normals inward or "
        "--viewpoint",
        100.0 * double(facing) / double(all)));
}

}  // namespace vmap::detail
