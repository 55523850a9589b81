// The range checks of the parameter structs (one check() each; messages name the field).
#include <fmt/format.h>

#include "vmap/error.h"
#include "vmap/visibility_map.h"

namespace vmap {

void OctreeParams::check(const std::string& source) const {
    if (max_height < 1 || max_height > 21)
        throw Error(fmt::format("{}: max_height {} out of range (1..21)", source, max_height));
    if (leaf_points < 1 || leaf_points > 1000000)
        throw Error(
            fmt::format("{}: leaf_points {} out of range (1..1000000)", source, leaf_points));
}

void VisibilityParams::check(const std::string& source) const {
    if (K < 1 || K > 1000) throw Error(fmt::format("{}: K {} out of range (1..1000)", source, K));
    if (!(eps >= 0 && eps < 0.5f))
        throw Error(fmt::format("{}: eps {} out of range [0, 0.5)", source, eps));
    if (!(facing_tol >= 0 && facing_tol < 1))
        throw Error(fmt::format("{}: facing_tol {} out of range [0, 1)", source, facing_tol));
    if (!(parallel_tol >= 0 && parallel_tol < 1))
        throw Error(fmt::format("{}: parallel_tol {} out of range [0, 1)", source, parallel_tol));
}

void BuildParams::check(const std::string& source) const {
    octree.check(source);
    visibility.check(source);
    if (max_level_pairs < 1)
        throw Error(fmt::format("{}: max_level_pairs must be at least 1", source));
    if (max_batch_pairs < 1024)
        throw Error(fmt::format("{}: max_batch_pairs {} is too small (>= 1024)", source,
                                max_batch_pairs));
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
