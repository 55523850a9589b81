// Shared by normal estimation, orientation and radii: a k-d tree over positions (nanoflann, the
// positions read in place) and the test for "the same surface side".
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <nanoflann.hpp>
#include <vector>

#include "vmap/vec.h"

namespace vmap::detail {

struct CloudAdaptor {
    const std::vector<Vec3>& pts;

    size_t kdtree_get_point_count() const { return pts.size(); }
    float kdtree_get_pt(uint32_t i, size_t dim) const {
        const Vec3& p = pts[i];
        return dim == 0 ? p.x : (dim == 1 ? p.y : p.z);
    }
    template <class Bbox>
    bool kdtree_get_bbox(Bbox&) const {
        return false;
    }
};

using KdTree =
    nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, CloudAdaptor>,
                                        CloudAdaptor, 3, uint32_t>;

// Is q, a neighbour of p, on p's side of the same surface? It must lie near p's tangent plane
// (within 0.25 of its distance, about 14 degrees: a curve of radius R keeps neighbours at
// distance d within d / 2R of it) and its normal must share p's axis within about 37 degrees
// (signs ignored). The other face of a plate thinner than the neighbour spacing fails the first
// test; the other wall at a room's edge fails the second. (Allowing more off the plane where
// the normals turn, to follow tight curves, let the other face of plates back in: their fitted
// normals tilt where the neighbourhood mixes both faces.)
// On a noisy cloud, `slack` (the roughness: the noise's reach off the plane, roughness_of in
// vmap/normals.h) is allowed off the plane besides; 0 for exact samples, as before.
inline bool same_surface(Vec3 p, Vec3 np, Vec3 q, Vec3 nq, float slack = 0) {
    const Vec3 d = q - p;
    const float off = std::max(0.0f, std::fabs(dot(np, d)) - slack);
    return off * off <= 0.0625f * length2(d) && std::fabs(dot(np, nq)) >= 0.8f;
}

}  // namespace vmap::detail
