// The range checks of the parameter structs (one check() each; messages name the field).
#include <fmt/format.h>

#include <cmath>

#include "vmap/error.h"
#include "vmap/visibility_map.h"

namespace vmap {

void OctreeParams::check(const std::string& source) const {
    if (max_height < 1 || max_height > kHeightLimit)
        throw Error(fmt::format("{}: max_height {} out of range (1..{})", source, max_height,
                                kHeightLimit));
    if (leaf_points < 1 || leaf_points > kLeafPointsLimit)
        throw Error(fmt::format("{}: leaf_points {} out of range (1..{})", source, leaf_points,
                                kLeafPointsLimit));
    if (!(delta_floor >= 0 && delta_floor <= kDeltaFloorLimit))
        throw Error(fmt::format("{}: delta_floor {} out of range (0..{})", source, delta_floor,
                                kDeltaFloorLimit));
}

void VisibilityParams::check(const std::string& source) const {
    if (K < 1 || K > kKLimit)
        throw Error(fmt::format("{}: K {} out of range (1..{})", source, K, kKLimit));
    if (!(eps >= 0 && eps < kEpsLimit))
        throw Error(fmt::format("{}: eps {} out of range [0, {})", source, eps, kEpsLimit));
    if (!(facing_tol >= 0 && facing_tol < kTolLimit))
        throw Error(fmt::format("{}: facing_tol {} out of range [0, {})", source, facing_tol,
                                kTolLimit));
    if (!(parallel_tol >= 0 && parallel_tol < kTolLimit))
        throw Error(fmt::format("{}: parallel_tol {} out of range [0, {})", source, parallel_tol,
                                kTolLimit));
    if (!(end_window >= 0 && end_window <= kEndWindowLimit))
        throw Error(fmt::format("{}: end_window {} out of range [0, {}]", source, end_window,
                                kEndWindowLimit));
    if (!(roughness >= 0 && std::isfinite(roughness)))
        throw Error(fmt::format("{}: roughness {} out of range (finite, >= 0)", source, roughness));
    if (!(core >= 0 && core <= kCoreLimit))
        throw Error(fmt::format("{}: core {} out of range [0, {}]", source, core, kCoreLimit));
}

void BuildParams::check(const std::string& source) const {
    octree.check(source);
    visibility.check(source);
    if (max_level_pairs < 1)
        throw Error(fmt::format("{}: max_level_pairs must be at least 1", source));
    if (max_batch_pairs < 1024)
        throw Error(fmt::format("{}: max_batch_pairs {} is too small (>= 1024)", source,
                                max_batch_pairs));
    if (lanes < 0 || lanes > 16)
        throw Error(fmt::format("{}: lanes {} out of range (0 = the backend's choice, up to 16)",
                                source, lanes));
    if (threads < 0 || threads > 4096)
        throw Error(fmt::format("{}: threads {} out of range (0 = all cores, up to 4096)", source,
                                threads));
    if (occluders == OccluderSearch::kGridWalk && backend == Backend::kCuda)
        throw Error(fmt::format(
            "{}: backend cuda: the GPU does occluders boxes only (the grid walk runs on the "
            "CPU; use backend auto or cpu)",
            source));
}

}  // namespace vmap
