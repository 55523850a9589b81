// Link extraction and the per-node link arrays (links.h).
#include "vmap/links.h"
#include "vmap/map_access.h"

#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>

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
std::vector<std::span<const Link>> split_pieces(const std::vector<std::span<const Link>>& pieces) {
    std::vector<std::span<const Link>> tasks;
    for (auto sp : pieces)
        for (size_t i = 0; i < sp.size(); i += (1u << 20))
            tasks.push_back(sp.subspan(i, std::min<size_t>(1u << 20, sp.size() - i)));
    return tasks;
}
}  // namespace

void LinkArrays::count(const std::vector<std::span<const Link>>& pieces) {
    const auto tasks = split_pieces(pieces);
    std::atomic<bool> bad{false};
    tbb::parallel_for(size_t(0), tasks.size(), [&](size_t k) {
        for (auto [a, b] : tasks[k]) {
            if (a < 0 || b < 0 || a >= nn_ || b >= nn_ || a == b) {
                bad = true;
                return;
            }
            std::atomic_ref<uint64_t>(deg_[a + 1]).fetch_add(1, std::memory_order_relaxed);
            std::atomic_ref<uint64_t>(deg_[b + 1]).fetch_add(1, std::memory_order_relaxed);
        }
    });
    if (bad)
        throw Error(
            fmt::format("a link is out of range ({} nodes) or joins a node to itself", nn_));
}

void LinkArrays::finish(VisibilityMap& vm, const std::vector<std::span<const Link>>& pieces) {
    std::vector<uint64_t>& deg = deg_;
    for (int32_t n = 0; n < nn_; ++n) deg[n + 1] += deg[n];
    detail::MapData& d = detail::MapAccess::data(vm);
    d.link_offsets = deg;
    int32_t* out = detail::allocate_link_targets(d, deg.back());  // uninitialised: all written below
    std::vector<uint64_t> fill(deg.begin(), deg.end() - 1);
    const auto tasks = split_pieces(pieces);
    tbb::parallel_for(size_t(0), tasks.size(), [&](size_t k) {
        for (auto [a, b] : tasks[k]) {
            out[std::atomic_ref<uint64_t>(fill[a]).fetch_add(1, std::memory_order_relaxed)] = b;
            out[std::atomic_ref<uint64_t>(fill[b]).fetch_add(1, std::memory_order_relaxed)] = a;
        }
    });
    tbb::parallel_for(int32_t(0), nn_,
                      [&](int32_t n) { std::sort(out + deg[n], out + deg[n + 1]); });
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
