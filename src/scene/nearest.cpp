// NearestPoints (vmap/normals.h): the estimators' k-d tree (scene/cloud_knn.h) behind the
// public header.
#include <nanoflann.hpp>

#include "scene/cloud_knn.h"
#include "vmap/normals.h"

namespace vmap {

struct NearestPoints::Impl {
    explicit Impl(const std::vector<Vec3>& positions)
        : adaptor{positions}, tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16)) {}
    detail::CloudAdaptor adaptor;
    detail::KdTree tree;
};

NearestPoints::NearestPoints(const std::vector<Vec3>& positions)
    : impl_(std::make_unique<Impl>(positions)) {}
NearestPoints::~NearestPoints() = default;

size_t NearestPoints::find(Vec3 q, size_t k, uint32_t* idx, float* d2) const {
    const float p[3] = {q.x, q.y, q.z};
    return impl_->tree.knnSearch(p, k, idx, d2);
}

}  // namespace vmap
