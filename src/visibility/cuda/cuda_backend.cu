// Leaf-pair visibility on a CUDA GPU (paper §4.3: the GPU fills the leaf visibility status table
// while the host extracts links). The predicate is leaf_pair.h, the same code the CPU runs.
//
// Work decomposition: the leaf pairs of a batch are numbered across its jobs (row by row inside
// a job), whatever the jobs' shapes (locate_pair); a warp takes a chunk of consecutive ones,
// keeps those that face, and walks them 32 at a time, a lane per pair. Neighbouring lanes walk
// nearly the same segment, so the warp walks the tree once for all 32
// (leaf_pairs_packet_kernel, the default). The per-lane walk of leaf_pair.h
// (leaf_pairs_kernel, VMAP_CUDA_VARIANT=lane) is kept as the on-device oracle: the GPU tests
// check that both give the same bits and counts. The node-pair tests of the construction's
// frontier (node_pair.h, decide_kernel) run here too, one thread a node pair.
#include <cuda_runtime.h>

#include <algorithm>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <string>
#include <type_traits>
#include <vector>

#include "octree/records.h"
#include "util/cuda_check.h"
#include "util/device.h"
#include "visibility/backend.h"
#include "visibility/leaf_pair.h"
#include "visibility/node_pair.h"
#include "vmap/error.h"

namespace vmap::detail {
namespace {

struct DeviceCounters {
    unsigned long long pairs, facing_pairs, visible_pairs, node_tests, occluder_tests;
    unsigned long long next_chunk;  // the packet kernel's next chunk of pairs
};

constexpr int kWarpsPerBlock = 8;

// Per-thread work counts; 32 bits suffice between the per-item flushes below.
struct SmallCounters {
    uint32_t pairs = 0, facing_pairs = 0, visible_pairs = 0, node_tests = 0, occluder_tests = 0;
};

// Where a leaf pair of the batch lies: pairs are numbered across the batch's jobs, row by row
// inside a job (first[j] is the number of pairs before job j), so a warp takes 32 consecutive
// pairs whatever the jobs' shapes: a job of 3 x 5 leaf pairs fills 15 lanes and the next job
// the rest, where one row per warp would leave 27 of 32 lanes idle on it (issue 15). The pairs
// of a job are neighbours in space, and so are consecutive jobs (children of one pair), so the
// 32 segments still form a thin bundle for the packet walk.
struct PairPos {
    int32_t a = 0, b = 0;  // the leaves (a == b when the lane has no pair)
    bool in = false;
    uint64_t word = ~0ull;  // the bit's word in the batch's table
    uint32_t bit = 0;
};
__device__ inline PairPos locate_pair(const PairJob* jobs, const uint64_t* first, int32_t num_jobs,
                                      uint64_t pair, uint64_t num_pairs) {
    PairPos at;
    if (pair >= num_pairs) return at;
    int32_t lo = 0, hi = num_jobs;
    while (hi - lo > 1) {
        const int32_t mid = (lo + hi) >> 1;
        if (first[mid] <= pair)
            lo = mid;
        else
            hi = mid;
    }
    const PairJob job = jobs[lo];
    const uint64_t local = pair - first[lo];
    const int32_t r = int32_t(local / uint64_t(job.cols)), c = int32_t(local % uint64_t(job.cols));
    at.a = job.row0 + r;
    at.b = job.col0 + c;
    at.in = true;
    at.word = job.word_offset + uint64_t(r) * ((uint64_t(job.cols) + 31) / 32) + uint64_t(c / 32);
    at.bit = 1u << (c % 32);
    return at;
}

// The warp's answers into the table (zeroed before the kernel): the lanes of one word OR their
// bits together and one of them stores them; a word split between two warps (a row that ends
// mid-warp) is ORed by both, hence the atomic.
__device__ inline void store_bits(const PairPos& at, bool vis, uint32_t* bits) {
    const unsigned peers = __match_any_sync(0xffffffffu, at.word);
    const unsigned v = __reduce_or_sync(peers, vis ? at.bit : 0u);
    const int lane = threadIdx.x & 31;
    if (at.in && v && lane == __ffs(peers) - 1) atomicOr(bits + at.word, v);
}

// Warp-reduces the counters; one atomic per warp and counter.
__device__ inline void flush_counters(const SmallCounters& wc, int lane, DeviceCounters* out) {
    unsigned long long v[5] = {wc.pairs, wc.facing_pairs, wc.visible_pairs, wc.node_tests,
                               wc.occluder_tests};
#pragma unroll
    for (int k = 0; k < 5; ++k)
        for (int o = 16; o > 0; o >>= 1) v[k] += __shfl_down_sync(0xffffffffu, v[k], o);
    if (lane == 0) {
        atomicAdd(&out->pairs, v[0]);
        atomicAdd(&out->facing_pairs, v[1]);
        atomicAdd(&out->visible_pairs, v[2]);
        atomicAdd(&out->node_tests, v[3]);
        atomicAdd(&out->occluder_tests, v[4]);
    }
}

// One lane, one pair: leaf_pair_visible as the CPU runs it (the on-device oracle).
__global__ void __launch_bounds__(kWarpsPerBlock * 32)
    leaf_pairs_kernel(OctreeView t, VisibilityParams vp, const PairJob* __restrict__ jobs,
                      const uint64_t* __restrict__ first, int32_t num_jobs, uint64_t num_pairs,
                      uint32_t* __restrict__ bits, DeviceCounters* counters) {
    const int lane = threadIdx.x & 31;
    const uint64_t warp = (uint64_t(blockIdx.x) * blockDim.x + threadIdx.x) >> 5;
    const uint64_t warps = (uint64_t(gridDim.x) * blockDim.x) >> 5;
    SmallCounters wc;
    for (uint64_t w = warp; w * 32 < num_pairs; w += warps) {
        const PairPos at = locate_pair(jobs, first, num_jobs, w * 32 + lane, num_pairs);
        bool vis = false;
        if (at.in) {
            vis = leaf_pair_visible<true>(t, at.a, at.b, vp, &wc);
            wc.pairs++;
        }
        store_bits(at, vis, bits);
        wc.visible_pairs += vis;
    }
    // (A thread sees at most a few thousand warps of 32 pairs and ~100 node tests a pair:
    // far below 2^32.)
    flush_counters(wc, lane, counters);
}

// The same walk for a warp's 32 lanes as a packet. The lanes hold neighbouring leaf pairs, so
// their segments form a thin bundle. The warp walks the preorder tree once, entering a node
// when any lane's own walk would enter it; node and leaf records are then warp-uniform loads
// (one broadcast instead of 32 gathers). Each lane tests only the nodes on its own path
// (n >= resume: it has not skipped past the node's subtree), so it makes exactly the tests,
// counts and answer of leaf_pair_visible, from the same pieces (pair_segment, slab_meets_box,
// occluder_reached), whichever pairs share the warp. `faces`: the lane's pair faces
// (pair_faces, computed by the caller); a lane without a pair or whose pair does not face
// only takes part in the warp's votes.
// The box test: where no walking lane's direction has a component under 1e-30 in magnitude
// (all but segments that lie in an axis plane), the warp walks with slab_meets_box_regular,
// without slab_meets_box's three per-axis checks at every node test: the kernel 15% faster on
// the dragon at lp 4 and 1 (H100, docs/results.md "The box test without its per-axis checks");
// otherwise with slab_meets_box itself.
__device__ inline void walk_packet(const OctreeView& t, const VisibilityParams& vp,
                                   const PairPos& at, bool faces, uint32_t* bits,
                                   SmallCounters& wc) {
    const int32_t a = at.in ? at.a : 0, b = at.in ? at.b : 0;
    const PairSegment s = pair_segment(t.leaves[a], t.leaves[b], vp, faces);
    bool vis = at.in && s.faces;
    int occluders = 0;
    int32_t resume = 0;  // this lane's own walk skipped everything below this index
    // One vote a node (does any lane enter it?); whether any lane is still visible changes only
    // where a lane tests an occluder, so it is voted on there (two votes a node before: the
    // kernel 8% slower on the dragon, H100).
    bool any_vis = __any_sync(0xffffffffu, vis);
    auto walk = [&](auto regular) {
        int32_t n = 0;
        while (n < t.num_nodes && any_vis) {
            const WalkNode w = load_walk(t.walk + n);
            bool hit = false;
            if (vis && n >= resume) {
                wc.node_tests++;
                if constexpr (decltype(regular)::value)
                    hit = slab_meets_box_regular(s.ray, Box{w.lo, w.hi});
                else
                    hit = slab_meets_box(s.ray, Box{w.lo, w.hi}, 0.f);
                if (!hit) resume = w.skip;
            }
            const bool any_hit = __any_sync(0xffffffffu, hit);
            if (any_hit && w.leaf >= 0) {
                if (hit && occluder_reached<true>(t, s, w.leaf, a, b, vp, occluders, &wc))
                    vis = false;
                any_vis = __any_sync(0xffffffffu, vis);
            }
            n = any_hit ? n + 1 : w.skip;
        }
    };
    if (__all_sync(0xffffffffu, !(vis && has_tiny_component(s.ray.d))))
        walk(std::true_type{});
    else
        walk(std::false_type{});
    store_bits(at, vis, bits);
    wc.visible_pairs += vis;
}

// The packet walk over facing pairs only (the default kernel). A lane whose pair does not face
// idles through its warp's whole walk, and a third of the pairs the construction walks do not
// face (curved nodes, nodes holding two walls). So a warp takes a chunk of consecutive pairs
// (handed out by an atomic counter, for balance), runs the facing test on them 32 at a time,
// and queues the facing ones in shared memory in their order; each time 32 are queued it
// walks them as a packet. The queue's pairs are still neighbours (a chunk's pairs are
// consecutive), so the bundle stays thin; what is left of the queue at a chunk's end is walked
// as a partial packet rather than mixed with a distant chunk. The table starts zeroed, so the
// pairs that do not face need no store. Answers and counts are leaf_pair_visible's.
constexpr int kQueue = 64;  // a warp's queue: fewer than 32 left over plus 32 new
// Four blocks an SM (32 warps) cap the walk at 64 registers (a few bytes spilled); without the
// cap it took 76 and ran three blocks (24 warps). The walk waits on each node's load, so
// warps in flight pay: the kernel 21% faster on the dragon at lp 1 and 4 (H100); five blocks
// (48 registers) spill 240 bytes and lose 7% again (docs/results.md, "Registers and votes in
// the GPU's packet walk").
constexpr int kPacketBlocksPerSm = 4;
__global__ void __launch_bounds__(kWarpsPerBlock * 32, kPacketBlocksPerSm)
    leaf_pairs_packet_kernel(OctreeView t, VisibilityParams vp, const PairJob* __restrict__ jobs,
                             const uint64_t* __restrict__ first, int32_t num_jobs,
                             uint64_t num_pairs, uint64_t chunk_pairs,
                             uint32_t* __restrict__ bits, DeviceCounters* counters) {
    __shared__ uint64_t queues[kWarpsPerBlock][kQueue];
    const int lane = threadIdx.x & 31;
    uint64_t* queue = queues[threadIdx.x >> 5];
    const unsigned below = (1u << lane) - 1u;
    const uint64_t chunks = (num_pairs + chunk_pairs - 1) / chunk_pairs;
    SmallCounters wc;
    auto walk_queued = [&](int count) {  // the first `count` (<= 32) queued pairs
        const uint64_t pair = lane < count ? queue[lane] : num_pairs;
        __syncwarp();
        const PairPos at = locate_pair(jobs, first, num_jobs, pair, num_pairs);
        walk_packet(t, vp, at, at.in, bits, wc);
    };
    for (;;) {
        unsigned long long chunk = 0;
        if (lane == 0) chunk = atomicAdd(&counters->next_chunk, 1ull);
        chunk = __shfl_sync(0xffffffffu, chunk, 0);
        if (chunk >= chunks) break;
        const uint64_t begin = chunk * chunk_pairs;
        const uint64_t end = begin + chunk_pairs < num_pairs ? begin + chunk_pairs : num_pairs;
        int queued = 0;
        for (uint64_t base = begin; base < end; base += 32) {
            const uint64_t pair = base + uint64_t(lane);
            const PairPos at = locate_pair(jobs, first, num_jobs, pair, end);
            const bool faces = at.in && pair_faces(t.leaves[at.a], t.leaves[at.b], vp);
            wc.pairs += at.in;
            wc.facing_pairs += faces;
            const unsigned m = __ballot_sync(0xffffffffu, faces);
            if (faces) queue[queued + __popc(m & below)] = pair;
            queued += __popc(m);
            __syncwarp();
            if (queued >= 32) {
                walk_queued(32);
                queued -= 32;
                const uint64_t rest = lane < queued ? queue[32 + lane] : 0;
                __syncwarp();
                if (lane < queued) queue[lane] = rest;
                __syncwarp();
            }
        }
        if (queued > 0) walk_queued(queued);
        __syncwarp();
    }
    flush_counters(wc, lane, counters);
}

// How many consecutive pairs a warp's chunk holds: up to 512 (a tail of fewer than 32 queued
// pairs per chunk walks as a partial packet), fewer for a small batch so that its chunks still
// fill the GPU (32 warps per SM).
inline uint64_t chunk_pairs_for(uint64_t pairs, int sms) {
    const uint64_t fill = pairs / (uint64_t(sms) * 32);
    return std::clamp<uint64_t>(fill / 32 * 32, 32, 512);
}

// Node-pair decisions (node_pair.h), one thread a pair (those worth_deciding; the others stay
// undecided): the host's decide_node_pair on the device (the same double arithmetic, no contraction: the same decisions bit for bit).
struct ShaftCounters {
    unsigned long long shaft_node_tests = 0;
};
// Four blocks of 128 an SM cap the node tests at 128 registers (154 without; 3 blocks).
__global__ void __launch_bounds__(128, 4)
    decide_kernel(NodePairContext c, const NodePairRef* __restrict__ pairs, uint64_t n,
                  uint8_t* __restrict__ out, unsigned long long* shaft_node_tests) {
    const uint64_t i = uint64_t(blockIdx.x) * blockDim.x + threadIdx.x;
    ShaftCounters wc;
    if (i < n) {
        const NodePairRef p = pairs[i];
        out[i] = uint8_t(worth_deciding(c, p.a, p.b) ? decide_node_pair(c, p.a, p.b, &wc)
                                                     : PairDecision::kUndecided);
    }
    unsigned long long v = wc.shaft_node_tests;
    for (int o = 16; o > 0; o >>= 1) v += __shfl_down_sync(0xffffffffu, v, o);
    if ((threadIdx.x & 31) == 0 && v) atomicAdd(shaft_node_tests, v);
}

template <class T>
struct DeviceBuffer {
    T* ptr = nullptr;
    size_t n = 0;
    ~DeviceBuffer() {
        if (ptr) cudaFree(ptr);
    }
    void reserve(size_t count, uint64_t& held, uint64_t& peak) {
        if (count <= n) return;
        if (ptr) {
            VMAP_CUDA_CHECK(cudaFree(ptr));
            held -= n * sizeof(T);
        }
        ptr = nullptr;
        n = 0;
        VMAP_CUDA_CHECK(cudaMalloc(&ptr, count * sizeof(T)));
        n = count;
        held += n * sizeof(T);
        peak = std::max(peak, held);
    }
    void upload(const T* src, size_t count, cudaStream_t s, uint64_t& held, uint64_t& peak) {
        reserve(count, held, peak);
        VMAP_CUDA_CHECK(cudaMemcpyAsync(ptr, src, count * sizeof(T), cudaMemcpyHostToDevice, s));
    }
};

template <class T>
struct PinnedBuffer {
    T* ptr = nullptr;
    size_t n = 0;
    ~PinnedBuffer() {
        if (ptr) cudaFreeHost(ptr);
    }
    void reserve(size_t count) {
        if (count <= n) return;
        if (ptr) VMAP_CUDA_CHECK(cudaFreeHost(ptr));
        ptr = nullptr;
        n = 0;
        VMAP_CUDA_CHECK(cudaMallocHost(&ptr, count * sizeof(T)));
        n = count;
    }
};

// What the lanes of one build share (Backend::lane): the tree and node bounds on the device,
// the event kernel times are measured from, and the kernels' intervals (the busy time is their
// union over all lanes, which run kernels at the same time on their own streams).
struct DeviceShared {
    DeviceBuffer<WalkNode> walk;
    DeviceBuffer<LeafDisc> leaves;
    DeviceBuffer<NodeBounds> nb;
    DeviceBuffer<NormalCone> cones;
    DeviceBuffer<int32_t> skip;
    DeviceBuffer<int32_t> index;  // per node: its bounds in nb (-1 for a leaf)
    cudaEvent_t origin = nullptr;  // recorded in prepare(): kernel times are measured from it
    std::mutex m;
    std::vector<std::pair<double, double>> busy;  // kernel intervals, ms after origin
    ~DeviceShared() {
        if (origin) cudaEventDestroy(origin);
    }
    double busy_seconds() {
        std::lock_guard<std::mutex> lock(m);
        std::vector<std::pair<double, double>> iv = busy;
        std::sort(iv.begin(), iv.end());
        double sum = 0, end = -1e300;
        for (const auto& [a, b] : iv) {
            if (b > end) sum += b - std::max(a, end);
            end = std::max(end, b);
        }
        return sum * 1e-3;
    }
};

class CudaBackend final : public Backend {
  public:
    explicit CudaBackend(int device) : device_(device), sh_(std::make_shared<DeviceShared>()) {
        try {
            init();
            VMAP_CUDA_CHECK(cudaEventCreate(&sh_->origin));
        } catch (...) {
            release();
            throw;
        }
    }
    // A lane of `lead` (Backend::lane): its own streams and batch buffers, the lead's tree.
    explicit CudaBackend(const CudaBackend& lead)
        : device_(lead.device_), sh_(lead.sh_), lanes_(lead.lanes_) {
        try {
            init();
        } catch (...) {
            release();
            throw;
        }
        variant_ = lead.variant_;
        vp_ = lead.vp_;
        view_ = lead.view_;
        have_ctx_ = lead.have_ctx_;
        ctx_ = lead.ctx_;
        if (have_ctx_) {
            d_shaft_.reserve(1, held_, peak_);
            h_shaft_.reserve(1);
        }
        std::lock_guard<std::mutex> lock(sh_->m);
        lanes_->push_back(this);
    }
    ~CudaBackend() override {
        release();
        std::lock_guard<std::mutex> lock(sh_->m);
        std::erase(*lanes_, this);
    }

  private:
    void init() {
        if (const char* v = getenv("VMAP_CUDA_VARIANT")) variant_ = v;
        if (!variant_.empty() && variant_ != "packet" && variant_ != "lane")
            throw Error("VMAP_CUDA_VARIANT: unknown kernel variant '" + variant_ +
                        "' (packet or lane)");
        VMAP_CUDA_CHECK(cudaSetDevice(device_));
        VMAP_CUDA_CHECK(cudaGetDeviceProperties(&prop_, device_));
        for (auto& s : slots_) {
            VMAP_CUDA_CHECK(cudaStreamCreateWithFlags(&s.stream, cudaStreamNonBlocking));
            VMAP_CUDA_CHECK(cudaEventCreateWithFlags(&s.done, cudaEventDisableTiming));
            VMAP_CUDA_CHECK(cudaEventCreate(&s.k0));
            VMAP_CUDA_CHECK(cudaEventCreate(&s.k1));
        }
    }
    // Destroys whatever streams and events exist (also after a failed init).
    void release() {
        for (auto& s : slots_) {
            if (s.stream) cudaStreamSynchronize(s.stream);
            if (s.done) cudaEventDestroy(s.done);
            if (s.k0) cudaEventDestroy(s.k0);
            if (s.k1) cudaEventDestroy(s.k1);
            if (s.stream) cudaStreamDestroy(s.stream);
            s.stream = nullptr;
            s.done = s.k0 = s.k1 = nullptr;
        }
    }

  public:
    std::string name() const override {
        // (fmt's compile-time format strings do not build under nvcc: plain strings here.)
        return std::string("cuda (") + prop_.name + ", " +
               std::to_string(prop_.multiProcessorCount) + " SMs)";
    }

    void prepare(const Octree& tree, const VisibilityParams& vp, uint64_t) override {
        vp_ = vp;
        cudaStream_t s = slots_[0].stream;
        sh_->walk.upload(walk_nodes(tree).data(), walk_nodes(tree).size(), s, held_, peak_);
        sh_->leaves.upload(leaf_discs(tree).data(), leaf_discs(tree).size(), s, held_, peak_);
        VMAP_CUDA_CHECK(cudaEventRecord(sh_->origin, s));
        sh_->busy.clear();
        VMAP_CUDA_CHECK(cudaStreamSynchronize(s));
        view_ = OctreeView{sh_->walk.ptr, sh_->leaves.ptr, tree.num_nodes(), tree.num_leaves()};
    }

    void submit(std::span<const PairJob> jobs, uint64_t words, int slot) override {
        // A lane runs on a thread of its own, whose current device starts at 0.
        VMAP_CUDA_CHECK(cudaSetDevice(device_));
        Slot& sl = slots_[slot];
        // The previous batch in this slot has been waited for; its buffers may be reused.
        const size_t nj = jobs.size();
        sl.h_jobs.reserve(nj);
        sl.h_first.reserve(nj + 1);
        std::copy(jobs.begin(), jobs.end(), sl.h_jobs.ptr);
        sl.h_first.ptr[0] = 0;
        for (size_t i = 0; i < nj; ++i)
            sl.h_first.ptr[i + 1] = sl.h_first.ptr[i] + uint64_t(jobs[i].rows) * jobs[i].cols;
        const uint64_t pairs = sl.h_first.ptr[nj];
        sl.d_jobs.upload(sl.h_jobs.ptr, nj, sl.stream, held_, peak_);
        sl.d_first.upload(sl.h_first.ptr, nj + 1, sl.stream, held_, peak_);
        sl.d_bits.reserve(std::max<uint64_t>(words, 1), held_, peak_);
        sl.d_counters.reserve(1, held_, peak_);
        sl.h_bits.reserve(std::max<uint64_t>(words, 1));
        sl.h_counters.reserve(1);
        VMAP_CUDA_CHECK(cudaMemsetAsync(sl.d_counters.ptr, 0, sizeof(DeviceCounters), sl.stream));
        VMAP_CUDA_CHECK(cudaMemsetAsync(sl.d_bits.ptr, 0, words * sizeof(uint32_t), sl.stream));
        VMAP_CUDA_CHECK(cudaEventRecord(sl.k0, sl.stream));
        if (pairs > 0) {
            const int threads = kWarpsPerBlock * 32;
            const int sms = prop_.multiProcessorCount;
            // VMAP_CUDA_VARIANT=lane runs the per-lane walk (the on-device oracle; same answers)
            // instead of the default packet walk.
            if (variant_ == "lane") {
                const uint64_t warps = (pairs + 31) / 32;
                const uint64_t want = (warps + kWarpsPerBlock - 1) / kWarpsPerBlock;
                const int blocks = int(std::min<uint64_t>(want, uint64_t(sms) * 64));
                leaf_pairs_kernel<<<blocks, threads, 0, sl.stream>>>(
                    view_, vp_, sl.d_jobs.ptr, sl.d_first.ptr, int32_t(nj), pairs, sl.d_bits.ptr,
                    sl.d_counters.ptr);
            } else {
                // Warps take chunks from a counter: enough blocks to fill every SM, no more
                // than there are chunks.
                const uint64_t chunk = chunk_pairs_for(pairs, sms);
                const uint64_t chunks = (pairs + chunk - 1) / chunk;
                const uint64_t want = (chunks + kWarpsPerBlock - 1) / kWarpsPerBlock;
                const int blocks = int(std::min<uint64_t>(want, uint64_t(sms) * 8));
                leaf_pairs_packet_kernel<<<blocks, threads, 0, sl.stream>>>(
                    view_, vp_, sl.d_jobs.ptr, sl.d_first.ptr, int32_t(nj), pairs, chunk,
                    sl.d_bits.ptr, sl.d_counters.ptr);
            }
            VMAP_CUDA_CHECK(cudaGetLastError());
        }
        VMAP_CUDA_CHECK(cudaEventRecord(sl.k1, sl.stream));
        VMAP_CUDA_CHECK(cudaMemcpyAsync(sl.h_bits.ptr, sl.d_bits.ptr, words * sizeof(uint32_t),
                                        cudaMemcpyDeviceToHost, sl.stream));
        VMAP_CUDA_CHECK(cudaMemcpyAsync(sl.h_counters.ptr, sl.d_counters.ptr,
                                        sizeof(DeviceCounters), cudaMemcpyDeviceToHost, sl.stream));
        VMAP_CUDA_CHECK(cudaEventRecord(sl.done, sl.stream));
    }

    const uint32_t* wait(int slot, WorkCounters& wc) override {
        Slot& sl = slots_[slot];
        VMAP_CUDA_CHECK(cudaEventSynchronize(sl.done));
        // Busy time is the union of the kernels' intervals: the two slots' kernels (and the
        // other lanes') can run at the same time, and summing their lengths would count that
        // more than once.
        float start = 0, end = 0;
        VMAP_CUDA_CHECK(cudaEventElapsedTime(&start, sh_->origin, sl.k0));
        VMAP_CUDA_CHECK(cudaEventElapsedTime(&end, sh_->origin, sl.k1));
        {
            std::lock_guard<std::mutex> lock(sh_->m);
            sh_->busy.emplace_back(double(start), double(end));
        }
        const DeviceCounters& c = *sl.h_counters.ptr;
        wc.pairs += c.pairs;
        wc.facing_pairs += c.facing_pairs;
        wc.visible_pairs += c.visible_pairs;
        wc.node_tests += c.node_tests;
        wc.occluder_tests += c.occluder_tests;
        return sl.h_bits.ptr;
    }

    // The node bounds go to the device once; decide() runs the node tests there.
    void set_node_context(const NodePairContext* ctx) override {
        have_ctx_ = ctx != nullptr && ctx->margin > 0;
        if (!have_ctx_) return;
        cudaStream_t s = slots_[0].stream;
        const int32_t nn = ctx->tree.num_nodes;
        const NodeBounds& last = ctx->nb[nn - 1];
        // Only the internal nodes' bounds travel (a leaf's are computed from its disc,
        // leaf_bounds), with each node's index among them.
        std::vector<NodeBounds> inner;
        std::vector<int32_t> index(size_t(nn), -1);
        for (int32_t n = 0; n < nn; ++n) {
            if (ctx->tree.walk[n].leaf >= 0) continue;
            index[n] = int32_t(inner.size());
            inner.push_back(ctx->nb[n]);
        }
        if (inner.empty()) inner.emplace_back();
        sh_->nb.upload(inner.data(), inner.size(), s, held_, peak_);
        sh_->index.upload(index.data(), index.size(), s, held_, peak_);
        const size_t num_cones = size_t(last.cone_begin) + last.cone_count;
        if (num_cones > 0)
            sh_->cones.upload(ctx->cones, num_cones, s, held_, peak_);
        else
            sh_->cones.reserve(1, held_, peak_);  // every leaf flagged: no cone is ever read
        sh_->skip.upload(ctx->skip, size_t(nn), s, held_, peak_);
        d_shaft_.reserve(1, held_, peak_);
        h_shaft_.reserve(1);
        VMAP_CUDA_CHECK(cudaStreamSynchronize(s));
        ctx_ = *ctx;
        ctx_.tree = view_;
        ctx_.nb = sh_->nb.ptr;
        ctx_.cones = sh_->cones.ptr;
        ctx_.skip = sh_->skip.ptr;
        ctx_.bounds_index = sh_->index.ptr;
        ctx_.leaves_stored = false;  // the device keeps the internal nodes' bounds only
    }

    bool decide(std::span<const NodePairRef> pairs, uint8_t* out,
                uint64_t* shaft_node_tests) override {
        if (!have_ctx_) return false;
        VMAP_CUDA_CHECK(cudaSetDevice(device_));
        const size_t n = pairs.size();
        if (n == 0) return true;
        // Called between batches (the builder has waited for every batch), so slot 0's stream
        // is idle.
        cudaStream_t s = slots_[0].stream;
        h_pairs_.reserve(n);
        h_dec_.reserve(n);
        std::copy(pairs.begin(), pairs.end(), h_pairs_.ptr);
        d_pairs_.upload(h_pairs_.ptr, n, s, held_, peak_);
        d_dec_.reserve(n, held_, peak_);
        VMAP_CUDA_CHECK(cudaMemsetAsync(d_shaft_.ptr, 0, sizeof(unsigned long long), s));
        const int threads = 128;
        decide_kernel<<<unsigned((n + threads - 1) / threads), threads, 0, s>>>(
            ctx_, d_pairs_.ptr, n, d_dec_.ptr, d_shaft_.ptr);
        VMAP_CUDA_CHECK(cudaGetLastError());
        VMAP_CUDA_CHECK(cudaMemcpyAsync(h_dec_.ptr, d_dec_.ptr, n, cudaMemcpyDeviceToHost, s));
        VMAP_CUDA_CHECK(cudaMemcpyAsync(h_shaft_.ptr, d_shaft_.ptr, sizeof(unsigned long long),
                                        cudaMemcpyDeviceToHost, s));
        VMAP_CUDA_CHECK(cudaStreamSynchronize(s));
        std::copy(h_dec_.ptr, h_dec_.ptr + n, out);
        *shaft_node_tests += *h_shaft_.ptr;
        return true;
    }

    std::unique_ptr<Backend> lane() override { return std::make_unique<CudaBackend>(*this); }
    // This backend's peak and its lanes' (alive), added: a bound on what they held at once.
    uint64_t peak_device_bytes() const override {
        std::lock_guard<std::mutex> lock(sh_->m);
        uint64_t p = peak_;
        for (const CudaBackend* l : *lanes_)
            if (l != this) p += l->peak_;
        return p;
    }
    double busy_seconds() const override { return sh_->busy_seconds(); }
    // The kernel on one H100 (docs/results.md); link extraction on the host adds to it.
    double expected_pairs_per_second() const override { return 2.5e9; }

  private:
    struct Slot {
        cudaStream_t stream = nullptr;
        cudaEvent_t done = nullptr;
        cudaEvent_t k0 = nullptr, k1 = nullptr;  // around the kernel, for busy_seconds
        PinnedBuffer<PairJob> h_jobs;
        PinnedBuffer<uint64_t> h_first;
        PinnedBuffer<uint32_t> h_bits;
        PinnedBuffer<DeviceCounters> h_counters;
        DeviceBuffer<PairJob> d_jobs;
        DeviceBuffer<uint64_t> d_first;
        DeviceBuffer<uint32_t> d_bits;
        DeviceBuffer<DeviceCounters> d_counters;
    };
    int device_;
    std::string variant_;  // "" = the default kernel (docs/gpu-notes.md)
    cudaDeviceProp prop_{};
    VisibilityParams vp_;
    OctreeView view_;
    std::shared_ptr<DeviceShared> sh_;
    // The lanes made from this backend (or from its lead), alive: for peak_device_bytes.
    std::shared_ptr<std::vector<const CudaBackend*>> lanes_ =
        std::make_shared<std::vector<const CudaBackend*>>();
    Slot slots_[2];
    // The node tests (set_node_context, decide).
    bool have_ctx_ = false;
    NodePairContext ctx_;  // with device pointers
    DeviceBuffer<NodePairRef> d_pairs_;
    DeviceBuffer<uint8_t> d_dec_;
    DeviceBuffer<unsigned long long> d_shaft_;
    PinnedBuffer<NodePairRef> h_pairs_;
    PinnedBuffer<uint8_t> h_dec_;
    PinnedBuffer<unsigned long long> h_shaft_;
    uint64_t held_ = 0, peak_ = 0;
};

}  // namespace

int cuda_device_count() {
    int count = 0;
    return cudaGetDeviceCount(&count) == cudaSuccess ? count : 0;
}

std::unique_ptr<Backend> make_cuda_backend(std::string* why, int device) {
    if (!cuda_device(why)) return nullptr;
    const int count = cuda_device_count();
    if (device < 0) device = 0;
    if (device >= count) {
        const char* vis = getenv("CUDA_VISIBLE_DEVICES");
        throw Error("device " + std::to_string(device) + ": " + std::to_string(count) +
                    " CUDA device(s) visible (0.." + std::to_string(count - 1) + ")" +
                    (vis ? std::string(", CUDA_VISIBLE_DEVICES=") + vis : std::string()));
    }
    // A device that is present but unusable (busy in exclusive mode, out of memory) is reported
    // like an absent one, so auto and cuda fall back to the CPU with the reason.
    try {
        return std::make_unique<CudaBackend>(device);
    } catch (const Error& e) {
        if (why) *why = e.what();
        return nullptr;
    }
}

}  // namespace vmap::detail
