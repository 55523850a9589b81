// Host helpers of the radiosity solver (src/gi/gi.cpp) that tests use too: the node geometry and
// the plain-array view of the tree that gi_hier.h's walks read.
#pragma once

#include <vector>

#include "gi/gi_hier.h"
#include "vmap/visibility_map.h"

namespace vmap::detail {

// Per node: total area, area-weighted mean position and normal, half-diagonal, mean point area.
std::vector<NodeGeom> gi_node_geometry(const VisibilityMap& vm);

// The tree of `vm` with `geom` (per node), `area` (pi r^2) and `point_leaf` (each point's leaf
// node) as a GiTree; the arrays must outlive it.
GiTree gi_tree_view(const VisibilityMap& vm, const NodeGeom* geom, const float* area,
                    const int32_t* point_leaf);

}  // namespace vmap::detail
