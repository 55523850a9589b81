// The occluder disc radius Delta of a leaf (docs/design.md "Leaf-pair visibility"): the distance from
// the centroid to its farthest point, but never below kDeltaSplatFloor times the largest splat
// radius of its points. The floor was chosen by measurement (docs/validation.md).
#pragma once

#include "vmap/octree.h"

namespace vmap::detail {

inline constexpr float kDeltaSplatFloor = OctreeParams::kDefaultDeltaFloor;  // vmap/octree.h

}  // namespace vmap::detail
