// Link extraction and the per-node link arrays (links.h).
#include "vmap/links.h"
#include "vmap/map_access.h"

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cstdlib>
#include <memory>
#include <new>

#include "util/huge_array.h"
#include "vmap/error.h"

namespace vmap {
namespace detail {

// Set bits in rows [r0, r1) x cols [c0, c1), job-relative.
uint64_t Extractor::count(int32_t r0, int32_t r1, int32_t c0, int32_t c1) const {
    const uint64_t rw = row_words(job.cols);
    uint64_t n = 0;
    const int32_t w0 = c0 / 32, w1 = (c1 - 1) / 32;
    const uint32_t m0 = ~0u << (c0 % 32);
    const uint32_t m1 = ~0u >> (31 - (c1 - 1) % 32);
    for (int32_t r = r0; r < r1; ++r) {
        const uint32_t* row = bits + r * rw;
        if (w0 == w1) {
            n += __builtin_popcount(row[w0] & m0 & m1);
            continue;
        }
        n += __builtin_popcount(row[w0] & m0);
        for (int32_t w = w0 + 1; w < w1; ++w) n += __builtin_popcount(row[w]);
        n += __builtin_popcount(row[w1] & m1);
    }
    return n;
}

// Every set bit of rows [r0, r1) x cols [c0, c1) as a leaf-leaf link, row by row.
void Extractor::emit_bits(int32_t r0, int32_t r1, int32_t c0, int32_t c1) {
    const uint64_t rw = row_words(job.cols);
    const int32_t w0 = c0 / 32, w1 = (c1 - 1) / 32;
    LinkSink& out = sinks.local();
    for (int32_t r = r0; r < r1; ++r) {
        const uint32_t* row = bits + r * rw;
        const int32_t la = t.leaf_node()[job.row0 + r];
        for (int32_t w = w0; w <= w1; ++w) {
            uint32_t word = row[w];
            if (w == w0) word &= ~0u << (c0 % 32);
            if (w == w1) word &= ~0u >> (31 - (c1 - 1) % 32);
            while (word) {
                const int32_t c = w * 32 + __builtin_ctz(word);
                out.push(la, t.leaf_node()[job.col0 + c]);
                word &= word - 1;
            }
        }
    }
}

bool Extractor::run() {
    const uint64_t n = count(0, job.rows, 0, job.cols);
    if (n == uint64_t(job.rows) * uint64_t(job.cols)) return true;
    if (n > 0) split(job.a, job.b);
    return false;
}

void Extractor::resolve(int32_t a, int32_t b) {
    const int32_t r0 = t.leaf_begin()[a] - job.row0, r1 = t.leaf_end()[a] - job.row0;
    const int32_t c0 = t.leaf_begin()[b] - job.col0, c1 = t.leaf_end()[b] - job.col0;
    const uint64_t n = count(r0, r1, c0, c1);
    if (n == 0) return;  // nothing visible below either: no link anywhere under (a, b)
    if (n == uint64_t(r1 - r0) * uint64_t(c1 - c0)) {
        sinks.local().push(a, b);
        return;
    }
    split(a, b);
}

// (a, b) is partly visible: resolve the pairs it splits into.
void Extractor::split(int32_t a, int32_t b) {
    const int32_t r0 = t.leaf_begin()[a] - job.row0, r1 = t.leaf_end()[a] - job.row0;
    const int32_t c0 = t.leaf_begin()[b] - job.col0, c1 = t.leaf_end()[b] - job.col0;
    if (leafy[a] && leafy[b]) {
        // The split reaches leaf pairs at once: each visible one is a link of its own. Read
        // them off the table a word at a time (most links of a large V-map are made here).
        emit_bits(r0, r1, c0, c1);
        return;
    }
    std::array<std::pair<int32_t, int32_t>, 64> kids;
    int nk = 0;
    for_each_child_pair(t, a, b, [&](int32_t x, int32_t y) { kids[nk++] = {x, y}; });
    if (uint64_t(r1 - r0) * uint64_t(c1 - c0) > kParallelArea) {
        tbb::parallel_for(0, nk, [&](int k) { resolve(kids[k].first, kids[k].second); });
    } else {
        for (int k = 0; k < nk; ++k) resolve(kids[k].first, kids[k].second);
    }
}

namespace {

using Spans = std::vector<std::span<const Link>>;

// Blocks of at most 2^20 links, for the degree count.
Spans split_pieces(const Spans& pieces) {
    Spans tasks;
    for (auto sp : pieces)
        for (size_t i = 0; i < sp.size(); i += (1u << 20))
            tasks.push_back(sp.subspan(i, std::min<size_t>(1u << 20, sp.size() - i)));
    return tasks;
}

// The links of the pieces cut into `parts` runs of about equal length, each a list of spans:
// the scatter keeps a cursor per task and bucket, so it wants few tasks, not one per block.
std::vector<Spans> deal(const Spans& pieces, size_t parts) {
    size_t total = 0;
    for (auto sp : pieces) total += sp.size();
    const size_t each = std::max<size_t>(1, (total + parts - 1) / parts);
    std::vector<Spans> tasks(1);
    size_t room = each;
    for (auto sp : pieces) {
        while (!sp.empty()) {
            if (room == 0) tasks.emplace_back(), room = each;
            const size_t k = std::min(room, sp.size());
            tasks.back().push_back(sp.first(k));
            sp = sp.subspan(k);
            room -= k;
        }
    }
    return tasks;
}

// The nodes in runs (buckets) of at most kEnds link ends (a node with more is a bucket of its
// own), so that one bucket's ends sort in a core's cache, and of at most 2^(32 - tb) nodes for
// targets of tb bits, so that an end is one 32-bit key: (source in its bucket, target).
struct Buckets {
    static constexpr uint64_t kEnds = uint64_t(1) << 16;
    int tb;                      // bits of a target
    std::vector<uint32_t> of;    // per node, its bucket
    std::vector<int32_t> first;  // per bucket, its first node; then the number of nodes
    explicit Buckets(const std::vector<uint64_t>& offsets) : of(offsets.size() - 1) {
        const int32_t nn = int32_t(of.size());
        tb = std::bit_width(uint32_t(std::max(nn, 1) - 1));
        const int64_t max_nodes = int64_t(1) << (32 - tb);
        uint64_t ends = 0;
        for (int32_t n = 0; n < nn; ++n) {
            const uint64_t d = offsets[n + 1] - offsets[n];
            if (first.empty() || n - first.back() == max_nodes || (ends > 0 && ends + d > kEnds)) {
                first.push_back(n);
                ends = 0;
            }
            of[n] = uint32_t(first.size() - 1);
            ends += d;
        }
        first.push_back(nn);
    }
    size_t size() const { return first.size() - 1; }
    uint32_t key(int32_t s, int32_t t, uint32_t b) const {
        return (uint32_t(s - first[b]) << tb) | uint32_t(t);
    }
};

// Every link end as its key into its source's bucket, a contiguous range of `out` (the bucket's
// nodes' ranges). A first pass counts each task's ends per bucket, so that each task writes
// sub-ranges of its own: no atomics, and a few streams per task rather than a random place per
// end. The tasks are few (the cursors are tasks x buckets).
void scatter(const Buckets& bk, const std::vector<uint64_t>& off, const Spans& pieces,
             uint32_t* out) {
    const size_t nb = bk.size();
    const size_t cap = std::max<size_t>(1, (size_t(1) << 27) / std::max<size_t>(nb, 1));
    const auto tasks =
        deal(pieces, std::min(cap, 4 * size_t(tbb::this_task_arena::max_concurrency())));
    std::vector<uint64_t> cur(tasks.size() * nb, 0);
    tbb::parallel_for(size_t(0), tasks.size(), [&](size_t k) {
        uint64_t* c = cur.data() + k * nb;
        for (auto sp : tasks[k])
            for (auto [a, b] : sp) ++c[bk.of[a]], ++c[bk.of[b]];
    });
    std::atomic<bool> mismatch{false};
    tbb::parallel_for(size_t(0), nb, [&](size_t b) {
        uint64_t p = off[bk.first[b]];
        for (size_t k = 0; k < tasks.size(); ++k) p += std::exchange(cur[k * nb + b], p);
        if (p != off[bk.first[b + 1]]) mismatch = true;
    });
    // The ranges come from count(): other pieces would write outside them.
    if (mismatch) throw Error("link arrays: the pieces finished are not the pieces counted");
    tbb::parallel_for(size_t(0), tasks.size(), [&](size_t k) {
        uint64_t* c = cur.data() + k * nb;
        for (auto sp : tasks[k])
            for (auto [a, b] : sp) {
                const uint32_t ba = bk.of[a], bb = bk.of[b];
                out[c[ba]++] = bk.key(a, b, ba);
                out[c[bb]++] = bk.key(b, a, bb);
            }
    });
}

// Sorts keys[0, n) by their low `bits` bits (LSD radix, as few passes of at most kDigit bits as
// will do, with counts that stay in L1 for 2^13 digits; a digit the same in every key is
// skipped), tmp as room; returns where the sorted keys are.
uint32_t* radix_sort(uint32_t* keys, uint32_t* tmp, size_t n, int bits) {
    constexpr int kDigit = 13;
    const int passes = (bits + kDigit - 1) / kDigit;
    if (passes == 0) return keys;
    const int digit = (bits + passes - 1) / passes;
    const uint32_t mask = (uint32_t(1) << digit) - 1;
    std::array<uint32_t, size_t(1) << kDigit> cnt;
    for (int shift = 0; shift < bits; shift += digit) {
        std::fill(cnt.begin(), cnt.begin() + mask + 1, 0);
        for (size_t i = 0; i < n; ++i) ++cnt[(keys[i] >> shift) & mask];
        if (cnt[(keys[0] >> shift) & mask] == n) continue;
        uint32_t sum = 0;
        for (size_t d = 0; d <= mask; ++d) sum += std::exchange(cnt[d], sum);
        for (size_t i = 0; i < n; ++i) tmp[cnt[(keys[i] >> shift) & mask]++] = keys[i];
        std::swap(keys, tmp);
    }
    return keys;
}

// Each bucket's keys sorted (by source in the bucket, then target) and the targets written
// back: each node's range then holds its targets, sorted.
void sort_buckets(const Buckets& bk, const std::vector<uint64_t>& off, uint32_t* out) {
    tbb::enumerable_thread_specific<std::vector<uint32_t>> scratch;
    const uint32_t tmask = (uint64_t(1) << bk.tb) - 1;
    tbb::parallel_for(size_t(0), bk.size(), [&](size_t b) {
        uint32_t* k = out + off[bk.first[b]];
        const size_t n = off[bk.first[b + 1]] - off[bk.first[b]];
        uint32_t* sorted = k;
        if (n <= 64) {
            std::sort(k, k + n);
        } else {
            std::vector<uint32_t>& tmp = scratch.local();
            if (tmp.size() < n) tmp.resize(n);
            const int lb = std::bit_width(uint32_t(bk.first[b + 1] - bk.first[b] - 1));
            sorted = radix_sort(k, tmp.data(), n, bk.tb + lb);
        }
        for (size_t i = 0; i < n; ++i) k[i] = sorted[i] & tmask;
    });
}

}  // namespace

void LinkArrays::count(const Spans& pieces) {
    const auto tasks = split_pieces(pieces);
    std::atomic<bool> bad{false};
    tbb::parallel_for(size_t(0), tasks.size(), [&](size_t k) {
        std::vector<uint32_t>& ends = ends_.local();
        if (ends.empty()) ends.assign(size_t(nn_), 0);
        for (auto [a, b] : tasks[k]) {
            if (a < 0 || b < 0 || a >= nn_ || b >= nn_ || a == b) {
                bad = true;
                return;
            }
            ++ends[a], ++ends[b];
        }
    });
    if (bad)
        throw Error(
            fmt::format("a link is out of range ({} nodes) or joins a node to itself", nn_));
}

std::vector<uint64_t> LinkArrays::degrees() {
    std::vector<const uint32_t*> per_thread;
    for (const auto& e : ends_)
        if (!e.empty()) per_thread.push_back(e.data());
    std::vector<uint64_t> off(size_t(nn_) + 1, 0);
    tbb::parallel_for(tbb::blocked_range<int32_t>(0, nn_, 4096), [&](auto r) {
        for (const uint32_t* e : per_thread)
            for (int32_t n = r.begin(); n < r.end(); ++n) off[n + 1] += e[n];
    });
    for (int32_t n = 0; n < nn_; ++n) off[n + 1] += off[n];
    return off;
}

// Bucketed: every end goes into its source's bucket (a contiguous range of the output), then
// each bucket is sorted in cache. The result is each node's targets, sorted, whatever the
// order of the links and of the passes.
void LinkArrays::finish(VisibilityMap& vm, const Spans& pieces) {
    detail::MapData& d = detail::MapAccess::data(vm);
    d.link_offsets = degrees();
    const std::vector<uint64_t>& off = d.link_offsets;
    int32_t* out = detail::allocate_link_targets(d, off.back());  // uninitialised: written below
    const Buckets bk(off);
    // The keys live in the targets' own memory (a target is >= 0: its int32_t has the same bits).
    uint32_t* keys = reinterpret_cast<uint32_t*>(out);
    scatter(bk, off, pieces, keys);
    sort_buckets(bk, off, keys);
}

// Huge pages when large (util/huge_array.h): the arrays' writers scatter over gigabytes, where
// 4 KiB pages would cost a TLB miss and soon a page fault every few writes.
int32_t* allocate_link_targets(MapData& d, size_t n) {
    d.link_targets = std::shared_ptr<int32_t[]>(make_huge_array<int32_t>(n));
    d.num_link_targets = n;
    return d.link_targets.get();
}

std::vector<uint8_t> leafy_nodes(const Octree& t) {
    std::vector<uint8_t> leafy(t.num_nodes(), 1);
    tbb::parallel_for(int32_t(0), t.num_nodes(), [&](int32_t n) {
        if (!t.is_leaf(n)) t.for_each_child(n, [&](int32_t c) { leafy[n] &= t.is_leaf(c); });
    });
    return leafy;
}

}  // namespace detail

void set_links(VisibilityMap& vm, std::vector<std::pair<int32_t, int32_t>> pairs) {
    detail::LinkArrays la(vm.octree().num_nodes());
    const std::vector<std::span<const detail::Link>> one{std::span<const detail::Link>(pairs)};
    la.count(one);
    la.finish(vm, one);
}

}  // namespace vmap
