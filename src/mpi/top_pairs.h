// The V-map construction cut into independent jobs for several processes (src/mpi/), with no
// MPI in it: the top node pairs, their shares and the merge of the pieces back into one map.
//
// Every unordered leaf pair lies in exactly one sibling rectangle (src/vmap/build.cpp), so the
// construction started from disjoint sets of node pairs gives disjoint sets of links. The
// sibling pairs near the root are too large to share out (the 28 pairs of the root's children
// hold most of the work), so the largest are split into their children's pairs (the split of
// resolve(A, B), DESIGN.md "The V-map") until each holds at most a given number of leaf pairs:
// a tree of node pairs whose leaves are the jobs. A split pair whose job pieces all come back
// fully visible (each its own single link) is one link at its own level instead, as in the
// single-process build: merge_full() settles that, so the union is byte for byte that build's.
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include "vmap/octree.h"

namespace vmap::mpi {

using NodePair = std::pair<int32_t, int32_t>;

struct TopPair {
    int32_t a, b;
    int32_t parent;                         // -1: a sibling pair
    uint32_t kids_begin = 0, kids_end = 0;  // split: its children in TopPairs::pairs; else a job
    uint64_t area = 0;                      // leaf pairs under (a, b)
    bool is_job() const { return kids_begin == kids_end; }
};

struct TopPairs {
    std::vector<TopPair> pairs;  // sibling pairs in preorder of their parent, then the splits
    std::vector<uint32_t> jobs;  // indices of the unsplit pairs, in order
    uint64_t total_area = 0;     // all leaf pairs
};

// The sibling pairs, those with more than `max_area` leaf pairs split (a leaf-leaf pair never
// is). Deterministic: every process computes the same list from the same octree.
TopPairs make_top_pairs(const Octree& t, uint64_t max_area);

// A split fine enough for `ranks` processes: no job above 1/(64 ranks) of all leaf pairs.
TopPairs make_top_pairs_for(const Octree& t, int ranks);

// Static shares by the work estimate (a job's leaf pairs): the largest job first to the least
// loaded rank (LPT). Returns per rank its job indices (into pairs), in increasing order.
std::vector<std::vector<uint32_t>> static_shares(const TopPairs& tp, int ranks);

// Chunks for handing out on demand: the jobs in kChunksPerRank x ranks bins of equal work
// estimate, each filled like static_shares (largest jobs first, to the lightest bin), so every
// chunk holds the same mix of large and small jobs. Measured (docs/scaling.md): chunks cut from
// the jobs sorted by size, largest first and shrinking (guided self-scheduling), balanced worse
// than the static shares (slowest / mean 1.36-1.55 against 1.11-1.14 at 4 and 8 ranks), since
// the estimate undercounts the small jobs' cost (the large ones are mostly decided at node level).
// A rank resolves all its chunks in one build_vmap (mpi::build_rounds), so a chunk costs one
// message, not an octree: 16 a rank balanced 8 ranks to 1.03 (4: 1.08-1.12; docs/scaling.md).
// (--chunks-per-rank sets another number: any gives the same map.)
constexpr int kChunksPerRank = 16;
std::vector<std::vector<uint32_t>> dynamic_chunks(const TopPairs& tp, int ranks,
                                                  int per_rank = kChunksPerRank);

// The node pairs of the given jobs, for BuildParams::top_pairs.
std::vector<NodePair> job_pairs(const TopPairs& tp, const std::vector<uint32_t>& jobs);

// Given which jobs came back fully visible (full[i] for pair i; ignored for split pairs),
// the links to drop (the single links of jobs whose parent is full as a whole) and the links
// to add (the highest full split pairs). drop is indexed like pairs.
struct Merge {
    std::vector<uint8_t> drop;
    std::vector<NodePair> add;
};
Merge merge_full(const TopPairs& tp, const std::vector<uint8_t>& full);

}  // namespace vmap::mpi
