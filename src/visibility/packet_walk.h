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
#pragma once

#include <array>
#include <climits>
#include <cstdint>

#include "octree/records.h"
#include "visibility/leaf_pair.h"

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
        live_ = alone_ = 0;
        int n = 0;  // the lanes to walk, packed
        for (int k = 0; k < count; ++k) {
            const LeafDisc& la = t.leaves[a[k]];
            const LeafDisc& lb = t.leaves[b[k]];
            if (!faced && !pair_faces(la, lb, vp)) continue;
            lane_[n] = k;
            a_[n] = a[k], b_[n] = b[k];
            seg_[n] = pair_segment(la, lb, vp, true);
            const SlabRay& r = seg_[n].ray;
            const bool small =
                fabsf(r.d.x) < 1e-30f || fabsf(r.d.y) < 1e-30f || fabsf(r.d.z) < 1e-30f;
            live_ |= uint32_t(!small) << n;
            alone_ |= uint32_t(small) << n;
            resume_[n] = small ? INT_MAX : 0;  // a lane not in the packet is past all
            occluders_[n] = 0;
            p_[0][n] = r.p.x, p_[1][n] = r.p.y, p_[2][n] = r.p.z;
            inv_[0][n] = r.inv.x, inv_[1][n] = r.inv.y, inv_[2][n] = r.inv.z;
            t0_[n] = r.t0, t1_[n] = r.t1;
            ++n;
        }
        for (int i = n; i < W; ++i) {  // no pair: past every node (finite slabs, no NaN)
            resume_[i] = INT_MAX;
            p_[0][i] = p_[1][i] = p_[2][i] = inv_[0][i] = inv_[1][i] = inv_[2][i] = 0.f;
            t0_[i] = t1_[i] = 0.f;
        }
        wc->facing_pairs += uint64_t(__builtin_popcount(live_));
        return n > 0;
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
    // 1 << i, as a table: the lane loop's masks then vectorise with SSE2 as well.
    static constexpr auto kBit = [] {
        std::array<uint32_t, W> b{};
        for (int i = 0; i < W; ++i) b[size_t(i)] = 1u << i;
        return b;
    }();
    // The packet's walk; returns the node tests. The same loop compiled for wider vectors
    // (walk_avx2, walk_avx512: the same float operations, FMA contraction is off, so the same
    // bits) where the CPU has them.
    template <class Counters>
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
                resume_[i] = on & !h ? w.skip : resume_[i];
                hits |= (0u - uint32_t(h)) & kBit[i];
            }
            if (!hits) {
                n = w.skip;
                continue;
            }
            if (w.leaf >= 0) live -= occluders_at(t, w.leaf, hits, vp, wc);
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
        return walk_nodes(t, vp, live, wc);
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
            if (w.leaf >= 0) {  // occluders_at reads and sets resume_
                _mm512_store_si512(resume_, resume[0]);
                _mm512_store_si512(resume_ + 16, resume[1]);
                live -= occluders_at(t, w.leaf, hits, vp, wc);
                resume[0] = _mm512_load_si512(resume_);
                resume[1] = _mm512_load_si512(resume_ + 16);
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
            if (!occluder_reached<true>(t, seg_[i], leaf, a_[i], b_[i], vp, occluders_[i], wc))
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
    int32_t a_[W], b_[W], occluders_[W];
    int32_t lane_[W];  // the pair's place in the packet, per lane
    PairSegment seg_[W];
    uint32_t live_ = 0;   // the packet's lanes still walking, then the visible ones
    uint32_t alone_ = 0;  // facing lanes that walk alone (a direction component below 1e-30)
};

}  // namespace vmap::detail
