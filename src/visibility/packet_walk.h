// The leaf-pair walk of leaf_pair.h for up to W leaf pairs at once, on the CPU (issue 15): the
// host's counterpart of the GPU's packet kernel (cuda/cuda_backend.cu). The W segments of
// neighbouring leaf pairs form a thin bundle, so they walk the preorder array together: each
// node's box is tested against every lane's segment in one loop over the lanes (plain float
// arrays, which the compiler turns into SIMD; for 32 lanes on AVX-512, the same loop written
// with intrinsics, walk_zmm), the packet descends when any lane's own walk
// would, and a lane tests only the nodes on its own path (n >= resume[i]: it has not skipped
// past the node's subtree). So each lane makes exactly the tests of leaf_pair_visible, in the
// same order, with the same float operations (FMA contraction is off in the whole build): the
// same answer, node tests and occluder tests, from the same pieces (pair_segment's SlabRay,
// occluder_reached). What the packet saves is the per-node cost: one load and one branch for W
// lanes instead of an unpredictable branch per lane and node.
//
// slab_meets_box, lane by lane and branch free: the slab interval per axis is [min(ta, tb),
// max(ta, tb)] as there. leaf_pair.h handles a direction component below 1e-30 in magnitude
// apart (no inverse); a pair with one walks alone, through leaf_pair_visible itself, so the
// packet's loop has no such case. tests/visibility_test.cpp holds the packet to
// leaf_pair_visible on randomized trees, every pair, answers and counters.
//
// On AVX-512 the rest of a pair's work is in vectors too, with the float operations of
// leaf_pair.h in the same order (so the same bits): the facing test for 16 columns of a row
// (facing_mask, from the leaves by field, LeafColumns), the setup of 16 facing pairs' segments
// (load_faced: pair_segment), and a leaf's occluder test for the lanes that reach it
// (occluders_zmm: counts_as_occluder for a leaf with a plane; a flagged leaf goes lane by lane).
// On the default scene this took the CPU's user time from 24 s to about 14 s
// (docs/results.md, "The CPU walk in vectors"). On AVX2 the same pieces have 8-lane forms:
// walk_ymm, occluders_ymm, facing_row_ymm, load_ymm (docs/results.md "The CPU walk on a host
// without AVX-512").
#pragma once

#include <array>
#include <climits>
#include <cstdint>
#include <vector>

#include "octree/records.h"
#include "visibility/leaf_pair.h"
#include "visibility/node_pair.h"

// The packet loop compiled for AVX2 and AVX-512 too, chosen at run time (GCC on x86-64).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(__CUDACC__)
#define VMAP_PACKET_ISA 1
#else
#define VMAP_PACKET_ISA 0
#endif
#if VMAP_PACKET_ISA
#include <immintrin.h>
#endif

namespace vmap::detail {

// The leaves' centroids, normals and flags by field (structure of arrays): the facing test
// loads 16 consecutive leaves' fields as 16 lanes.
struct LeafColumns {
    std::vector<float> c[3], n[3];
    std::vector<uint32_t> flags;
    LeafColumns() = default;
    explicit LeafColumns(const OctreeView& t) {
        for (int k = 0; k < 3; ++k)
            c[k].resize(size_t(t.num_leaves)), n[k].resize(size_t(t.num_leaves));
        flags.resize(size_t(t.num_leaves));
        for (int32_t l = 0; l < t.num_leaves; ++l) {
            const LeafDisc& d = t.leaves[l];
            c[0][l] = d.centroid.x, c[1][l] = d.centroid.y, c[2][l] = d.centroid.z;
            n[0][l] = d.normal.x, n[1][l] = d.normal.y, n[2][l] = d.normal.z;
            flags[l] = d.flags;
        }
    }
};

#if VMAP_PACKET_ISA
#define VMAP_ZMM_TARGET __attribute__((target("avx512f,avx512vl,avx512bw,avx512dq")))
// _mm512_sqrt_ps through an all-lanes mask (GCC 12's unmasked forms start
// from _mm512_undefined_*, which -Wuninitialized reports).
VMAP_ZMM_TARGET inline __m512 sqrt_zmm(__m512 a) {
    return _mm512_mask_sqrt_ps(a, __mmask16(0xffff), a);
}
// The fields of the leaves idx[i], i < n <= 16 (zero past n), as 16 lanes each: f[0..2] the
// centroid, f[3] Delta, f[4..6] the normal, f[7] the flags' bits. A leaf is 8 floats, so lanes i
// and i + 8 are loaded into one register and the two 8 x 8 blocks transposed together (fewer
// micro-ops than 16 gathers).
VMAP_ZMM_TARGET inline void leaf_fields(const LeafDisc* leaves, const int32_t* idx, int n,
                                        __m512 f[8]) {
    static_assert(sizeof(LeafDisc) == 8 * sizeof(float), "a leaf is read as 8 floats");
    alignas(32) static const float zero[8] = {};
    const float* r[16];
    for (int i = 0; i < 16; ++i)
        r[i] = i < n ? reinterpret_cast<const float*>(leaves + idx[i]) : zero;
    __m512 z[8], t[8], u[8];
    const __mmask16 all = 0xffff;
    for (int i = 0; i < 8; ++i) {  // (masked forms: GCC 12's unmasked ones start undefined)
        z[i] = _mm512_maskz_loadu_ps(0x00ff, r[i]);
        const auto upper = reinterpret_cast<uintptr_t>(r[i + 8]) - 8 * sizeof(float);
        z[i] = _mm512_mask_loadu_ps(z[i], 0xff00, reinterpret_cast<const float*>(upper));
    }
    for (int i = 0; i < 8; i += 2) {
        t[i] = _mm512_mask_unpacklo_ps(z[i], all, z[i], z[i + 1]);
        t[i + 1] = _mm512_mask_unpackhi_ps(z[i], all, z[i], z[i + 1]);
    }
    for (int i = 0; i < 8; i += 4) {
        u[i] = _mm512_shuffle_ps(t[i], t[i + 2], _MM_SHUFFLE(1, 0, 1, 0));
        u[i + 1] = _mm512_shuffle_ps(t[i], t[i + 2], _MM_SHUFFLE(3, 2, 3, 2));
        u[i + 2] = _mm512_shuffle_ps(t[i + 1], t[i + 3], _MM_SHUFFLE(1, 0, 1, 0));
        u[i + 3] = _mm512_shuffle_ps(t[i + 1], t[i + 3], _MM_SHUFFLE(3, 2, 3, 2));
    }
    const __m512i lo = _mm512_setr_epi32(0, 1, 2, 3, 16, 17, 18, 19, 8, 9, 10, 11, 24, 25, 26, 27);
    const __m512i hi =
        _mm512_setr_epi32(4, 5, 6, 7, 20, 21, 22, 23, 12, 13, 14, 15, 28, 29, 30, 31);
    for (int k = 0; k < 4; ++k) {
        f[k] = _mm512_permutex2var_ps(u[k], lo, u[k + 4]);
        f[k + 4] = _mm512_permutex2var_ps(u[k], hi, u[k + 4]);
    }
}
// dot(a, b) as vec.h evaluates it: (a.x b.x + a.y b.y) + a.z b.z.
VMAP_ZMM_TARGET inline __m512 dot_zmm(__m512 ax, __m512 ay, __m512 az, __m512 bx, __m512 by,
                                      __m512 bz) {
    return _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(ax, bx), _mm512_mul_ps(ay, by)),
                         _mm512_mul_ps(az, bz));
}
// facing_mask's lanes on AVX-512: pair_faces' float operations on 16 columns at once (the same
// order; vsqrtps is IEEE like sqrtf; FMA contraction is off), so the same answers.
VMAP_ZMM_TARGET inline uint32_t facing_mask_zmm(const OctreeView& t, const LeafColumns& lc,
                                                int32_t a, int32_t b0, int n,
                                                const VisibilityParams& vp) {
    const __mmask16 m = __mmask16(n >= 16 ? 0xffff : (1u << n) - 1);
    const LeafDisc& la = t.leaves[a];
    const __m512 dx =
        _mm512_sub_ps(_mm512_maskz_loadu_ps(m, lc.c[0].data() + b0), _mm512_set1_ps(la.centroid.x));
    const __m512 dy =
        _mm512_sub_ps(_mm512_maskz_loadu_ps(m, lc.c[1].data() + b0), _mm512_set1_ps(la.centroid.y));
    const __m512 dz =
        _mm512_sub_ps(_mm512_maskz_loadu_ps(m, lc.c[2].data() + b0), _mm512_set1_ps(la.centroid.z));
    const __m512 len = sqrt_zmm(dot_zmm(dx, dy, dz, dx, dy, dz));
    const __m512 lim = _mm512_mul_ps(_mm512_set1_ps(vp.facing_tol), len);
    __mmask16 faces = m & _mm512_cmp_ps_mask(len, _mm512_setzero_ps(), _CMP_GT_OQ);
    if (!(la.flags & kLeafNormalDegenerate)) {
        const __m512 da = dot_zmm(_mm512_set1_ps(la.normal.x), _mm512_set1_ps(la.normal.y),
                                  _mm512_set1_ps(la.normal.z), dx, dy, dz);
        faces &= _mm512_cmp_ps_mask(da, lim, _CMP_GT_OQ);
    }
    const __m512 db = dot_zmm(_mm512_maskz_loadu_ps(m, lc.n[0].data() + b0),
                              _mm512_maskz_loadu_ps(m, lc.n[1].data() + b0),
                              _mm512_maskz_loadu_ps(m, lc.n[2].data() + b0), dx, dy, dz);
    const __m512 neg = _mm512_castsi512_ps(_mm512_xor_si512(
        _mm512_castps_si512(db), _mm512_set1_epi32(int(0x80000000u))));  // -db, exactly
    const __mmask16 flagged =
        _mm512_mask_test_epi32_mask(m, _mm512_maskz_loadu_epi32(m, lc.flags.data() + b0),
                                    _mm512_set1_epi32(int(kLeafNormalDegenerate)));
    faces &= flagged | _mm512_cmp_ps_mask(neg, lim, _CMP_GT_OQ);
    return faces;
}
// dot_zmm on AVX2: the same order of operations.
__attribute__((target("avx2"), always_inline)) inline __m256 dot_ymm(__m256 ax, __m256 ay,
                                                                     __m256 az, __m256 bx,
                                                                     __m256 by, __m256 bz) {
    return _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(ax, bx), _mm256_mul_ps(ay, by)),
                         _mm256_mul_ps(az, bz));
}
// leaf_fields on AVX2: the fields of the leaves idx[i], i < n <= 8 (zero past n), as 8 lanes
// each (f[0..2] the centroid, f[3] Delta, f[4..6] the normal, f[7] the flags' bits): one leaf a
// register, the 8 x 8 block transposed.
__attribute__((target("avx2"), always_inline)) inline void leaf_fields_ymm(const LeafDisc* leaves,
                                                                           const int32_t* idx,
                                                                           int n, __m256 f[8]) {
    static_assert(sizeof(LeafDisc) == 8 * sizeof(float), "a leaf is read as 8 floats");
    __m256 r[8], t[8], u[8];
    for (int i = 0; i < 8; ++i)
        r[i] = i < n ? _mm256_loadu_ps(reinterpret_cast<const float*>(leaves + idx[i]))
                     : _mm256_setzero_ps();
    for (int i = 0; i < 8; i += 2) {
        t[i] = _mm256_unpacklo_ps(r[i], r[i + 1]);
        t[i + 1] = _mm256_unpackhi_ps(r[i], r[i + 1]);
    }
    for (int i = 0; i < 8; i += 4) {
        u[i] = _mm256_shuffle_ps(t[i], t[i + 2], _MM_SHUFFLE(1, 0, 1, 0));
        u[i + 1] = _mm256_shuffle_ps(t[i], t[i + 2], _MM_SHUFFLE(3, 2, 3, 2));
        u[i + 2] = _mm256_shuffle_ps(t[i + 1], t[i + 3], _MM_SHUFFLE(1, 0, 1, 0));
        u[i + 3] = _mm256_shuffle_ps(t[i + 1], t[i + 3], _MM_SHUFFLE(3, 2, 3, 2));
    }
    for (int k = 0; k < 4; ++k) {
        f[k] = _mm256_permute2f128_ps(u[k], u[k + 4], 0x20);
        f[k + 4] = _mm256_permute2f128_ps(u[k], u[k + 4], 0x31);
    }
}
// facing_mask's lanes on AVX2 (hosts without AVX-512): pair_faces' float operations on 8
// columns b0 .. b0 + n - 1 (n <= 8) of row a, in the same order as facing_mask_zmm; vsqrtps is
// IEEE like sqrtf, so the same answers. Masked loads read no column past n.
__attribute__((target("avx2"))) inline uint32_t facing_row_ymm(const OctreeView& t,
                                                               const LeafColumns& lc, int32_t a,
                                                               int32_t b0, int n,
                                                               const VisibilityParams& vp) {
    const uint32_t m = n >= 8 ? 0xffu : (1u << n) - 1;
    const __m256i lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    const __m256i mv = _mm256_cmpgt_epi32(_mm256_set1_epi32(n), lanes);
    const LeafDisc& la = t.leaves[a];
    const __m256 dx = _mm256_sub_ps(_mm256_maskload_ps(lc.c[0].data() + b0, mv),
                                    _mm256_set1_ps(la.centroid.x));
    const __m256 dy = _mm256_sub_ps(_mm256_maskload_ps(lc.c[1].data() + b0, mv),
                                    _mm256_set1_ps(la.centroid.y));
    const __m256 dz = _mm256_sub_ps(_mm256_maskload_ps(lc.c[2].data() + b0, mv),
                                    _mm256_set1_ps(la.centroid.z));
    const __m256 len = _mm256_sqrt_ps(dot_ymm(dx, dy, dz, dx, dy, dz));
    const __m256 lim = _mm256_mul_ps(_mm256_set1_ps(vp.facing_tol), len);
    uint32_t faces = m & uint32_t(_mm256_movemask_ps(_mm256_cmp_ps(len, _mm256_setzero_ps(), _CMP_GT_OQ)));
    if (!(la.flags & kLeafNormalDegenerate)) {
        const __m256 da = dot_ymm(_mm256_set1_ps(la.normal.x), _mm256_set1_ps(la.normal.y),
                               _mm256_set1_ps(la.normal.z), dx, dy, dz);
        faces &= uint32_t(_mm256_movemask_ps(_mm256_cmp_ps(da, lim, _CMP_GT_OQ)));
    }
    const __m256 db = dot_ymm(_mm256_maskload_ps(lc.n[0].data() + b0, mv),
                           _mm256_maskload_ps(lc.n[1].data() + b0, mv),
                           _mm256_maskload_ps(lc.n[2].data() + b0, mv), dx, dy, dz);
    const __m256 neg = _mm256_xor_ps(db, _mm256_castsi256_ps(_mm256_set1_epi32(int(0x80000000u))));
    const __m256i fl = _mm256_maskload_epi32(
        reinterpret_cast<const int*>(lc.flags.data() + b0), mv);
    const uint32_t flagged = uint32_t(_mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(
                                 _mm256_and_si256(fl, _mm256_set1_epi32(int(kLeafNormalDegenerate))),
                                 _mm256_set1_epi32(int(kLeafNormalDegenerate)))))) & m;
    faces &= flagged | uint32_t(_mm256_movemask_ps(_mm256_cmp_ps(neg, lim, _CMP_GT_OQ)));
    return faces;
}
inline bool has_avx2() {
    static const bool y = [] {
        __builtin_cpu_init();
        return __builtin_cpu_supports("avx2") != 0;
    }();
    return y;
}
#endif

#if VMAP_PACKET_ISA
// facing_mask for two rows at once, n <= 8 columns: lanes 0-7 row a0, lanes 8-15 row a1.
VMAP_ZMM_TARGET inline uint32_t facing_rows_zmm(const OctreeView& t, const LeafColumns& lc,
                                                int32_t a0, int32_t a1, int32_t b0, int n,
                                                const VisibilityParams& vp) {
    const __mmask8 m8 = __mmask8((1u << n) - 1);
    const __mmask16 m = __mmask16(m8 | (uint32_t(m8) << 8));
    const __mmask16 upper = 0xff00;
    const LeafDisc &l0 = t.leaves[a0], &l1 = t.leaves[a1];
    auto col = [&](const std::vector<float>& v) { return v.data() + b0; };
    const __m512 dx = _mm512_sub_ps(_mm512_maskz_broadcast_f32x8(0xffff, _mm256_maskz_loadu_ps(m8, col(lc.c[0]))),
                                    _mm512_mask_blend_ps(upper, _mm512_set1_ps(l0.centroid.x),
                                                         _mm512_set1_ps(l1.centroid.x)));
    const __m512 dy = _mm512_sub_ps(_mm512_maskz_broadcast_f32x8(0xffff, _mm256_maskz_loadu_ps(m8, col(lc.c[1]))),
                                    _mm512_mask_blend_ps(upper, _mm512_set1_ps(l0.centroid.y),
                                                         _mm512_set1_ps(l1.centroid.y)));
    const __m512 dz = _mm512_sub_ps(_mm512_maskz_broadcast_f32x8(0xffff, _mm256_maskz_loadu_ps(m8, col(lc.c[2]))),
                                    _mm512_mask_blend_ps(upper, _mm512_set1_ps(l0.centroid.z),
                                                         _mm512_set1_ps(l1.centroid.z)));
    const __m512 len = sqrt_zmm(dot_zmm(dx, dy, dz, dx, dy, dz));
    const __m512 lim = _mm512_mul_ps(_mm512_set1_ps(vp.facing_tol), len);
    __mmask16 faces = m & _mm512_cmp_ps_mask(len, _mm512_setzero_ps(), _CMP_GT_OQ);
    const __m512 da = dot_zmm(
        _mm512_mask_blend_ps(upper, _mm512_set1_ps(l0.normal.x), _mm512_set1_ps(l1.normal.x)),
        _mm512_mask_blend_ps(upper, _mm512_set1_ps(l0.normal.y), _mm512_set1_ps(l1.normal.y)),
        _mm512_mask_blend_ps(upper, _mm512_set1_ps(l0.normal.z), _mm512_set1_ps(l1.normal.z)), dx,
        dy, dz);
    const __mmask16 row_flagged = __mmask16((l0.flags & kLeafNormalDegenerate ? 0x00ffu : 0u) |
                                            (l1.flags & kLeafNormalDegenerate ? 0xff00u : 0u));
    faces &= row_flagged | _mm512_cmp_ps_mask(da, lim, _CMP_GT_OQ);
    const __m512 db = dot_zmm(_mm512_maskz_broadcast_f32x8(0xffff, _mm256_maskz_loadu_ps(m8, col(lc.n[0]))),
                              _mm512_maskz_broadcast_f32x8(0xffff, _mm256_maskz_loadu_ps(m8, col(lc.n[1]))),
                              _mm512_maskz_broadcast_f32x8(0xffff, _mm256_maskz_loadu_ps(m8, col(lc.n[2]))), dx,
                              dy, dz);
    const __m512 neg = _mm512_castsi512_ps(_mm512_xor_si512(
        _mm512_castps_si512(db), _mm512_set1_epi32(int(0x80000000u))));  // -db, exactly
    const __m512i flags =
        _mm512_maskz_broadcast_i32x8(0xffff, _mm256_maskz_loadu_epi32(m8, lc.flags.data() + b0));
    const __mmask16 flagged =
        _mm512_mask_test_epi32_mask(m, flags, _mm512_set1_epi32(int(kLeafNormalDegenerate)));
    faces &= flagged | _mm512_cmp_ps_mask(neg, lim, _CMP_GT_OQ);
    return faces;
}
#endif

// facing_mask for rows a0 and a1 and columns b0 .. b0 + n - 1, n <= 8: bits 0-7 for row a0,
// bits 8-15 for row a1.
inline uint32_t facing_rows(const OctreeView& t, const LeafColumns& lc, int32_t a0, int32_t a1,
                            int32_t b0, int n, const VisibilityParams& vp);

// The columns b0 + i, i < n <= 16, whose leaf pair (a, b0 + i) faces (pair_faces), as a mask.
// `lc`: the leaves of t by field.
inline uint32_t facing_mask(const OctreeView& t, const LeafColumns& lc, int32_t a, int32_t b0,
                            int n, const VisibilityParams& vp) {
#if VMAP_PACKET_ISA
    static const bool zmm = [] {
        __builtin_cpu_init();
        return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
               __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq");
    }();
    if (zmm) return facing_mask_zmm(t, lc, a, b0, n, vp);
    if (has_avx2())
        return facing_row_ymm(t, lc, a, b0, n < 8 ? n : 8, vp) |
               (n > 8 ? facing_row_ymm(t, lc, a, b0 + 8, n - 8, vp) << 8 : 0u);
#else
    (void)lc;
#endif
    uint32_t m = 0;
    for (int i = 0; i < n; ++i) m |= uint32_t(pair_faces(t.leaves[a], t.leaves[b0 + i], vp)) << i;
    return m;
}

// shaft_walk_nodes' list (node_pair.h) with walk_shaft's box test and flat-end rule alone,
// without its plane and disc tests: every node walk_shaft enters passes the tests kept here, so
// this list holds that one (and both are ancestor-closed tops of the tree, in preorder), and
// every leaf pair under (A, B) gets the answer of the whole walk through it as through that one
// (node_pair.h: walk_shaft prunes only nodes that hold no actual occluder of such a pair, e4).
// The plane and disc tests (square roots, divisions, in double) cost most of a shaft walk's
// time and leave few nodes out of these lists. `orig` is scratch.
// `pads`, when given, holds per node its bounds' pad and whether it has a flagged leaf below
// (node_pads), read instead of the whole bounds.
struct NodePad {
    float pad = 0;
    int32_t ndeg = 0;
};
inline std::vector<NodePad> node_pads(const NodePairContext& c) {
    std::vector<NodePad> p(size_t(c.tree.num_nodes));
    for (int32_t n = 0; n < c.tree.num_nodes; ++n) {
        const NodeBounds x = bounds_at(c, n);
        p[size_t(n)] = {x.pad, x.ndeg};
    }
    return p;
}
inline void box_walk_nodes(const NodePairContext& c, int32_t A, int32_t B,
                           std::vector<WalkNode>& out, std::vector<int32_t>& orig,
                           const NodePad* pads = nullptr) {
    out.clear();
    orig.clear();
    bool flat_a, flat_b;
    flat_ends(c, A, B, &flat_a, &flat_b);
    const Shaft s = pair_shaft(c, A, B);
    const double E = c.margin;
    const bool a_leaf = c.tree.walk[A].leaf >= 0, b_leaf = c.tree.walk[B].leaf >= 0;
    for (int32_t n = 0; n < c.tree.num_nodes;) {
        const WalkNode w = c.tree.walk[n];
        const bool in_a = n >= A && n < c.skip[A], in_b = n >= B && n < c.skip[B];
        const NodePad x = pads ? pads[n] : NodePad{bounds_at(c, n).pad, bounds_at(c, n).ndeg};
        if (!shaft_meets_box(s, w.lo, w.hi, E + x.pad) ||
            (in_a && (a_leaf || (flat_a && x.ndeg == 0))) ||
            (in_b && (b_leaf || (flat_b && x.ndeg == 0)))) {
            n = w.skip;
            continue;
        }
        out.push_back(w);
        orig.push_back(n);
        ++n;
    }
    list_skips(out, orig);  // the skips remapped to the list (node_pair.h)
}

inline uint32_t facing_rows(const OctreeView& t, const LeafColumns& lc, int32_t a0, int32_t a1,
                            int32_t b0, int n, const VisibilityParams& vp) {
#if VMAP_PACKET_ISA
    static const bool zmm = [] {
        __builtin_cpu_init();
        return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
               __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq");
    }();
    if (zmm) return facing_rows_zmm(t, lc, a0, a1, b0, n, vp);
    if (has_avx2())
        return facing_row_ymm(t, lc, a0, b0, n, vp) | facing_row_ymm(t, lc, a1, b0, n, vp) << 8;
#endif
    return facing_mask(t, lc, a0, b0, n, vp) | facing_mask(t, lc, a1, b0, n, vp) << 8;
}

template <int W>
class SegmentPacket {
    static_assert(W >= 1 && W <= 32, "a packet's lanes are the bits of one word");

  public:
    // Takes the leaf pairs (a[k], b[k]), k < count, a[k] != b[k], that face each other
    // (pair_faces) as its lanes. Returns whether there are any (a walk to make). `faced`: the
    // caller has kept only pairs that face (pair_faces is not evaluated again).
    template <class Counters>
    uint32_t load(const OctreeView& t, const int32_t* a, const int32_t* b, int count,
                  const VisibilityParams& vp, Counters* wc, bool faced = false) {
        live_ = alone_ = no_plane_a_ = no_plane_b_ = 0;
        roughness_ = vp.roughness;
        int n = 0;  // the lanes to walk, packed
        for (int k = 0; k < count; ++k) {
            const LeafDisc& la = t.leaves[a[k]];
            const LeafDisc& lb = t.leaves[b[k]];
            if (!faced && !pair_faces(la, lb, vp)) continue;
            lane_[n] = k;
            a_[n] = a[k], b_[n] = b[k];
            const PairSegment sg = pair_segment(la, lb, vp, true);
            const SlabRay& r = sg.ray;
            const bool small =
                fabsf(r.d.x) < 1e-30f || fabsf(r.d.y) < 1e-30f || fabsf(r.d.z) < 1e-30f;
            live_ |= uint32_t(!small) << n;
            alone_ |= uint32_t(small) << n;
            resume_[n] = small ? INT_MAX : 0;  // a lane not in the packet is past all
            occluders_[n] = 0;
            p_[0][n] = r.p.x, p_[1][n] = r.p.y, p_[2][n] = r.p.z;
            inv_[0][n] = r.inv.x, inv_[1][n] = r.inv.y, inv_[2][n] = r.inv.z;
            t0_[n] = r.t0, t1_[n] = r.t1;
            d_[0][n] = sg.d.x, d_[1][n] = sg.d.y, d_[2][n] = sg.d.z;
            q_[0][n] = sg.q.x, q_[1][n] = sg.q.y, q_[2][n] = sg.q.z;
            na_[0][n] = sg.na.x, na_[1][n] = sg.na.y, na_[2][n] = sg.na.z;
            nb_[0][n] = sg.nb.x, nb_[1][n] = sg.nb.y, nb_[2][n] = sg.nb.z;
            len_[n] = sg.len;
            delta_a_[n] = sg.delta_a, delta_b_[n] = sg.delta_b;
            win_a_[n] = sg.window_a, win_b_[n] = sg.window_b;
            no_plane_a_ |= uint32_t(!sg.plane_a) << n;
            no_plane_b_ |= uint32_t(!sg.plane_b) << n;
            ++n;
        }
        pad(n);
        wc->facing_pairs += uint64_t(__builtin_popcount(live_));
        return n > 0;
    }
    // load(t, a, b, count, vp, wc, true) (every pair faces), for 16 lanes at a time where the
    // CPU has AVX-512: pair_segment's float operations on every lane (vsqrtps and vdivps are
    // IEEE like sqrtf and /, FMA contraction is off), so the same bits.
    template <class Counters>
    uint32_t load_faced(const OctreeView& t, const int32_t* a, const int32_t* b, int count,
                        const VisibilityParams& vp, Counters* wc) {
        static const int isa = best_isa();
        return load_faced(t, a, b, count, vp, wc, isa);
    }
    // `isa` as for walk: 0 the scalar load, 1 AVX2 (load_ymm), 2 AVX-512 (load_zmm), at most
    // best_isa().
    template <class Counters>
    uint32_t load_faced(const OctreeView& t, const int32_t* a, const int32_t* b, int count,
                        const VisibilityParams& vp, Counters* wc, int isa) {
        (void)isa;
#if VMAP_PACKET_ISA
        if (isa == 2 && W == 32) {
            load_zmm(t, a, b, count, vp);
            wc->facing_pairs += uint64_t(__builtin_popcount(live_));
            return count > 0;
        }
        if (isa == 1 && W % 8 == 0) {
            load_ymm(t, a, b, count, vp);
            wc->facing_pairs += uint64_t(__builtin_popcount(live_));
            return count > 0;
        }
#endif
        return load(t, a, b, count, vp, wc, true);
    }

    // Walks `t` (the whole preorder array or a job's shaft list, as leaf_pair_visible would)
    // with the lanes loaded; returns the mask of visible lanes. `isa`: the lane loop's code,
    // 0 (the build's own, SSE2 on x86-64), 1 (AVX2), 2 (AVX-512), at most best_isa().
    template <class Counters>
    uint32_t walk(const OctreeView& t, const VisibilityParams& vp, Counters* wc) {
        static const int isa = best_isa();
        return walk(t, vp, wc, isa);
    }
    template <class Counters>
    uint32_t walk(const OctreeView& t, const VisibilityParams& vp, Counters* wc, int isa) {
        const int live = __builtin_popcount(live_);
        int64_t tests = 0;
        if (live > 0) {
#if VMAP_PACKET_ISA
            if (isa == 2)
                tests = walk_avx512(t, vp, live, wc);
            else if (isa == 1)
                tests = walk_avx2(t, vp, live, wc);
            else
#endif
                tests = walk_nodes(t, vp, live, wc);
        }
        (void)isa;
        wc->node_tests += uint64_t(tests);
        for (uint32_t m = alone_; m; m &= m - 1) {
            const int i = __builtin_ctz(m);
            if (leaf_pair_visible<true>(t, a_[i], b_[i], vp, wc)) live_ |= 1u << i;
        }
        uint32_t visible = 0;  // by the pairs' places in the packet
        for (uint32_t m = live_; m; m &= m - 1) visible |= 1u << lane_[__builtin_ctz(m)];
        return visible;
    }
    // The widest lane loop this CPU runs.
    static int best_isa() {
#if VMAP_PACKET_ISA
        __builtin_cpu_init();
        if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
            __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq"))
            return 2;
        return __builtin_cpu_supports("avx2") ? 1 : 0;
#else
        return 0;
#endif
    }

  private:
    // Lanes n..W-1 hold no pair: past every node (finite slabs, no NaN).
    void pad(int n) {
        for (int i = n; i < W; ++i) pad_lane(i);
    }
    // Lane i's PairSegment, from the lanes' arrays (the scalar occluder test).
    PairSegment segment(int i) const {
        PairSegment s;
        s.p = {p_[0][i], p_[1][i], p_[2][i]};
        s.d = {d_[0][i], d_[1][i], d_[2][i]};
        s.len = len_[i];
        s.faces = true;
        s.ray = SlabRay{s.p, {inv_[0][i], inv_[1][i], inv_[2][i]}, s.d, t0_[i], t1_[i]};
        s.q = {q_[0][i], q_[1][i], q_[2][i]};
        s.na = {na_[0][i], na_[1][i], na_[2][i]};
        s.nb = {nb_[0][i], nb_[1][i], nb_[2][i]};
        s.plane_a = !(no_plane_a_ >> i & 1u);
        s.plane_b = !(no_plane_b_ >> i & 1u);
        s.delta_a = delta_a_[i], s.delta_b = delta_b_[i];
        s.window_a = win_a_[i], s.window_b = win_b_[i];
        s.roughness = roughness_;
        return s;
    }
#if VMAP_PACKET_ISA
    // load's lanes for pairs that all face, 16 at a time: the leaves' fields gathered (a
    // LeafDisc is 8 floats), then pair_segment (faces = true, so len > 0) written out.
    __attribute__((target("avx512f,avx512vl,avx512bw,avx512dq"), noinline)) void load_zmm(
        const OctreeView& t, const int32_t* a, const int32_t* b, int count,
        const VisibilityParams& vp) {
        live_ = alone_ = no_plane_a_ = no_plane_b_ = 0;
        roughness_ = vp.roughness;
        const __m512 eps = _mm512_set1_ps(vp.eps), half = _mm512_set1_ps(0.5f),
                     shrink = _mm512_set1_ps(0.999f), one = _mm512_set1_ps(1.f),
                     window = _mm512_set1_ps(vp.end_window), tiny = _mm512_set1_ps(1e-30f);
        const __m512 absmask = _mm512_castsi512_ps(_mm512_set1_epi32(0x7fffffff));
        for (int o = 0; o < count; o += 16) {
            const __mmask16 m = __mmask16(count - o >= 16 ? 0xffff : (1u << (count - o)) - 1);
            const __m512i ia = _mm512_maskz_loadu_epi32(m, a + o);
            const __m512i ib = _mm512_maskz_loadu_epi32(m, b + o);
            _mm512_store_si512(a_ + o, _mm512_mask_mov_epi32(_mm512_set1_epi32(-1), m, ia));
            _mm512_store_si512(b_ + o, _mm512_mask_mov_epi32(_mm512_set1_epi32(-1), m, ib));
            __m512 fa[8], fb[8];
            leaf_fields(t.leaves, a + o, count - o, fa);
            leaf_fields(t.leaves, b + o, count - o, fb);
            const __m512 ax = fa[0], ay = fa[1], az = fa[2], da = fa[3];
            const __m512 bx = fb[0], by = fb[1], bz = fb[2], db = fb[3];
            const __m512 dx = _mm512_sub_ps(bx, ax), dy = _mm512_sub_ps(by, ay),
                         dz = _mm512_sub_ps(bz, az);
            const __m512 len = sqrt_zmm(dot_zmm(dx, dy, dz, dx, dy, dz));
            const __m512 wa = _mm512_mul_ps(window, da), wb = _mm512_mul_ps(window, db);
            // len > 0 for a facing pair: ta = min(max(eps, wa / len), 0.5), tb alike
            const __m512 ta = min_zmm(max_zmm(eps, _mm512_div_ps(wa, len)), half);
            const __m512 tb = min_zmm(max_zmm(eps, _mm512_div_ps(wb, len)), half);
            _mm512_store_ps(t0_ + o, _mm512_mul_ps(ta, shrink));
            _mm512_store_ps(t1_ + o, _mm512_sub_ps(one, _mm512_mul_ps(tb, shrink)));
            const __mmask16 small =
                m & (_mm512_cmp_ps_mask(_mm512_and_ps(dx, absmask), tiny, _CMP_LT_OQ) |
                     _mm512_cmp_ps_mask(_mm512_and_ps(dy, absmask), tiny, _CMP_LT_OQ) |
                     _mm512_cmp_ps_mask(_mm512_and_ps(dz, absmask), tiny, _CMP_LT_OQ));
            live_ |= uint32_t(m & ~small) << o;
            alone_ |= uint32_t(small) << o;
            _mm512_store_si512(resume_ + o,
                               _mm512_mask_mov_epi32(_mm512_setzero_si512(), __mmask16(~m | small),
                                                     _mm512_set1_epi32(INT_MAX)));
            _mm512_store_si512(occluders_ + o, _mm512_setzero_si512());
            _mm512_store_ps(p_[0] + o, ax), _mm512_store_ps(p_[1] + o, ay);
            _mm512_store_ps(p_[2] + o, az);
            _mm512_store_ps(inv_[0] + o, _mm512_div_ps(one, dx));
            _mm512_store_ps(inv_[1] + o, _mm512_div_ps(one, dy));
            _mm512_store_ps(inv_[2] + o, _mm512_div_ps(one, dz));
            _mm512_store_ps(d_[0] + o, dx), _mm512_store_ps(d_[1] + o, dy);
            _mm512_store_ps(d_[2] + o, dz);
            _mm512_store_ps(q_[0] + o, bx), _mm512_store_ps(q_[1] + o, by);
            _mm512_store_ps(q_[2] + o, bz);
            _mm512_store_ps(na_[0] + o, fa[4]), _mm512_store_ps(na_[1] + o, fa[5]);
            _mm512_store_ps(na_[2] + o, fa[6]);
            _mm512_store_ps(nb_[0] + o, fb[4]), _mm512_store_ps(nb_[1] + o, fb[5]);
            _mm512_store_ps(nb_[2] + o, fb[6]);
            _mm512_store_ps(len_ + o, len);
            _mm512_store_ps(delta_a_ + o, da), _mm512_store_ps(delta_b_ + o, db);
            _mm512_store_ps(win_a_ + o, wa), _mm512_store_ps(win_b_ + o, wb);
            const __m512i flag = _mm512_set1_epi32(int(kLeafNormalDegenerate));
            no_plane_a_ |=
                uint32_t(_mm512_mask_test_epi32_mask(m, _mm512_castps_si512(fa[7]), flag)) << o;
            no_plane_b_ |=
                uint32_t(_mm512_mask_test_epi32_mask(m, _mm512_castps_si512(fb[7]), flag)) << o;
        }
        for (int i = 0; i < count; ++i) lane_[i] = i;
        // Lanes past count: padding as in pad() (no pair, finite slabs).
        for (int i = count; i < ((count + 15) & ~15); ++i) {
            p_[0][i] = p_[1][i] = p_[2][i] = inv_[0][i] = inv_[1][i] = inv_[2][i] = 0.f;
            t0_[i] = t1_[i] = 0.f;
        }
        for (int i = (count + 15) & ~15; i < W; ++i) pad_lane(i);
    }
    // load_zmm on AVX2, 8 lanes at a time: the same float operations (vsqrtps, vdivps and the
    // compares are IEEE like their scalar forms), so the same bits.
    __attribute__((target("avx2"), noinline)) void load_ymm(const OctreeView& t, const int32_t* a,
                                                            const int32_t* b, int count,
                                                            const VisibilityParams& vp) {
        live_ = alone_ = no_plane_a_ = no_plane_b_ = 0;
        roughness_ = vp.roughness;
        const __m256 eps = _mm256_set1_ps(vp.eps), half = _mm256_set1_ps(0.5f),
                     shrink = _mm256_set1_ps(0.999f), one = _mm256_set1_ps(1.f),
                     window = _mm256_set1_ps(vp.end_window), tiny = _mm256_set1_ps(1e-30f);
        const __m256 absmask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
        const __m256i lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        const __m256i none = _mm256_set1_epi32(-1),
                      flag = _mm256_set1_epi32(int(kLeafNormalDegenerate));
        for (int o = 0; o < count; o += 8) {
            const int n = count - o < 8 ? count - o : 8;
            const __m256i mv = _mm256_cmpgt_epi32(_mm256_set1_epi32(n), lanes);
            const uint32_t m = n == 8 ? 0xffu : (1u << n) - 1;
            sti(a_ + o, _mm256_blendv_epi8(none, _mm256_maskload_epi32(a + o, mv), mv));
            sti(b_ + o, _mm256_blendv_epi8(none, _mm256_maskload_epi32(b + o, mv), mv));
            __m256 fa[8], fb[8];
            leaf_fields_ymm(t.leaves, a + o, n, fa);
            leaf_fields_ymm(t.leaves, b + o, n, fb);
            const __m256 ax = fa[0], ay = fa[1], az = fa[2], da = fa[3];
            const __m256 bx = fb[0], by = fb[1], bz = fb[2], db = fb[3];
            const __m256 dx = _mm256_sub_ps(bx, ax), dy = _mm256_sub_ps(by, ay),
                         dz = _mm256_sub_ps(bz, az);
            const __m256 len = _mm256_sqrt_ps(dot_ymm(dx, dy, dz, dx, dy, dz));
            const __m256 wa = _mm256_mul_ps(window, da), wb = _mm256_mul_ps(window, db);
            // len > 0 for a facing pair: ta = min(max(eps, wa / len), 0.5), tb alike
            const __m256 ta = _mm256_min_ps(_mm256_max_ps(eps, _mm256_div_ps(wa, len)), half);
            const __m256 tb = _mm256_min_ps(_mm256_max_ps(eps, _mm256_div_ps(wb, len)), half);
            st(t0_ + o, _mm256_mul_ps(ta, shrink));
            st(t1_ + o, _mm256_sub_ps(one, _mm256_mul_ps(tb, shrink)));
            const __m256 small_v = _mm256_or_ps(
                _mm256_or_ps(_mm256_cmp_ps(_mm256_and_ps(dx, absmask), tiny, _CMP_LT_OQ),
                             _mm256_cmp_ps(_mm256_and_ps(dy, absmask), tiny, _CMP_LT_OQ)),
                _mm256_cmp_ps(_mm256_and_ps(dz, absmask), tiny, _CMP_LT_OQ));
            const uint32_t small = m & bits_ymm(small_v);
            live_ |= (m & ~small) << o;
            alone_ |= small << o;
            // INT_MAX where no pair or a small lane, else 0
            const __m256i out =
                _mm256_or_si256(_mm256_castps_si256(small_v), _mm256_xor_si256(mv, none));
            sti(resume_ + o, _mm256_and_si256(out, _mm256_set1_epi32(INT_MAX)));
            sti(occluders_ + o, _mm256_setzero_si256());
            st(p_[0] + o, ax), st(p_[1] + o, ay), st(p_[2] + o, az);
            st(inv_[0] + o, _mm256_div_ps(one, dx));
            st(inv_[1] + o, _mm256_div_ps(one, dy));
            st(inv_[2] + o, _mm256_div_ps(one, dz));
            st(d_[0] + o, dx), st(d_[1] + o, dy), st(d_[2] + o, dz);
            st(q_[0] + o, bx), st(q_[1] + o, by), st(q_[2] + o, bz);
            st(na_[0] + o, fa[4]), st(na_[1] + o, fa[5]), st(na_[2] + o, fa[6]);
            st(nb_[0] + o, fb[4]), st(nb_[1] + o, fb[5]), st(nb_[2] + o, fb[6]);
            st(len_ + o, len);
            st(delta_a_ + o, da), st(delta_b_ + o, db);
            st(win_a_ + o, wa), st(win_b_ + o, wb);
            no_plane_a_ |= (flagged_ymm(fa[7], flag) & m) << o;
            no_plane_b_ |= (flagged_ymm(fb[7], flag) & m) << o;
        }
        for (int i = 0; i < count; ++i) lane_[i] = i;
        // Lanes past count: padding as in pad() (no pair, finite slabs).
        for (int i = count; i < ((count + 7) & ~7); ++i) {
            p_[0][i] = p_[1][i] = p_[2][i] = inv_[0][i] = inv_[1][i] = inv_[2][i] = 0.f;
            t0_[i] = t1_[i] = 0.f;
        }
        for (int i = (count + 7) & ~7; i < W; ++i) pad_lane(i);
    }
#endif
    void pad_lane(int i) {
        resume_[i] = INT_MAX;
        p_[0][i] = p_[1][i] = p_[2][i] = inv_[0][i] = inv_[1][i] = inv_[2][i] = 0.f;
        t0_[i] = t1_[i] = 0.f;
        a_[i] = b_[i] = -1;
        occluders_[i] = 0;
    }
    // 1 << i, as a table: the lane loop's masks then vectorise with SSE2 as well.
    static constexpr auto kBit = [] {
        std::array<uint32_t, W> b{};
        for (int i = 0; i < W; ++i) b[size_t(i)] = 1u << i;
        return b;
    }();
    // The packet's walk; returns the node tests. The same loop compiled for wider vectors
    // (walk_avx2, walk_avx512: the same float operations, FMA contraction is off, so the same
    // bits) where the CPU has them.
    // kYmm: the occluder tests of a leaf with a plane 8 lanes at a time (occluders_ymm; only
    // from walk_avx2).
    template <bool kYmm = false, class Counters>
    __attribute__((always_inline)) inline int64_t walk_nodes(const OctreeView& t,
                                                             const VisibilityParams& vp, int live,
                                                             Counters* wc) {
        int32_t tests[W] = {};
        int32_t n = 0;
        while (n < t.num_nodes && live > 0) {
            const WalkNode w = t.walk[n];
            uint32_t hits = 0;  // the lanes whose walks enter node n
            for (int i = 0; i < W; ++i) {
                float tmin = t0_[i], tmax = t1_[i];
                axis(0, i, w.lo.x, w.hi.x, tmin, tmax);
                axis(1, i, w.lo.y, w.hi.y, tmin, tmax);
                axis(2, i, w.lo.z, w.hi.z, tmin, tmax);
                const int32_t on = n >= resume_[i];
                const int32_t h = on & (tmin <= tmax);
                tests[i] += on;
                resume_[i] = (on & !h) ? w.skip : resume_[i];
                hits |= (0u - uint32_t(h)) & kBit[i];
            }
            if (!hits) {
                n = w.skip;
                continue;
            }
            if (w.leaf >= 0) {
#if VMAP_PACKET_ISA
                if constexpr (kYmm && W % 8 == 0) {
                    const LeafDisc& x = t.leaves[w.leaf];
                    live -= !(x.flags & kLeafNormalDegenerate)
                                ? occluders_ymm(x, w.leaf, hits, vp, wc)
                                : occluders_at(t, w.leaf, hits, vp, wc);
                } else
#endif
                    live -= occluders_at(t, w.leaf, hits, vp, wc);
            }
            ++n;  // first child, or (for a leaf, whose skip is n + 1) the next subtree
        }
        int64_t sum = 0;
        for (int i = 0; i < W; ++i) sum += tests[i];
        return sum;
    }
#if VMAP_PACKET_ISA
    template <class Counters>
    __attribute__((target("avx2"), noinline)) int64_t walk_avx2(const OctreeView& t,
                                                                const VisibilityParams& vp,
                                                                int live, Counters* wc) {
        if constexpr (W % 8 == 0)
            return walk_ymm(t, vp, live, wc);
        else
            return walk_nodes<true>(t, vp, live, wc);
    }
    // walk_nodes in AVX2 vectors, 8 lanes a register, written out as walk_zmm is: the same
    // float operations (vminps and vmaxps are min_f and max_f), so the same bits. The lanes'
    // hits come out of the compares as bits (vmovmskps) where GCC's vectorised loop ORs the
    // lanes' words together at every node; the resume points stay in registers between
    // occluder tests; the node tests are counted as the popcount of the lanes on.
    template <class Counters>
    __attribute__((target("avx2"), always_inline)) inline int64_t walk_ymm(
        const OctreeView& t, const VisibilityParams& vp, int live, Counters* wc) {
        constexpr int G = W / 8;
        __m256i resume[G];
        for (int h = 0; h < G; ++h)
            resume[h] = _mm256_load_si256(reinterpret_cast<const __m256i*>(resume_ + 8 * h));
        int64_t tests = 0;
        int32_t n = 0;
        while (n < t.num_nodes && live > 0) {
            const WalkNode w = t.walk[n];
            const __m256 lo[3] = {_mm256_set1_ps(w.lo.x), _mm256_set1_ps(w.lo.y),
                                  _mm256_set1_ps(w.lo.z)};
            const __m256 hi[3] = {_mm256_set1_ps(w.hi.x), _mm256_set1_ps(w.hi.y),
                                  _mm256_set1_ps(w.hi.z)};
            const __m256i at = _mm256_set1_epi32(n), skip = _mm256_set1_epi32(w.skip);
            uint32_t hits = 0, on_all = 0;  // the lanes whose walks enter node n; test it
            for (int h = 0; h < G; ++h) {
                const int o = 8 * h;
                __m256 tmin = ld(t0_ + o), tmax = ld(t1_ + o);
                for (int k = 0; k < 3; ++k) {
                    const __m256 p = ld(p_[k] + o), inv = ld(inv_[k] + o);
                    const __m256 ta = _mm256_mul_ps(_mm256_sub_ps(lo[k], p), inv);
                    const __m256 tb = _mm256_mul_ps(_mm256_sub_ps(hi[k], p), inv);
                    tmin = _mm256_max_ps(tmin, _mm256_min_ps(ta, tb));
                    tmax = _mm256_min_ps(tmax, _mm256_max_ps(ta, tb));
                }
                // on: n >= resume, i.e. not resume > n
                const __m256i off = _mm256_cmpgt_epi32(resume[h], at);
                const __m256 hit = _mm256_andnot_ps(_mm256_castsi256_ps(off),
                                                    _mm256_cmp_ps(tmin, tmax, _CMP_LE_OQ));
                // resume = on & !hit ? skip : resume
                const __m256i miss = _mm256_andnot_si256(
                    _mm256_or_si256(off, _mm256_castps_si256(hit)), _mm256_set1_epi32(-1));
                resume[h] = _mm256_blendv_epi8(resume[h], skip, miss);
                on_all |= (~bits_ymm(_mm256_castsi256_ps(off)) & 0xffu) << o;
                hits |= bits_ymm(hit) << o;
            }
            tests += __builtin_popcount(on_all);
            if (!hits) {
                n = w.skip;
                continue;
            }
            if (w.leaf >= 0) {  // the occluder tests read and set resume_
                for (int h = 0; h < G; ++h)
                    _mm256_store_si256(reinterpret_cast<__m256i*>(resume_ + 8 * h), resume[h]);
                const LeafDisc& x = t.leaves[w.leaf];
                live -= !(x.flags & kLeafNormalDegenerate) ? occluders_ymm(x, w.leaf, hits, vp, wc)
                                                           : occluders_at(t, w.leaf, hits, vp, wc);
                for (int h = 0; h < G; ++h)
                    resume[h] =
                        _mm256_load_si256(reinterpret_cast<const __m256i*>(resume_ + 8 * h));
            }
            ++n;  // first child, or (for a leaf, whose skip is n + 1) the next subtree
        }
        for (int h = 0; h < G; ++h)
            _mm256_store_si256(reinterpret_cast<__m256i*>(resume_ + 8 * h), resume[h]);
        return tests;
    }
    // occluders_zmm on AVX2 (hosts without AVX-512): counts_as_occluder's float operations in
    // the same order, 8 lanes at a time, the masks as bits of a word (vmovmskps); the K rule
    // lane by lane over the lanes whose leaf counts. The same bits as occluders_at.
    // Why the 8- and 16-lane forms (load_ymm / load_zmm, occluders_ymm / occluders_zmm,
    // walk_ymm / walk_zmm) are written twice: one body over a vector-width trait would call
    // intrinsics wrappers from a function without the ISA's target attribute, which GCC refuses
    // to inline (target specific option mismatch); one translation unit per ISA (-mavx512f)
    // would also compile the shared headers' inline functions for AVX-512, and the linker may
    // keep those copies for every caller, AVX2 hosts included. So each width has its own body,
    // and the PacketWalk tests hold every one the CPU has to the one-pair walk.
    __attribute__((target("avx2"), always_inline)) static inline uint32_t bits_ymm(__m256 v) {
        return uint32_t(_mm256_movemask_ps(v));
    }
    __attribute__((target("avx2"), always_inline)) static inline __m256 ld(const float* f) {
        return _mm256_load_ps(f);
    }
    __attribute__((target("avx2"), always_inline)) static inline void st(float* to, __m256 v) {
        _mm256_store_ps(to, v);
    }
    __attribute__((target("avx2"), always_inline)) static inline void sti(int32_t* to, __m256i v) {
        _mm256_store_si256(reinterpret_cast<__m256i*>(to), v);
    }
    // The lanes whose flags' bits (a leaf's eighth float) hold `flag`.
    __attribute__((target("avx2"), always_inline)) static inline uint32_t flagged_ymm(
        __m256 bits, __m256i flag) {
        const __m256i f = _mm256_and_si256(_mm256_castps_si256(bits), flag);
        return ~bits_ymm(_mm256_castsi256_ps(_mm256_cmpeq_epi32(f, _mm256_setzero_si256()))) &
               0xffu;
    }
    template <class Counters>
    __attribute__((target("avx2"), noinline)) int
    occluders_ymm(const LeafDisc& x, int32_t leaf, uint32_t hits, const VisibilityParams& vp,
                  Counters* wc) {
        const __m256 cx = _mm256_set1_ps(x.centroid.x), cy = _mm256_set1_ps(x.centroid.y),
                     cz = _mm256_set1_ps(x.centroid.z);
        const __m256 nx = _mm256_set1_ps(x.normal.x), ny = _mm256_set1_ps(x.normal.y),
                     nz = _mm256_set1_ps(x.normal.z);
        const __m256 zero = _mm256_setzero_ps(), half = _mm256_set1_ps(0.5f),
                     one = _mm256_set1_ps(1.f);
        const __m256 eps = _mm256_set1_ps(vp.eps), eps1 = _mm256_set1_ps(1.f - vp.eps);
        const __m256 ptol = _mm256_set1_ps(vp.parallel_tol);
        const __m256 dd = _mm256_set1_ps(x.delta * x.delta);
        const float rc = core_radius(x, vp);
        const __m256 cc = _mm256_set1_ps(rc * rc);
        const __m256 rough_ = _mm256_set1_ps(vp.roughness),
                     sheet_cos = _mm256_set1_ps(kSameSheetCos);
        const bool rough_on = vp.roughness > 0;
        const __m256i lf = _mm256_set1_epi32(leaf);
        const __m256 absmask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
        int left = 0;
        for (int h = 0; h < W / 8; ++h) {
            const int o = 8 * h;
            uint32_t m = (hits >> o) & 0xffu;
            if (!m) continue;
            const __m256i la = _mm256_load_si256(reinterpret_cast<const __m256i*>(a_ + o));
            const __m256i lb = _mm256_load_si256(reinterpret_cast<const __m256i*>(b_ + o));
            m &= ~(bits_ymm(_mm256_castsi256_ps(_mm256_cmpeq_epi32(la, lf))) |
                   bits_ymm(_mm256_castsi256_ps(_mm256_cmpeq_epi32(lb, lf))));
            wc->occluder_tests += uint64_t(__builtin_popcount(m));
            if (!m) continue;
            const __m256 px = ld(p_[0] + o), py = ld(p_[1] + o), pz = ld(p_[2] + o);
            const __m256 qx = ld(q_[0] + o), qy = ld(q_[1] + o), qz = ld(q_[2] + o);
            const __m256 dx = ld(d_[0] + o), dy = ld(d_[1] + o), dz = ld(d_[2] + o);
            const __m256 len = ld(len_ + o);
            const uint32_t npa = (no_plane_a_ >> o) & 0xffu, npb = (no_plane_b_ >> o) & 0xffu;
            // in_front_of_ends
            const __m256 vx = _mm256_sub_ps(cx, px), vy = _mm256_sub_ps(cy, py),
                         vz = _mm256_sub_ps(cz, pz);
            const __m256 fa = dot_ymm(ld(na_[0] + o), ld(na_[1] + o), ld(na_[2] + o), vx, vy, vz);
            const __m256 fb = dot_ymm(ld(nb_[0] + o), ld(nb_[1] + o), ld(nb_[2] + o),
                                      _mm256_sub_ps(cx, qx), _mm256_sub_ps(cy, qy),
                                      _mm256_sub_ps(cz, qz));
            m &= bits_ymm(_mm256_cmp_ps(fa, zero, _CMP_GT_OQ)) | npa;
            m &= bits_ymm(_mm256_cmp_ps(fb, zero, _CMP_GT_OQ)) | npb;
            // is_actual_occluder, x with a plane
            const __m256 nd = dot_ymm(nx, ny, nz, dx, dy, dz);
            m &= ~bits_ymm(
                _mm256_cmp_ps(_mm256_and_ps(nd, absmask), _mm256_mul_ps(ptol, len), _CMP_LE_OQ));
            const __m256 tt = _mm256_div_ps(dot_ymm(nx, ny, nz, vx, vy, vz), nd);
            m &= bits_ymm(_mm256_cmp_ps(tt, eps, _CMP_GT_OQ)) &
                 bits_ymm(_mm256_cmp_ps(tt, eps1, _CMP_LT_OQ));
            const __m256 ex = _mm256_sub_ps(_mm256_add_ps(px, _mm256_mul_ps(dx, tt)), cx);
            const __m256 ey = _mm256_sub_ps(_mm256_add_ps(py, _mm256_mul_ps(dy, tt)), cy);
            const __m256 ez = _mm256_sub_ps(_mm256_add_ps(pz, _mm256_mul_ps(dz, tt)), cz);
            const __m256 r2 = dot_ymm(ex, ey, ez, ex, ey, ez);
            m &= bits_ymm(_mm256_cmp_ps(r2, dd, _CMP_LE_OQ));
            if (!m) continue;
            const uint32_t in_core = bits_ymm(_mm256_cmp_ps(r2, cc, _CMP_LT_OQ));
            // exits_at_an_end and beyond_the_end_windows, by the nearer end (blendv takes its
            // second operand where the mask is set, as mask_blend does)
            const __m256 near_v = _mm256_cmp_ps(tt, half, _CMP_LT_OQ);
            const uint32_t near_a = bits_ymm(near_v);
            const __m256 from_end =
                _mm256_mul_ps(_mm256_blendv_ps(_mm256_sub_ps(one, tt), tt, near_v), len);
            const __m256 hd = _mm256_mul_ps(
                half, _mm256_blendv_ps(ld(delta_b_ + o), ld(delta_a_ + o), near_v));
            const __m256 ux = _mm256_blendv_ps(qx, px, near_v),
                         uy = _mm256_blendv_ps(qy, py, near_v),
                         uz = _mm256_blendv_ps(qz, pz, near_v);
            const __m256 back = dot_ymm(nx, ny, nz, _mm256_sub_ps(ux, cx), _mm256_sub_ps(uy, cy),
                                        _mm256_sub_ps(uz, cz));
            const uint32_t plane_near = ~((near_a & npa) | (~near_a & npb)) & 0xffu;
            uint32_t rough = 0;
            if (rough_on) {
                const __m256 same =
                    dot_ymm(nx, ny, nz, _mm256_blendv_ps(ld(nb_[0] + o), ld(na_[0] + o), near_v),
                            _mm256_blendv_ps(ld(nb_[1] + o), ld(na_[1] + o), near_v),
                            _mm256_blendv_ps(ld(nb_[2] + o), ld(na_[2] + o), near_v));
                rough = bits_ymm(_mm256_cmp_ps(_mm256_sub_ps(zero, back), rough_, _CMP_LT_OQ)) &
                        bits_ymm(_mm256_cmp_ps(same, sheet_cos, _CMP_GT_OQ));
            }
            const uint32_t exits = plane_near & bits_ymm(_mm256_cmp_ps(back, zero, _CMP_LT_OQ)) &
                                   (bits_ymm(_mm256_cmp_ps(from_end, hd, _CMP_LT_OQ)) | rough);
            const __m256 win = _mm256_blendv_ps(ld(win_b_ + o), ld(win_a_ + o), near_v);
            m &= ~exits & bits_ymm(_mm256_cmp_ps(from_end, win, _CMP_NLT_UQ));
            // The K rule, lane by lane; a crossing in x's core counts K (occluder_weight).
            for (; m; m &= m - 1) {
                const int b = __builtin_ctz(m), i = o + b;
                occluders_[i] += (in_core >> b & 1u) ? vp.K : 1;
                if (occluders_[i] < vp.K) continue;
                live_ &= ~(1u << i);
                resume_[i] = INT_MAX;
                ++left;
            }
        }
        return left;
    }
    template <class Counters>
    __attribute__((target("avx512f,avx512vl,avx512bw,avx512dq,prefer-vector-width=512"), noinline))
    int64_t
    walk_avx512(const OctreeView& t, const VisibilityParams& vp, int live, Counters* wc) {
        if constexpr (W == 32)
            return walk_zmm(t, vp, live, wc);
        else
            return walk_nodes(t, vp, live, wc);
    }
    // walk_nodes for 32 lanes in two AVX-512 registers, written out: the same float operations
    // (vminps(a, b) is a < b ? a : b and vmaxps(a, b) is a > b ? a : b, min_f and max_f; no NaN
    // arises, as there), so the same bits; what differs is that the lanes' hits
    // come out of the compare as a mask (GCC's vectorised loop ORs 32 words together at every
    // node) and the lanes' resume points stay in registers between occluder tests.
    template <class Counters>
    __attribute__((target("avx512f,avx512vl,avx512bw,avx512dq"), always_inline)) inline int64_t
    walk_zmm(const OctreeView& t, const VisibilityParams& vp, int live, Counters* wc) {
        __m512 p[3][2], inv[3][2], t0[2], t1[2];
        __m512i resume[2], tests[2];
        for (int h = 0; h < 2; ++h) {
            for (int k = 0; k < 3; ++k) {
                p[k][h] = _mm512_load_ps(p_[k] + 16 * h);
                inv[k][h] = _mm512_load_ps(inv_[k] + 16 * h);
            }
            t0[h] = _mm512_load_ps(t0_ + 16 * h);
            t1[h] = _mm512_load_ps(t1_ + 16 * h);
            resume[h] = _mm512_load_si512(resume_ + 16 * h);
            tests[h] = _mm512_setzero_si512();
        }
        const __m512i one = _mm512_set1_epi32(1);
        int32_t n = 0;
        while (n < t.num_nodes && live > 0) {
            const WalkNode w = t.walk[n];
            const float lo[3] = {w.lo.x, w.lo.y, w.lo.z}, hi[3] = {w.hi.x, w.hi.y, w.hi.z};
            const __m512i at = _mm512_set1_epi32(n), skip = _mm512_set1_epi32(w.skip);
            uint32_t hits = 0;  // the lanes whose walks enter node n
            for (int h = 0; h < 2; ++h) {
                __m512 tmin = t0[h], tmax = t1[h];
                for (int k = 0; k < 3; ++k) {
                    const __m512 ta = _mm512_mul_ps(_mm512_sub_ps(_mm512_set1_ps(lo[k]), p[k][h]),
                                                    inv[k][h]);
                    const __m512 tb = _mm512_mul_ps(_mm512_sub_ps(_mm512_set1_ps(hi[k]), p[k][h]),
                                                    inv[k][h]);
                    tmin = max_zmm(tmin, min_zmm(ta, tb));
                    tmax = min_zmm(tmax, max_zmm(ta, tb));
                }
                const __mmask16 on = _mm512_cmpge_epi32_mask(at, resume[h]);
                const __mmask16 hit = _mm512_mask_cmp_ps_mask(on, tmin, tmax, _CMP_LE_OQ);
                tests[h] = _mm512_mask_add_epi32(tests[h], on, tests[h], one);
                resume[h] = _mm512_mask_mov_epi32(resume[h], __mmask16(on & ~hit), skip);
                hits |= uint32_t(hit) << (16 * h);
            }
            if (!hits) {
                n = w.skip;
                continue;
            }
            if (w.leaf >= 0) {
                const LeafDisc& x = t.leaves[w.leaf];
                if (!(x.flags & kLeafNormalDegenerate)) {
                    live -= occluders_zmm(x, w.leaf, hits, resume, vp, wc);
                } else {  // occluders_at reads and sets resume_
                    _mm512_store_si512(resume_, resume[0]);
                    _mm512_store_si512(resume_ + 16, resume[1]);
                    live -= occluders_at(t, w.leaf, hits, vp, wc);
                    resume[0] = _mm512_load_si512(resume_);
                    resume[1] = _mm512_load_si512(resume_ + 16);
                }
            }
            ++n;  // first child, or (for a leaf, whose skip is n + 1) the next subtree
        }
        alignas(64) int32_t sums[W];
        _mm512_store_si512(sums, tests[0]);
        _mm512_store_si512(sums + 16, tests[1]);
        int64_t sum = 0;
        for (int i = 0; i < W; ++i) sum += sums[i];
        return sum;
    }
    // occluders_at for a leaf x with a plane (not flagged), the lanes in 16 at a time:
    // counts_as_occluder's float operations in the same order on every lane (in_front_of_ends,
    // is_actual_occluder's plane branch, exits_at_an_end, beyond_the_end_windows; FMA
    // contraction is off, vdivps and the compares are IEEE like their scalar forms), so the same
    // bits; a lane whose own end is x is left out and not counted, as occluder_reached does.
    // The lanes that reach their K-th occluder leave: resume to INT_MAX, out of live_.
    template <class Counters>
    __attribute__((target("avx512f,avx512vl,avx512bw,avx512dq"), always_inline)) inline int
    occluders_zmm(const LeafDisc& x, int32_t leaf, uint32_t hits, __m512i resume[2],
                  const VisibilityParams& vp, Counters* wc) {
        const __m512 cx = _mm512_set1_ps(x.centroid.x), cy = _mm512_set1_ps(x.centroid.y),
                     cz = _mm512_set1_ps(x.centroid.z);
        const __m512 nx = _mm512_set1_ps(x.normal.x), ny = _mm512_set1_ps(x.normal.y),
                     nz = _mm512_set1_ps(x.normal.z);
        const __m512 zero = _mm512_setzero_ps(), half = _mm512_set1_ps(0.5f),
                     one = _mm512_set1_ps(1.f);
        const __m512 eps = _mm512_set1_ps(vp.eps), eps1 = _mm512_set1_ps(1.f - vp.eps);
        const __m512 ptol = _mm512_set1_ps(vp.parallel_tol);
        const __m512 dd = _mm512_set1_ps(x.delta * x.delta);
        const float rc = core_radius(x, vp);
        const __m512 cc = _mm512_set1_ps(rc * rc);
        const __m512 rough_ = _mm512_set1_ps(vp.roughness),
                     sheet_cos = _mm512_set1_ps(kSameSheetCos);
        const bool rough_on = vp.roughness > 0;
        const __m512i lf = _mm512_set1_epi32(leaf), kk = _mm512_set1_epi32(vp.K),
                      more = _mm512_set1_epi32(vp.K - 1);
        const __m512 absmask = _mm512_castsi512_ps(_mm512_set1_epi32(0x7fffffff));
        int left = 0;
        for (int h = 0; h < 2; ++h) {
            __mmask16 m = __mmask16(hits >> (16 * h));
            if (!m) continue;
            const int o = 16 * h;
            m &= __mmask16(~(_mm512_cmpeq_epi32_mask(_mm512_load_si512(a_ + o), lf) |
                             _mm512_cmpeq_epi32_mask(_mm512_load_si512(b_ + o), lf)));
            wc->occluder_tests += uint64_t(__builtin_popcount(m));
            const __m512 px = _mm512_load_ps(p_[0] + o), py = _mm512_load_ps(p_[1] + o),
                         pz = _mm512_load_ps(p_[2] + o);
            const __m512 qx = _mm512_load_ps(q_[0] + o), qy = _mm512_load_ps(q_[1] + o),
                         qz = _mm512_load_ps(q_[2] + o);
            const __m512 dx = _mm512_load_ps(d_[0] + o), dy = _mm512_load_ps(d_[1] + o),
                         dz = _mm512_load_ps(d_[2] + o);
            const __m512 len = _mm512_load_ps(len_ + o);
            // in_front_of_ends: dot(na, c - p) > 0 and dot(nb, c - q) > 0, where an end has a plane
            const __m512 vx = _mm512_sub_ps(cx, px), vy = _mm512_sub_ps(cy, py),
                         vz = _mm512_sub_ps(cz, pz);
            const __m512 fa = dot_zmm(_mm512_load_ps(na_[0] + o), _mm512_load_ps(na_[1] + o),
                                      _mm512_load_ps(na_[2] + o), vx, vy, vz);
            const __m512 fb = dot_zmm(_mm512_load_ps(nb_[0] + o), _mm512_load_ps(nb_[1] + o),
                                      _mm512_load_ps(nb_[2] + o), _mm512_sub_ps(cx, qx),
                                      _mm512_sub_ps(cy, qy), _mm512_sub_ps(cz, qz));
            m &= __mmask16(_mm512_cmp_ps_mask(fa, zero, _CMP_GT_OQ) | (no_plane_a_ >> o));
            m &= __mmask16(_mm512_cmp_ps_mask(fb, zero, _CMP_GT_OQ) | (no_plane_b_ >> o));
            // is_actual_occluder, x with a plane: not parallel, cut in (eps, 1 - eps), on the disc
            const __m512 nd = dot_zmm(nx, ny, nz, dx, dy, dz);
            m &= __mmask16(~_mm512_cmp_ps_mask(_mm512_and_ps(nd, absmask), _mm512_mul_ps(ptol, len),
                                               _CMP_LE_OQ));
            const __m512 tt = _mm512_div_ps(dot_zmm(nx, ny, nz, vx, vy, vz), nd);
            m &= _mm512_cmp_ps_mask(tt, eps, _CMP_GT_OQ) & _mm512_cmp_ps_mask(tt, eps1, _CMP_LT_OQ);
            const __m512 ex = _mm512_sub_ps(_mm512_add_ps(px, _mm512_mul_ps(dx, tt)), cx);
            const __m512 ey = _mm512_sub_ps(_mm512_add_ps(py, _mm512_mul_ps(dy, tt)), cy);
            const __m512 ez = _mm512_sub_ps(_mm512_add_ps(pz, _mm512_mul_ps(dz, tt)), cz);
            const __m512 r2 = dot_zmm(ex, ey, ez, ex, ey, ez);
            m &= _mm512_cmp_ps_mask(r2, dd, _CMP_LE_OQ);
            const __mmask16 in_core = _mm512_cmp_ps_mask(r2, cc, _CMP_LT_OQ);
            // exits_at_an_end (x has a plane) and beyond_the_end_windows, by the nearer end
            const __mmask16 near_a = _mm512_cmp_ps_mask(tt, half, _CMP_LT_OQ);
            const __m512 from_end =
                _mm512_mul_ps(_mm512_mask_blend_ps(near_a, _mm512_sub_ps(one, tt), tt), len);
            const __m512 hd =
                _mm512_mul_ps(half, _mm512_mask_blend_ps(near_a, _mm512_load_ps(delta_b_ + o),
                                                         _mm512_load_ps(delta_a_ + o)));
            const __m512 ux = _mm512_mask_blend_ps(near_a, qx, px),
                         uy = _mm512_mask_blend_ps(near_a, qy, py),
                         uz = _mm512_mask_blend_ps(near_a, qz, pz);
            const __m512 back = dot_zmm(nx, ny, nz, _mm512_sub_ps(ux, cx), _mm512_sub_ps(uy, cy),
                                        _mm512_sub_ps(uz, cz));
            const __mmask16 plane_near =
                __mmask16(~((near_a & (no_plane_a_ >> o)) | (~near_a & (no_plane_b_ >> o))));
            // ... or, on a rough sheet, an end behind x's plane by less than the roughness
            // with x's normal near that end's (negation is exact: -back < r as in the scalar).
            // Without a roughness no lane passes -back < 0 where back < 0: skipped.
            __mmask16 rough = 0;
            if (rough_on) {
                const __m512 same =
                    dot_zmm(nx, ny, nz,
                            _mm512_mask_blend_ps(near_a, _mm512_load_ps(nb_[0] + o),
                                                 _mm512_load_ps(na_[0] + o)),
                            _mm512_mask_blend_ps(near_a, _mm512_load_ps(nb_[1] + o),
                                                 _mm512_load_ps(na_[1] + o)),
                            _mm512_mask_blend_ps(near_a, _mm512_load_ps(nb_[2] + o),
                                                 _mm512_load_ps(na_[2] + o)));
                rough = _mm512_cmp_ps_mask(_mm512_sub_ps(zero, back), rough_, _CMP_LT_OQ) &
                        _mm512_cmp_ps_mask(same, sheet_cos, _CMP_GT_OQ);
            }
            const __mmask16 exits = plane_near & _mm512_cmp_ps_mask(back, zero, _CMP_LT_OQ) &
                                    (_mm512_cmp_ps_mask(from_end, hd, _CMP_LT_OQ) | rough);
            const __m512 win = _mm512_mask_blend_ps(near_a, _mm512_load_ps(win_b_ + o),
                                                    _mm512_load_ps(win_a_ + o));
            m &= __mmask16(~exits) & _mm512_cmp_ps_mask(from_end, win, _CMP_NLT_UQ);
            // The K rule: a lane at its K-th occluder is hidden and leaves the walk; a crossing in
            // x's core counts K (occluder_weight).
            __m512i occ = _mm512_load_si512(occluders_ + o);
            occ = _mm512_mask_add_epi32(occ, m, occ, _mm512_set1_epi32(1));
            occ = _mm512_mask_add_epi32(occ, m & in_core, occ, more);
            _mm512_store_si512(occluders_ + o, occ);
            const __mmask16 done = _mm512_mask_cmpge_epi32_mask(m, occ, kk);
            if (!done) continue;
            resume[h] = _mm512_mask_mov_epi32(resume[h], done, _mm512_set1_epi32(INT_MAX));
            live_ &= ~(uint32_t(done) << o);
            left += __builtin_popcount(done);
        }
        return left;
    }
    // _mm512_min_ps and _mm512_max_ps, all lanes through the mask (GCC 12's unmasked forms start
    // from _mm512_undefined_ps, which -Wuninitialized reports).
    __attribute__((target("avx512f"), always_inline)) static inline __m512 min_zmm(__m512 a,
                                                                                 __m512 b) {
        return _mm512_mask_min_ps(a, __mmask16(0xffff), a, b);
    }
    __attribute__((target("avx512f"), always_inline)) static inline __m512 max_zmm(__m512 a,
                                                                                 __m512 b) {
        return _mm512_mask_max_ps(a, __mmask16(0xffff), a, b);
    }
#endif
    // One axis of slab_meets_box for lane i.
    void axis(int k, int i, float lo, float hi, float& tmin, float& tmax) const {
        const float p = p_[k][i], inv = inv_[k][i];
        const float ta = (lo - p) * inv, tb = (hi - p) * inv;
        tmin = max_f(tmin, min_f(ta, tb));
        tmax = min_f(tmax, max_f(ta, tb));
    }
    // The lanes that reached leaf `leaf` test it as an occluder (occluder_reached); a lane at
    // its K-th occluder is hidden and leaves the walk. Returns the lanes that left.
    template <class Counters>
    int occluders_at(const OctreeView& t, int32_t leaf, uint32_t hits, const VisibilityParams& vp,
                     Counters* wc) {
        int left = 0;
        for (; hits; hits &= hits - 1) {
            const int i = __builtin_ctz(hits);
            if (!occluder_reached<true>(t, segment(i), leaf, a_[i], b_[i], vp, occluders_[i], wc))
                continue;
            live_ &= ~(1u << i);
            resume_[i] = INT_MAX;
            ++left;
        }
        return left;
    }

    alignas(64) float p_[3][W];
    alignas(64) float inv_[3][W];
    alignas(64) float t0_[W];
    alignas(64) float t1_[W];
    alignas(64) int32_t resume_[W];
    alignas(64) int32_t a_[W];
    alignas(64) int32_t b_[W];
    alignas(64) int32_t occluders_[W];
    // The rest of the lanes' segments (PairSegment), by field, for the vector occluder test.
    alignas(64) float d_[3][W];
    alignas(64) float q_[3][W];
    alignas(64) float na_[3][W];
    alignas(64) float nb_[3][W];
    alignas(64) float len_[W];
    alignas(64) float delta_a_[W];  // the ends' disc radii
    alignas(64) float delta_b_[W];
    alignas(64) float win_a_[W];  // the end windows
    alignas(64) float win_b_[W];
    uint32_t no_plane_a_ = 0, no_plane_b_ = 0;  // lanes whose end a (b) has no plane
    float roughness_ = 0;                       // VisibilityParams::roughness (every lane's)
    int32_t lane_[W];                           // the pair's place in the packet, per lane
    uint32_t live_ = 0;   // the packet's lanes still walking, then the visible ones
    uint32_t alone_ = 0;  // facing lanes that walk alone (a direction component below 1e-30)
};

}  // namespace vmap::detail
