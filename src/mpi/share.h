// One process's part of a shared V-map build, with no MPI in it (src/mpi/top_pairs.h says how
// the work is cut): the probe that builds the octree and lists the jobs, the rounds of
// build_vmap started from a share of the jobs, the counters summed over rounds and processes,
// and the links of a node range laid out as VisibilityMap's arrays.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "mpi/top_pairs.h"
#include "vmap/vmap.h"

namespace vmap::mpi {

// What one process built: links (a < b, each once) of its jobs, which jobs came back fully
// visible, and its counters summed over its rounds.
struct ShareResult {
    std::vector<NodePair> links;
    uint64_t links_counted = 0;  // links seen, kept or not (BuildParams::keep_links)
    std::vector<uint8_t> full;   // per top pair: a job of this share, fully visible
    BuildStats stats;
    int rounds = 0;
    double seconds = 0;  // in build_vmap, all rounds
};

// The octree and points of the build (build_octree's map: no links) and the jobs for `ranks`
// processes. Throws what build_vmap throws.
VisibilityMap probe(const PointSet& points, const BuildParams& params, int ranks, TopPairs& tp,
                    BuildStats& stats, const std::string& source);

// build_vmap started from `jobs`, over the points and octree of `base` (the probe's: they are
// not built again); adds its links (kept when keep, else counted), full flags and counters to
// `out`. base is given back as it came (no links), or left empty when this throws.
void build_round(VisibilityMap& base, const BuildParams& params, const TopPairs& tp,
                 const std::vector<uint32_t>& jobs, bool keep, const std::string& source,
                 ShareResult& out);
// The same for the chunks of jobs `next` hands out (nullptr: no more), all in one build_vmap:
// one octree and one backend for every chunk (a round each).
void build_rounds(VisibilityMap& base, const BuildParams& params, const TopPairs& tp,
                  const std::function<const std::vector<uint32_t>*()>& next, bool keep,
                  const std::string& source, ShareResult& out);

// Drops the links of the jobs merged into their parents' (Merge::drop).
void drop_merged(const TopPairs& tp, const Merge& m, std::vector<NodePair>& links);

// The counters of a build (work, per-level node pairs, leaf pairs walked per leaf, ...) as one
// array of `counter_count(levels, leaves)` numbers, for sums over rounds and processes.
size_t counter_count(size_t levels, size_t leaves);
std::vector<uint64_t> counters_of(const BuildStats& st, size_t levels, size_t leaves);
void add_counters(BuildStats& st, const std::vector<uint64_t>& c, size_t levels, size_t leaves);

// The link ends of nodes [n0, n1) among `links`, in VisibilityMap's layout: offsets (n1 - n0 +
// 1, from 0) and each node's targets sorted.
struct LinkRange {
    int32_t n0 = 0, n1 = 0;
    std::vector<uint64_t> offsets;
    std::vector<int32_t> targets;
};
LinkRange link_range(const std::vector<NodePair>& links, int32_t n0, int32_t n1);

// `links` cut by the owners of their ends (rank k owns nodes [bounds[k], bounds[k + 1])): each
// link in the list of each owner of an end (once when one owns both), in the order of `links`.
std::vector<std::vector<NodePair>> by_owner(const std::vector<NodePair>& links,
                                            const std::vector<int32_t>& bounds);

// Bounds b[0] = 0 < ... < b[parts] = nodes cutting the nodes into ranges of about equal link
// ends (degree[n]: node n's), each at least one node when there are enough.
std::vector<int32_t> split_nodes(const std::vector<uint32_t>& degree, int parts);

}  // namespace vmap::mpi
