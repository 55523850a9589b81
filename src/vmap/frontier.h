// The construction's frontier of node pairs (paper §3; issue 15), bounded: the sibling pairs
// are resolved a slice at a time, and each slice's undecided pairs split into the next level's
// pairs, again a slice at a time (depth first over slices, breadth first inside one), so the
// pairs held at once are at most about max_level_pairs per level of the split. Each level's
// pairs are decided by the node tests of visibility/node_pair.h (on the backend: the GPU
// decides on the device, the CPU on all cores), the undecided small ones are walked as
// rectangles of leaf pairs by the backend (double buffered against the host's link
// extraction), and the rest split. When a slice's children are resolved, each split pair is
// settled: it is full (all its leaf pairs visible) when all its children are, and otherwise its
// full children make their links. So a link is made at the highest level where all is visible,
// as DESIGN.md "The V-map" asks, and the links go straight into the per-node link arrays.
#pragma once

#include <tbb/task_group.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include "util/progress.h"
#include "visibility/backend.h"
#include "visibility/node_pair.h"
#include "vmap/links.h"
#include "vmap/vmap.h"

namespace vmap::detail {

struct FrontierParams {
    uint64_t max_job_pairs = 1;   // a pair with more leaf pairs is split, never walked whole
    uint64_t walk_pairs = 1;      // undecided pairs with at most this many leaf pairs are walked
    size_t max_level_pairs = 1;   // node pairs of one level held at once (bounds memory)
    uint64_t batch_words = 1024;  // words of one backend batch
};

class Frontier {
  public:
    // ctx: the node tests (nullptr: none, every pair is split down to walks: leaf-pairs).
    Frontier(const Octree& t, const NodePairContext* ctx, Backend& backend,
             const BuildParams& params, const FrontierParams& fp, BuildStats& st);
    ~Frontier();
    // Resolves every leaf pair under the roots (the sibling pairs), making their links.
    void run(const std::vector<NodePairRef>& roots);
    // The same for root lists pulled from `next` until it gives an empty one (the MPI build's
    // chunks, one octree and one backend for all of them).
    void run(const std::function<std::vector<NodePairRef>()>& next);
    // Lanes: more backends on the same device (Backend::lane), each driving frontier work of its
    // own. Where a split makes several slices of child pairs, the lanes take the slices
    // (each resolves its slice depth first, as the lead does), so one lane's node tests, link
    // extraction and settling on the host overlap the others' batches on the device, which
    // otherwise waits for them. The links are the same (the arrays sort each node's targets);
    // the lanes' counters are added to the lead's. Called before run.
    void add_lanes(std::vector<std::unique_ptr<Backend>> backends);
    size_t lanes() const { return 1 + helpers_.size(); }
    // The links made (blocks that were counted into arrays), and arrays counting their ends.
    std::vector<std::vector<Link>> pieces;
    LinkArrays arrays;
    uint64_t counted_links = 0;  // when the links are not kept

  private:
    // A helper lane of `lead`: its own backend, batches, sinks and counters; the lead's link
    // arrays and per-leaf walked counts.
    Frontier(Frontier& lead, std::unique_ptr<Backend> backend);
    enum class Kind : uint8_t { kFull, kEmpty, kSplit, kJob };
    std::vector<uint8_t> resolve(const std::vector<NodePairRef>& level);
    std::vector<Kind> classify(const std::vector<NodePairRef>& level);
    void decide(const std::vector<NodePairRef>& level, std::vector<uint8_t>& out);
    void count_level(const std::vector<NodePairRef>& level, const std::vector<Kind>& kinds);
    void walk(const std::vector<NodePairRef>& level, const std::vector<Kind>& kinds,
              std::vector<uint8_t>& full);
    std::vector<PairJob> make_jobs(const std::vector<NodePairRef>& level,
                                   const std::vector<Kind>& kinds, std::vector<size_t>& owner);
    void extract(int slot, const std::vector<PairJob>& jobs, size_t begin, size_t end,
                 const uint32_t* bits, std::vector<uint8_t>& job_full);
    void finish_extraction(int slot);
    void split(const std::vector<NodePairRef>& level, const std::vector<Kind>& kinds,
               std::vector<uint8_t>& full);
    void resolve_slice(const std::vector<NodePairRef>& level, std::span<const size_t> parents,
                       const std::vector<uint8_t>& nks, std::vector<uint8_t>& full);
    struct Offer;
    struct Pool;
    void offer(size_t slices, const std::function<void(Frontier&, size_t)>& one);
    void take(Offer& o, size_t s);
    void serve(int threads);
    void settle(const std::vector<NodePairRef>& kids, const std::vector<uint8_t>& kid_full,
                std::span<const size_t> parents, const std::vector<uint64_t>& first,
                std::vector<uint8_t>& full);
    void absorb(Frontier& helper);
    void collect_sinks(Sinks& sinks);
    uint64_t area(NodePairRef p) const {
        return uint64_t(t_.leaf_end()[p.a] - t_.leaf_begin()[p.a]) *
               uint64_t(t_.leaf_end()[p.b] - t_.leaf_begin()[p.b]);
    }
    uint32_t num_kids(NodePairRef p) const;

    // A helper's own (the lead's are the caller's).
    std::unique_ptr<Backend> own_backend_;
    BuildStats own_st_;

    const Octree& t_;
    const NodePairContext* ctx_;
    Backend& backend_;
    const BuildParams& params_;
    FrontierParams fp_;
    BuildStats& st_;
    Frontier* lead_;              // this, or the lane's lead
    std::vector<uint8_t> leafy_;  // (the lead's, for every lane)
    // Per leaf, the walked leaf pairs (a difference array; the lead's holds every lane's).
    std::vector<int64_t> walked_diff_;
    std::vector<std::unique_ptr<Frontier>> helpers_;
    std::unique_ptr<Pool> pool_;                       // the lead's, with helpers
    Pool* pool() const { return lead_->pool_.get(); }  // the lanes' pool, or none
    Sinks sinks_;
    // The links of a batch's partly visible jobs, extracted while the backend evaluates the
    // next batches (and the frontier moves on); the slot's table stays valid until its next
    // submit, which waits for this first.
    struct Extraction {
        tbb::task_group group;
        std::vector<PairJob> jobs;
        const uint32_t* bits = nullptr;
        Sinks sinks;
        bool busy = false;
    };
    Extraction extraction_[2];
    Progress* progress_ = nullptr;
};

}  // namespace vmap::detail
