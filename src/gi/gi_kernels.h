// The per-bounce arithmetic of the radiosity solver, written once for the CPU (oneTBB loops)
// and the GPU (one thread per item): plain arrays in, no allocation, no exceptions. Each item
// sums its terms in one fixed order and the build forbids contraction into FMAs
// (-ffp-contract=off, --fmad=false), so both backends give bit-identical radiosity.
#pragma once

#include <cstdint>

#include "vmap/vec.h"

namespace vmap::detail {

// Elements are nodes [0, num_nodes) then points [num_nodes, num_nodes + num_points) (octree
// order). The interaction list is CSR by receiver element: sources src[row[e] .. row[e+1]) with
// form factors coef[...], sorted by source.
struct GiView {
    int32_t num_nodes = 0;
    uint32_t num_points = 0;
    const uint64_t* row = nullptr;          // per element + 1
    const uint32_t* src = nullptr;          // per interaction: source element
    const float* coef = nullptr;            // per interaction: F_rs
    const Vec3* emission = nullptr;         // per point
    const Vec3* albedo = nullptr;           // per point
    const float* area = nullptr;            // per point: pi r^2
    const int32_t* point_leaf = nullptr;    // per point: its leaf's node
    const int32_t* parent = nullptr;        // per node, -1 for the root
    const uint32_t* point_begin = nullptr;  // per node
    const uint32_t* point_end = nullptr;    // per node
    const float* inv_area = nullptr;        // per node: 1 / total area (0 for none)
    Vec3* B = nullptr;                      // per element: radiosity (nodes: area-weighted mean)
    Vec3* G = nullptr;                      // per element: gathered irradiance of the bounce
};

// Step 1: what element e gathers from its interaction list.
VMAP_HD void gi_gather(const GiView& v, uint64_t e) {
    Vec3 acc{0, 0, 0};
    for (uint64_t k = v.row[e]; k < v.row[e + 1]; ++k) {
        const float f = v.coef[k];
        const Vec3 b = v.B[v.src[k]];
        acc.x = acc.x + f * b.x;
        acc.y = acc.y + f * b.y;
        acc.z = acc.z + f * b.z;
    }
    v.G[e] = acc;
}

// Step 2: point i's irradiance is its own gather plus its ancestors' (leaf first, root last);
// B_i = E_i + rho_i * H_i per channel.
VMAP_HD void gi_point_update(const GiView& v, uint32_t i) {
    const uint64_t e = uint64_t(v.num_nodes) + i;
    Vec3 h = v.G[e];
    for (int32_t n = v.point_leaf[i]; n >= 0; n = v.parent[n]) h = h + v.G[n];
    const Vec3 E = v.emission[i], rho = v.albedo[i];
    v.B[e] = Vec3{E.x + rho.x * h.x, E.y + rho.y * h.y, E.z + rho.z * h.z};
}

// Step 3: node n's radiosity is the area-weighted mean of its points' (in point order).
VMAP_HD void gi_pull_up(const GiView& v, int32_t n) {
    Vec3 acc{0, 0, 0};
    const uint64_t base = uint64_t(v.num_nodes);
    for (uint32_t k = v.point_begin[n]; k < v.point_end[n]; ++k)
        acc = acc + v.B[base + k] * v.area[k];
    v.B[n] = acc * v.inv_area[n];
}

}  // namespace vmap::detail
