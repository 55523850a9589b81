// The leaf-pair predicate's pieces (visibility/leaf_pair.h) asked on a backend: on the host, or
// in a kernel (predicate_cases.cu, built with CUDA) that runs the same VMAP_HD code, so the
// device's compiled predicate meets the expectations the host's does (visibility_test: Fig7,
// EndPlanes, Facing).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "visibility/leaf_pair.h"
#include "vmap/error.h"
#include "vmap/options.h"

namespace vmap::test {

enum class Predicate : uint8_t {
    kActualOccluder,
    kCountsAsOccluder,
    kLeavesFace,
    kInFrontOfEnds,
    kSlabRegular,
    kOccluderWeight
};

// One question about the segment from leaf a's centroid p along d (length len) to leaf b:
//   kActualOccluder    is_actual_occluder(p, d, len, x, vp)
//   kCountsAsOccluder  counts_as_occluder(pair_segment(a, b, vp), x, vp)
//   kLeavesFace        leaves_face(a, b, d, len, vp)
//   kInFrontOfEnds     in_front_of_ends(pair_segment(a, b, vp), x)
//   kSlabRegular       slab_meets_box_regular(slab_ray(p, d, t0, t1), box)
//   kOccluderWeight    occluder_weight(pair_segment(a, b, vp), x, vp) (0, 1 or K)
struct PredicateCase {
    Predicate what = Predicate::kActualOccluder;
    LeafDisc a, b, x;
    Vec3 p{0, 0, 0}, d{0, 0, 0};
    float len = 0;
    VisibilityParams vp;
    Box box{};
    float t0 = 0, t1 = 1;
};

VMAP_HD int answer(const PredicateCase& c) {
    switch (c.what) {
        case Predicate::kActualOccluder:
            return detail::is_actual_occluder(c.p, c.d, c.len, c.x, c.vp);
        case Predicate::kCountsAsOccluder:
            return detail::counts_as_occluder(detail::pair_segment(c.a, c.b, c.vp), c.x, c.vp);
        case Predicate::kLeavesFace:
            return detail::leaves_face(c.a, c.b, c.d, c.len, c.vp);
        case Predicate::kInFrontOfEnds:
            return detail::in_front_of_ends(detail::pair_segment(c.a, c.b, c.vp), c.x);
        case Predicate::kSlabRegular:
            return detail::slab_meets_box_regular(detail::slab_ray(c.p, c.d, c.t0, c.t1), c.box);
        case Predicate::kOccluderWeight:
            return detail::occluder_weight(detail::pair_segment(c.a, c.b, c.vp), c.x, c.vp);
    }
    return 0;
}

#ifdef VMAP_TEST_CUDA
// answer() of each case, in a kernel on CUDA device 0 (predicate_cases.cu).
std::vector<uint8_t> answers_on_cuda(std::span<const PredicateCase> cases);
#else
inline std::vector<uint8_t> answers_on_cuda(std::span<const PredicateCase>) {
    throw Error("this test was built without CUDA");
}
#endif

// answer() of each case on backend b (cpu or cuda), as a byte.
inline std::vector<uint8_t> answers_on(Backend b, std::span<const PredicateCase> cases) {
    if (b == Backend::kCuda) return answers_on_cuda(cases);
    std::vector<uint8_t> out;
    for (const PredicateCase& c : cases) out.push_back(uint8_t(answer(c)));
    return out;
}

}  // namespace vmap::test
