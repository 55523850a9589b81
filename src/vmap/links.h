// Links from leaf-pair tables and the compact per-node link arrays (paper §3, Fig. 5; DESIGN.md
// "The V-map"): the extraction of one walked rectangle's links, thread-local sinks that keep
// them in blocks that never move, and the both-direction arrays built from those blocks.
#pragma once

#include <atomic>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include <tbb/enumerable_thread_specific.h>

#include "visibility/backend.h"
#include "vmap/vmap.h"

namespace vmap::detail {

using Link = std::pair<int32_t, int32_t>;

// Links as they are extracted, per thread, in blocks that never move once written (no copying
// as they grow; the link arrays read them in place).
struct LinkSink {
    static constexpr size_t kBlock = size_t(1) << 20;
    std::vector<std::vector<Link>> blocks;
    void push(int32_t a, int32_t b) {
        if (blocks.empty() || blocks.back().size() == kBlock) {
            blocks.emplace_back();
            blocks.back().reserve(kBlock);
        }
        blocks.back().emplace_back(a, b);
    }
};
using Sinks = tbb::enumerable_thread_specific<LinkSink>;

// Link extraction from one job's bit table: resolve(A, B) stores a link when all leaf pairs
// under (A, B) are visible, else splits, down to leaf pairs.
struct Extractor {
    const Octree& t;
    const std::vector<uint8_t>& leafy;  // per node: a leaf, or every child is a leaf
    const PairJob& job;
    const uint32_t* bits;  // this job's table
    Sinks& sinks;
    // A partial node pair with more leaf pairs than this splits into parallel tasks (one thread
    // per job would leave cores idle on batches of a few large jobs).
    static constexpr uint64_t kParallelArea = uint64_t(1) << 16;

    // The job's own pair: true when it is fully visible (its one link is then made by the
    // caller, which may replace it by one at the parents' level), else its links go to sinks.
    bool run();
    // The set bits of the job's table.
    uint64_t visible() const { return count(0, job.rows, 0, job.cols); }

  private:
    uint64_t count(int32_t r0, int32_t r1, int32_t c0, int32_t c1) const;
    void emit_bits(int32_t r0, int32_t r1, int32_t c0, int32_t c1);
    void resolve(int32_t a, int32_t b);
    void split(int32_t a, int32_t b);
};

// Both-direction compact arrays from pieces of links, in parallel: count ends per node (per
// thread, no atomics; the builder counts each piece's links while the backend works on the
// next), then put every end into a bucket of nodes and sort each bucket in cache (so the result,
// each node's targets sorted, does not depend on the order of the links or the threads).
class LinkArrays {
  public:
    explicit LinkArrays(int32_t nodes) : nn_(nodes) {}
    // Throws vmap::Error for a link out of range or joining a node to itself.
    void count(const std::vector<std::span<const Link>>& pieces);
    // The arrays of vm from every piece counted.
    void finish(VisibilityMap& vm, const std::vector<std::span<const Link>>& pieces);

  private:
    int32_t nn_;
    // Per thread, link ends per node (32 bits: a node has at most one link to each other node).
    tbb::enumerable_thread_specific<std::vector<uint32_t>> ends_;
    std::vector<uint64_t> degrees();  // per node + 1, ends before it (summed over threads)
};

// The pairs a node pair (a, b) splits into (DESIGN.md "The V-map": both internal, their
// children's pairs; one a leaf, it with the other's children), in child order; f(x, y).
template <class F>
void for_each_child_pair(const Octree& t, int32_t a, int32_t b, F&& f) {
    if (!t.is_leaf(a) && !t.is_leaf(b)) {
        t.for_each_child(a, [&](int32_t x) { t.for_each_child(b, [&](int32_t y) { f(x, y); }); });
    } else if (t.is_leaf(a)) {
        t.for_each_child(b, [&](int32_t y) { f(a, y); });
    } else {
        t.for_each_child(a, [&](int32_t x) { f(x, b); });
    }
}

// Per node: a leaf, or every child is a leaf (where extraction reads links off the bits).
std::vector<uint8_t> leafy_nodes(const Octree& t);

}  // namespace vmap::detail
