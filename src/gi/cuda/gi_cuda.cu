// The radiosity solver on a CUDA GPU: the block refinement (gi_link_blocks, one thread per link
// end), the three bounce steps of gi_kernels.h (one thread per element, point or node) and the
// final gather (gi_final_gather_point, one thread per point), with the CPU's bodies and
// summation orders (bit-identical with --fmad=false; docs/gi.md). Every loop is an element-wise
// parallel_for_device (util/parallel_cuda.cuh) over a small functor that calls the shared body.
#include <cuda_runtime.h>

#include <algorithm>
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_run_length_encode.cuh>
#include <cub/device/device_scan.cuh>
#include <optional>
#include <string>

#include "gi/gi_device.h"
#include "util/cuda_check.h"
#include "util/device.h"
#include "util/parallel_cuda.cuh"
#include "vmap/error.h"

namespace vmap::detail {
namespace {

constexpr uint64_t kNoKey = ~uint64_t(0);

// A device array freed with its owner.
template <class T>
struct DevBuf {
    T* p = nullptr;
    uint64_t n = 0;
    DevBuf() = default;
    explicit DevBuf(uint64_t count) : n(count) {
        VMAP_CUDA_CHECK(cudaMalloc(&p, sizeof(T) * (count ? count : 1)));
    }
    DevBuf(const DevBuf&) = delete;
    DevBuf& operator=(const DevBuf&) = delete;
    DevBuf(DevBuf&& o) noexcept : p(o.p), n(o.n) { o.p = nullptr; }
    DevBuf& operator=(DevBuf&& o) noexcept {
        std::swap(p, o.p), std::swap(n, o.n);
        return *this;
    }
    ~DevBuf() {
        if (p) cudaFree(p);
    }
    void from(const T* h, uint64_t count) {
        *this = DevBuf(count);
        if (count) VMAP_CUDA_CHECK(cudaMemcpy(p, h, sizeof(T) * count, cudaMemcpyHostToDevice));
    }
    void to(T* h, uint64_t count) const {
        if (count) VMAP_CUDA_CHECK(cudaMemcpy(h, p, sizeof(T) * count, cudaMemcpyDeviceToHost));
    }
};

template <class T>
T read_one(const T* d) {
    T v{};
    VMAP_CUDA_CHECK(cudaMemcpy(&v, d, sizeof(T), cudaMemcpyDeviceToHost));
    return v;
}

void check_launch() {
    VMAP_CUDA_CHECK(cudaGetLastError());
    VMAP_CUDA_CHECK(cudaDeviceSynchronize());
}

// The loops' bodies (parallel_for_device: one index an element, link entry, block or point).

// ---- bounces
struct Gather {
    GiView v;
    __device__ void operator()(uint64_t e) const { gi_gather(v, e); }
};
struct PointUpdate {
    GiView v;
    __device__ void operator()(uint64_t i) const { gi_point_update(v, uint32_t(i)); }
};
struct PullUp {
    GiView v;
    __device__ void operator()(uint64_t n) const { gi_pull_up(v, int32_t(n)); }
};

// ---- refinement
struct CountOnly {
    VMAP_HD void operator()(uint64_t, double) const {}
};
struct FillParts {
    uint64_t* key;
    double* w;
    uint32_t* node;
    uint64_t at;
    uint32_t x;
    VMAP_HD void operator()(uint64_t k, double v) {
        key[at] = k, w[at] = v, node[at] = x;
        ++at;
    }
};

// The node whose link list holds link entry k (link_offsets is sorted, one entry per node + 1).
__device__ int32_t owner_of(const GiTree& t, uint64_t k) {
    int32_t lo = 0, hi = t.num_nodes;  // link_offsets[lo] <= k < link_offsets[hi]
    while (hi - lo > 1) {
        const int32_t mid = lo + (hi - lo) / 2;
        if (t.link_offsets[mid] <= k)
            lo = mid;
        else
            hi = mid;
    }
    return lo;
}

// Link entry k's number of parts (its link's, once: at the end x < y).
struct CountParts {
    GiTree t;
    float theta;
    uint64_t* count;
    __device__ void operator()(uint64_t k) const {
        const int32_t x = owner_of(t, k), y = t.links[k];
        count[k] = y > x ? gi_link_blocks(t, theta, x, y, CountOnly{}) : 0;
    }
};

// Link entry k's parts, from at[k] on.
struct FillPartsOf {
    GiTree t;
    float theta;
    const uint64_t* at;
    uint64_t* key;
    double* w;
    uint32_t* node;
    __device__ void operator()(uint64_t k) const {
        const int32_t x = owner_of(t, k), y = t.links[k];
        if (y > x) gi_link_blocks(t, theta, x, y, FillParts{key, w, node, at[k], uint32_t(x)});
    }
};

// Block s's weight: its parts in sorted order (stable: link-end order, then the walk's), summed
// per link end, then the link ends' sums added in order, as the CPU's cpu_blocks does.
struct SumBlocks {
    const uint64_t* start;
    const uint32_t *len, *order;
    const double* w;
    const uint32_t* node;
    double* out;
    __device__ void operator()(uint64_t s) const {
        double total = 0, part = 0;
        uint32_t x = node[order[start[s]]];
        for (uint64_t e = start[s]; e < start[s] + len[s]; ++e) {
            const uint32_t j = order[e];
            if (node[j] != x) total += part, part = 0, x = node[j];
            part += w[j];
        }
        out[s] = total + part;
    }
};

// Both interactions of block s as (receiver << 32 | source, F); kNoKey for an element of no area.
struct Interactions {
    GiTree t;
    const uint64_t* key;
    const double* w;
    uint64_t* ikey;
    float* icoef;
    __device__ void operator()(uint64_t s) const {
        const uint32_t e1 = uint32_t(key[s] >> 32), e2 = uint32_t(key[s]);
        const uint32_t N = uint32_t(t.num_nodes);
        const double a1 = e1 < N ? double(t.geom[e1].area) : double(t.area[e1 - N]);
        const double a2 = e2 < N ? double(t.geom[e2].area) : double(t.area[e2 - N]);
        if (!(a1 > 0) || !(a2 > 0)) {
            ikey[2 * s] = ikey[2 * s + 1] = kNoKey;
            icoef[2 * s] = icoef[2 * s + 1] = 0;
            return;
        }
        const double f1 = w[s] / a1, f2 = w[s] / a2;  // as std::min(1.0, f) on the host
        ikey[2 * s] = (uint64_t(e1) << 32) | e2, icoef[2 * s] = float(f1 < 1.0 ? f1 : 1.0);
        ikey[2 * s + 1] = (uint64_t(e2) << 32) | e1, icoef[2 * s + 1] = float(f2 < 1.0 ? f2 : 1.0);
    }
};

// row[e] = the first sorted interaction of receiver e (e = num_el: the number of interactions)
// and src[e] = the source of sorted interaction e, for e < max(n, num_el + 1).
struct Rows {
    const uint64_t* ikey;
    uint64_t n, num_el;
    uint64_t* row;
    uint32_t* src;
    __device__ void operator()(uint64_t e) const {
        if (e < n && ikey[e] != kNoKey) src[e] = uint32_t(ikey[e]);
        if (e > num_el) return;
        const uint64_t want = e << 32;
        uint64_t lo = 0, hi = n;
        while (lo < hi) {
            const uint64_t mid = lo + (hi - lo) / 2;
            if (ikey[mid] < want)
                lo = mid + 1;
            else
                hi = mid;
        }
        row[e] = lo;
    }
};

// ---- final gather
// Point k of the list (or point k when there is none).
struct FinalGather {
    GiGatherView v;
    const uint32_t* points;
    Vec3* out;
    __device__ void operator()(uint64_t k) const {
        out[k] = gi_final_gather_point(v, points ? points[k] : uint32_t(k));
    }
};

struct Iota {
    uint32_t* a;
    __device__ void operator()(uint64_t k) const { a[k] = uint32_t(k); }
};

// cub's two-call pattern: size, then run.
template <class F>
void with_temp(F&& f) {
    size_t bytes = 0;
    VMAP_CUDA_CHECK(f(nullptr, bytes));
    DevBuf<uint8_t> tmp(bytes);
    VMAP_CUDA_CHECK(f(tmp.p, bytes));
}

// Sorts (key, value) pairs by key, stably; the result is left in key/value.
template <class V>
void sort_pairs(DevBuf<uint64_t>& key, DevBuf<V>& value, uint64_t n) {
    DevBuf<uint64_t> key2(n);
    DevBuf<V> value2(n);
    cub::DoubleBuffer<uint64_t> k(key.p, key2.p);
    cub::DoubleBuffer<V> v(value.p, value2.p);
    with_temp([&](void* t, size_t& b) {
        return cub::DeviceRadixSort::SortPairs(t, b, k, v, int64_t(n));
    });
    if (k.Current() != key.p) std::swap(key, key2);
    if (v.Current() != value.p) std::swap(value, value2);
}

class CudaGi final : public GiDevice {
  public:
    explicit CudaGi(std::string name) : name_(std::move(name)) {}
    std::string name() const override { return name_; }

    void upload_tree(const GiTree& h, const uint8_t* emits) override;
    void refine_blocks(float theta, const std::function<void(uint64_t)>& check_total,
                       HugeVector<uint64_t>& row, HugeVector<uint32_t>& src,
                       HugeVector<float>& coef) override;
    void upload(const GiView& h, uint64_t num_interactions) override;
    void set_radiosity(const Vec3* B) override {
        B_.from(B, elements_);
        d_.B = B_.p;
    }
    void bounce() override {
        parallel_for_device(elements_, Gather{d_});
        parallel_for_device(d_.num_points, PointUpdate{d_});
        parallel_for_device(uint64_t(d_.num_nodes), PullUp{d_});
        check_launch();
    }
    void download_radiosity(Vec3* B) const override { B_.to(B, elements_); }
    void final_gather(float theta, const uint32_t* points, size_t n, bool listed,
                      Vec3* out) override;

  private:
    // Blocks (sorted keys, weights) of every link.
    void make_blocks(float theta, DevBuf<uint64_t>& key, DevBuf<double>& w);

    std::string name_;
    bool has_tree_ = false, has_csr_ = false;
    uint64_t link_entries_ = 0, elements_ = 0;
    GiTree t_;
    GiView d_;
    DevBuf<int32_t> skip_, leaf_, parent_, point_leaf_, links_;
    DevBuf<uint32_t> pb_, pe_, src_;
    DevBuf<uint64_t> offsets_, row_;
    DevBuf<NodeGeom> geom_;
    DevBuf<Vec3> pos_, nrm_, emission_, albedo_, B_, G_;
    DevBuf<float> area_, coef_, inv_area_;
    DevBuf<uint8_t> emits_;
};

void CudaGi::upload_tree(const GiTree& h, const uint8_t* emits) {
    if (has_tree_) return;
    const uint64_t N = uint64_t(h.num_nodes), P = h.num_points;
    link_entries_ = h.link_offsets[N];
    t_ = h;
    skip_.from(h.skip, N), t_.skip = skip_.p;
    leaf_.from(h.node_leaf, N), t_.node_leaf = leaf_.p;
    parent_.from(h.parent, N), t_.parent = parent_.p;
    pb_.from(h.point_begin, N), t_.point_begin = pb_.p;
    pe_.from(h.point_end, N), t_.point_end = pe_.p;
    geom_.from(h.geom, N), t_.geom = geom_.p;
    pos_.from(h.position, P), t_.position = pos_.p;
    nrm_.from(h.normal, P), t_.normal = nrm_.p;
    area_.from(h.area, P), t_.area = area_.p;
    point_leaf_.from(h.point_leaf, P), t_.point_leaf = point_leaf_.p;
    offsets_.from(h.link_offsets, N + 1), t_.link_offsets = offsets_.p;
    links_.from(h.links, link_entries_), t_.links = links_.p;
    emits_.from(emits, N);
    has_tree_ = true;
}

void CudaGi::make_blocks(float theta, DevBuf<uint64_t>& key, DevBuf<double>& w) {
    const uint64_t L = link_entries_;
    DevBuf<uint64_t> at(L + 1);
    VMAP_CUDA_CHECK(cudaMemset(at.p + L, 0, sizeof(uint64_t)));
    parallel_for_device(L, CountParts{t_, theta, at.p});
    check_launch();
    DevBuf<uint64_t> first(L + 1);
    with_temp([&](void* t, size_t& b) {
        return cub::DeviceScan::ExclusiveSum(t, b, at.p, first.p, int64_t(L + 1));
    });
    at = std::move(first);
    const uint64_t M = read_one(at.p + L);
    if (M >= (uint64_t(1) << 32))
        throw Error("gi: the refinement has " + std::to_string(M) + " parts, too many for the GPU");
    DevBuf<uint64_t> pkey(M);
    DevBuf<double> pw(M);
    DevBuf<uint32_t> pnode(M), order(M);
    parallel_for_device(L, FillPartsOf{t_, theta, at.p, pkey.p, pw.p, pnode.p});
    parallel_for_device(M, Iota{order.p});
    check_launch();
    at = DevBuf<uint64_t>();
    sort_pairs(pkey, order, M);
    DevBuf<uint64_t> ukey(M), start(M + 1);
    DevBuf<uint32_t> len(M);
    DevBuf<int64_t> runs(1);
    with_temp([&](void* t, size_t& b) {
        return cub::DeviceRunLengthEncode::Encode(t, b, pkey.p, ukey.p, len.p, runs.p, int64_t(M));
    });
    const uint64_t nb = uint64_t(read_one(runs.p));
    with_temp([&](void* t, size_t& b) {
        return cub::DeviceScan::ExclusiveSum(t, b, len.p, start.p, int64_t(nb));
    });
    w = DevBuf<double>(nb);
    parallel_for_device(nb, SumBlocks{start.p, len.p, order.p, pw.p, pnode.p, w.p});
    check_launch();
    key = std::move(ukey);
    key.n = nb;
}

void CudaGi::refine_blocks(float theta, const std::function<void(uint64_t)>& check_total,
                           HugeVector<uint64_t>& row, HugeVector<uint32_t>& src,
                           HugeVector<float>& coef) {
    DevBuf<uint64_t> key;
    DevBuf<double> w;
    make_blocks(theta, key, w);
    const uint64_t nb = key.n, n = 2 * nb;
    DevBuf<uint64_t> ikey(n);
    DevBuf<float> icoef(n);
    parallel_for_device(nb, Interactions{t_, key.p, w.p, ikey.p, icoef.p});
    check_launch();
    key = DevBuf<uint64_t>(), w = DevBuf<double>();
    sort_pairs(ikey, icoef, n);
    const uint64_t num_el = uint64_t(t_.num_nodes) + t_.num_points;
    row_ = DevBuf<uint64_t>(num_el + 1);
    src_ = DevBuf<uint32_t>(n);
    parallel_for_device(std::max(n, num_el + 1), Rows{ikey.p, n, num_el, row_.p, src_.p});
    check_launch();
    const uint64_t total = read_one(row_.p + num_el);
    check_total(total);
    coef_ = std::move(icoef);
    row.resize(num_el + 1), src.resize(total), coef.resize(total);
    row_.to(row.data(), num_el + 1);
    src_.to(src.data(), total);
    coef_.to(coef.data(), total);
    has_csr_ = true;
}

void CudaGi::upload(const GiView& h, uint64_t num_interactions) {
    const uint64_t N = uint64_t(h.num_nodes), P = h.num_points, E = N + P;
    d_ = h;
    if (!has_csr_) {
        row_.from(h.row, E + 1);
        src_.from(h.src, num_interactions);
        coef_.from(h.coef, num_interactions);
        has_csr_ = true;
    }
    d_.row = row_.p, d_.src = src_.p, d_.coef = coef_.p;
    emission_.from(h.emission, P), d_.emission = emission_.p;
    albedo_.from(h.albedo, P), d_.albedo = albedo_.p;
    d_.area = area_.p, d_.point_leaf = point_leaf_.p, d_.parent = parent_.p;
    d_.point_begin = pb_.p, d_.point_end = pe_.p;
    inv_area_.from(h.inv_area, N), d_.inv_area = inv_area_.p;
    elements_ = E;
    B_.from(h.B, E), d_.B = B_.p;
    G_.from(h.G, E), d_.G = G_.p;
}

void CudaGi::final_gather(float theta, const uint32_t* points, size_t n, bool listed, Vec3* out) {
    DevBuf<uint32_t> pts;
    if (listed) pts.from(points, n);
    DevBuf<Vec3> res(n);
    const GiGatherView v{t_, B_.p, emits_.p, emission_.p, albedo_.p, theta};
    parallel_for_device(n, FinalGather{v, listed ? pts.p : nullptr, res.p});
    check_launch();
    res.to(out, n);
}

}  // namespace

std::unique_ptr<GiDevice> make_gi_cuda(std::string* why) {
    const std::optional<std::string> name = cuda_device(why);
    if (!name) return nullptr;
    return std::make_unique<CudaGi>("cuda (" + *name + ")");
}

}  // namespace vmap::detail
