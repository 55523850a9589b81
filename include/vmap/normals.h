// Normal estimation for raw point clouds (no normals in the file).
#pragma once

#include <cstddef>

#include "vmap/mesh.h"

namespace vmap {

struct NormalEstimationParams {
    size_t k = 12;  // neighbours for the local plane fit (PCA)
};

// Fills points.normals: the local plane of the k nearest neighbours (nanoflann k-d tree) gives
// each normal, then normals are oriented consistently by propagation along a minimum spanning
// tree of the neighbour graph (Hoppe et al. 1992), each connected component seeded by its point
// farthest from the cloud's centre with its normal pointing away from that centre.
// Throws vmap::Error (naming `source`) when it cannot: fewer than 3 points, all points collinear
// or coincident, or non-finite coordinates.
void estimate_normals(PointSet& points, const NormalEstimationParams& params = {},
                      const char* source = "point cloud");

}  // namespace vmap
