// The visibility map (paper §3; docs/design.md): links between octree nodes, each saying
// that every leaf under one end sees every leaf under the other.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "vmap/mesh.h"
#include "vmap/octree.h"
#include "vmap/options.h"
#include "vmap/progress.h"
#include "vmap/visibility.h"

namespace vmap {

struct BuildParams {
    OctreeParams octree;
    VisibilityParams visibility;
    // auto: the GPU when one is usable, else the CPU (the progress callback's first report
    // and BuildStats::note say why); cuda: the GPU or vmap::Error; cpu.
    Backend backend = Backend::kAuto;
    OccluderSearch occluders = OccluderSearch::kBoxes;  // vmap/options.h (the grid walk: CPU only)
    uint64_t max_batch_pairs = 1ull << 28;  // leaf pairs evaluated per batch (bounds memory)
    int threads = 0;  // CPU threads for the build (0: all cores; the caller's limit, if any)
    // Called with the leaf pairs done (vmap/progress.h); returning false cancels the build
    // (vmap::Cancelled). The library itself never prints.
    ProgressCallback progress;
    // false: extract and count the links but keep none (BuildStats::links; the map then has no
    // links). Sizes a V-map too large for host memory, and times the GPU on it.
    bool keep_links = true;
    // nodes: node pairs decided at node level where the bounds of visibility/node_pair.h prove
    // all or none of their leaf pairs visible (the same V-map, fewer leaf pairs walked);
    // leaf-pairs: every leaf pair walked (the oracle the node path must match byte for byte);
    // auto: whichever is faster, by measurement (docs/results.md): nodes on both backends
    // (on the CPU about 3x less work; on the GPU, with three lanes, the dragon at lp 1 builds in
    // 15.0 s against 21.7 s for leaf-pairs, H100, "Construction lanes").
    Construction construction = Construction::kAuto;
    // Undecided node pairs with at most this many leaf pairs are walked whole instead of split
    // further; 0: the backend's choice (small on the CPU, wider on the GPU, whose warps take 32
    // columns of a row at once).
    uint64_t walk_pairs = 0;
    // Node pairs of one level of the construction's frontier held at once (vmap/frontier.h):
    // bounds the memory of the node-pair decisions; any value gives the same V-map.
    uint64_t max_level_pairs = uint64_t(1) << 18;
    // Frontiers driving the backend at once (vmap/frontier.h, lanes): one lane's host work
    // (node tests, link extraction, settling) overlaps the other lanes' batches on the device,
    // which one lane leaves idle meanwhile. 0: the backend's choice (3 on the GPU; 1 on the CPU,
    // where one frontier keeps every core busy). Any value gives the same V-map. The MPI build
    // (top_pairs) runs one.
    int lanes = 0;
    // The CUDA device (an index among those CUDA_VISIBLE_DEVICES leaves visible); -1: device 0
    // (under mpirun, src/mpi/ sets the local rank's). Out of range: vmap::Error.
    int device = -1;
    // The node pairs the construction starts from, given the octree; empty function: every
    // pair of sibling nodes (the whole V-map). Pairs (a, b) of disjoint subtrees, a before b in
    // preorder, each covering its leaves(a) x leaves(b) once: the map then holds the links of
    // those rectangles only (the MPI build, src/mpi/, gives each process a share). Called
    // again each time its pairs are resolved, until it returns none: a caller can hand out its
    // work in chunks over one octree (the MPI build's dynamic schedule).
    std::function<std::vector<std::pair<int32_t, int32_t>>(const Octree&)> top_pairs;

    // Throws vmap::Error naming `source` and the field for a value out of range (octree and
    // visibility included), or the grid walk with backend cuda.
    void check(const std::string& source) const;
};

// Node pairs of the construction at one octree level (the deeper level of the pair's nodes).
struct ConstructionLevel {
    uint64_t pairs = 0;      // node pairs met (sibling pairs and the child pairs of splits)
    uint64_t tested = 0;     // of them, tested at node level
    uint64_t visible = 0;    // decided all visible (one link, no leaf pair walked)
    uint64_t invisible = 0;  // decided none visible
    uint64_t split = 0;      // undecided, split into child pairs
    uint64_t walked = 0;     // undecided (or too small to test), leaf pairs walked
    uint64_t leaf_pairs_decided = 0;  // leaf pairs under the decided ones
    uint64_t leaf_pairs_visible = 0;  // ... of them under the ones decided all visible
    uint64_t leaf_pairs_walked = 0;
};

struct BuildStats {
    WorkCounters work;
    std::string backend;  // which backend ran, in words
    std::string note;     // e.g. why the requested backend was not used
    // What looked wrong with the input, one sentence each: radii estimated because none were
    // given, normals inconsistent, almost no leaf pairs facing (src/vmap/build_checks.h).
    std::vector<std::string> warnings;
    double seconds_octree = 0;
    double seconds_visibility = 0;  // leaf pairs and link extraction
    double seconds_total = 0;
    double seconds_plan = 0;     // listing the node-pair rectangles
    double seconds_wait = 0;     // host blocked on the backend (GPU busy, or CPU evaluation)
    double seconds_backend = 0;  // the backend evaluating leaf pairs (GPU: kernel time)
    double seconds_extract = 0;  // link extraction from the tables
    double seconds_links = 0;    // merging links into the compact per-node arrays
    uint64_t links = 0;          // links of the V-map (also when they were not kept)
    uint64_t batches = 0;
    uint32_t lanes = 1;  // frontiers that drove the backend at once (BuildParams::lanes)
    uint64_t peak_device_bytes = 0;
    std::string construction;        // nodes | leaf-pairs
    uint64_t leaf_pairs = 0;         // all unordered leaf pairs
    uint64_t leaf_pairs_walked = 0;  // of them, walked by the leaf-pair predicate
    uint64_t node_pairs_tested = 0;
    uint64_t shaft_node_tests = 0;          // tree nodes tested against node-pair shafts
    double seconds_decide = 0;              // node bounds and node-pair tests
    std::vector<ConstructionLevel> levels;  // indexed by octree level
    // Per leaf: leaf pairs it takes part in that were walked (for `vmap render --mode decided`).
    std::vector<uint64_t> leaf_walked;
};

// Visibility of one point pair, from the V-map.
enum class PairVisibility { kHidden, kVisible, kSameLeaf };

namespace detail {
struct MapAccess;
}

class VisibilityMap {
  public:
    const OctreeParams& octree_params() const { return d_.octree_params; }
    const VisibilityParams& visibility_params() const { return d_.visibility_params; }
    // In octree order and the octree's frame (positions and radii in input units /
    // octree().scale(); render.h's points_in_input_order gives them back in input units).
    const PointSet& points() const { return d_.points; }
    const std::vector<uint32_t>& order() const { return d_.order; }      // octree position -> input index
    const std::vector<uint32_t>& inverse() const { return d_.inverse; }  // input index -> octree position
    const Octree& octree() const { return d_.octree; }
    // Per node + 1: node n's links are link_targets()[link_offsets()[n] .. link_offsets()[n+1]),
    // sorted; every link is stored at both ends.
    const std::vector<uint64_t>& link_offsets() const { return d_.link_offsets; }
    std::span<const int32_t> link_targets() const {
        return {d_.link_targets.get(), d_.num_link_targets};
    }

    size_t num_links() const { return d_.num_link_targets / 2; }
    // False for a map built with BuildParams::keep_links = false (links counted, not kept):
    // queries, saving and GI then throw instead of answering "hidden" for everything.
    bool has_links() const {
        return d_.link_offsets.size() == size_t(d_.octree.num_nodes()) + 1;
    }
    void require_links(const char* what) const;
    std::span<const int32_t> links(int32_t node) const {
        return {d_.link_targets.get() + d_.link_offsets[node],
                d_.link_targets.get() + d_.link_offsets[node + 1]};
    }

    // Is leaf b covered by a link of leaf a or one of its ancestors? O(height x log degree).
    bool leaves_visible(int32_t leaf_a, int32_t leaf_b) const;
    // Point pair by input indices. Throws vmap::Error for an index out of range.
    PairVisibility query(uint32_t i, uint32_t j) const;
    // All input indices visible from input point i (paper Fig. 9): the points of every subtree
    // linked to i's leaf or an ancestor, sorted. Points sharing i's leaf are not included.
    std::vector<uint32_t> visible_set(uint32_t i) const;

  private:
    friend struct detail::MapAccess;  // the builder and the file reader fill it
    struct Data {
        OctreeParams octree_params;
        VisibilityParams visibility_params;
        PointSet points;
        std::vector<uint32_t> order, inverse;
        Octree octree;
        std::vector<uint64_t> link_offsets;
        // Shared by copies (a map is read-only); allocated uninitialised (it runs to
        // gigabytes and is filled in parallel right after).
        std::shared_ptr<int32_t[]> link_targets;
        size_t num_link_targets = 0;
    };
    Data d_;
};

// Builds the octree over `points` (which need normals) and the V-map, in the frame of the
// cloud's own size (Octree::build_in_unit_frame), so the map is the same whatever unit the
// input was written in. Points without splat radii get them from estimate_radii
// (vmap/normals.h); that, normals that look inconsistent, and almost no facing leaf pairs are
// reported in stats->warnings. Throws vmap::Error naming `source` for bad input or parameters
// (messages name the BuildParams field), or for backend "cuda" without a usable GPU;
// vmap::Cancelled when the progress callback returned false.
VisibilityMap build_vmap(PointSet points, const BuildParams& params, BuildStats* stats = nullptr,
                         const std::string& source = "points");

// Makes the GPU context a build with these params will use, now: the first CUDA call of a
// process takes a few tenths of a second. Called on a thread of its own while the input is read
// (`vmap build` does), it takes that wait off build_vmap. Does nothing for backend cpu, the grid
// walk, or a vmap built without CUDA; never throws (build_vmap reports a missing GPU).
void warm_up_gpu(const BuildParams& params) noexcept;

// For benchmarks (`vmap bench`, bench/bench.cpp), the backends of build_vmap apart from a build:
// the CUDA backend's name as BuildStats::backend gives it ("cuda (NVIDIA H200, 132 SMs)") when
// a usable device is present, else an empty string with the reason in *why.
std::string cuda_backend_name(std::string* why = nullptr);
// Leaf pairs per second the CPU backend decides with `vp` on a seeded sample of at least
// `samples` of `tree`'s leaf pairs: blocks of 8 rows by 32 consecutive columns at uniform random
// places above the diagonal of the leaf-by-leaf matrix, the access pattern of a build, so the
// caches behave as they would (1e9 for a tree of fewer than 64 leaves: too small to sample).
// Estimates a CPU build too long to run in full.
double sampled_cpu_pair_rate(const Octree& tree, const VisibilityParams& vp, uint64_t samples);

// The .vmap file (versioned binary with a checksum; io/vmap_file.cpp). save writes to a
// temporary name and renames it; load throws vmap::Error for a missing, truncated, corrupt or
// wrong-version file, naming the file and the section.
struct SaveStats {  // what a save took, when asked for
    uint64_t bytes = 0;          // the file's size
    double encode_seconds = 0;   // the sections laid out, the coded links' sizes counted
    double write_seconds = 0;    // links coded, hashed, written to the page cache, writeback started
    double sync_seconds = 0;     // waiting for the disk (fsync), the rename, the folder's fsync
};
void save_vmap(const std::string& path, const VisibilityMap& vm, SaveStats* stats = nullptr);
VisibilityMap load_vmap(const std::string& path);

}  // namespace vmap
