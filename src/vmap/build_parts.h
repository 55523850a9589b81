// build_vmap in two parts, for a caller that builds the octree once and resolves several
// shares of the node pairs over it (the MPI build, src/mpi/share.cpp): build_vmap(points) gives
// what build_links(build_octree(points)) gives, with the same parameters.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "vmap/visibility_map.h"

namespace vmap::detail {

// The points prepared (radii, the normals' check: build_checks.h) and the octree built: a map
// with no links. stats gets the warnings and seconds_octree. Throws what build_vmap throws.
VisibilityMap build_octree(PointSet points, const BuildParams& params, BuildStats& stats,
                           const std::string& source);

// The construction over base's points and octree (build_octree's, with the same
// params.octree): build_vmap's map and stats, seconds_octree 0. With raw (and keep_links), the
// links are appended to *raw as made (each once, its ends in either order) and the map gets no
// link arrays: for a caller that sorts them its own way.
VisibilityMap build_links(VisibilityMap base, const BuildParams& params, BuildStats* stats,
                          const std::string& source,
                          std::vector<std::pair<int32_t, int32_t>>* raw = nullptr);

}  // namespace vmap::detail
