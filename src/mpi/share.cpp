// One process's part of a shared build (src/mpi/share.h).
#include "mpi/share.h"

#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <unordered_map>
#include <utility>

#include "vmap/build_parts.h"
#include "vmap/map_access.h"
#include "vmap/parallel.h"

namespace vmap::mpi {
namespace {

constexpr size_t kWork = 6, kLevel = 9, kScalars = 4;

// Some top pairs, to be found among links by their nodes (either order): a per-node filter
// first, since most links touch none of their nodes.
class PairIndex {
  public:
    PairIndex(const TopPairs& tp, const std::vector<uint8_t>& pick) {
        for (size_t i = 0; i < pick.size(); ++i)
            if (pick[i]) add(tp.pairs[i], uint32_t(i));
    }
    PairIndex(const TopPairs& tp, const std::vector<uint32_t>& pick) {
        for (uint32_t i : pick) add(tp.pairs[i], i);
    }
    bool empty() const { return of_.empty(); }
    // The index of the top pair with nodes a and b, or -1.
    int64_t find(int32_t a, int32_t b) const {
        if (!end(a) || !end(b)) return -1;
        const auto it = of_.find(key(a, b));
        return it == of_.end() ? -1 : int64_t(it->second);
    }

  private:
    static uint64_t key(int32_t a, int32_t b) {
        if (a > b) std::swap(a, b);
        return uint64_t(uint32_t(a)) << 32 | uint32_t(b);
    }
    bool end(int32_t n) const { return size_t(n) < end_.size() && end_[size_t(n)]; }
    void add(const TopPair& q, uint32_t i) {
        of_.emplace(key(q.a, q.b), i);
        const size_t hi = size_t(std::max(q.a, q.b)) + 1;
        if (end_.size() < hi) end_.resize(hi, 0);
        end_[size_t(q.a)] = end_[size_t(q.b)] = 1;
    }
    std::unordered_map<uint64_t, uint32_t> of_;
    std::vector<uint8_t> end_;  // per node: an end of one of the pairs
};

// Which of `jobs` came back fully visible: their own single link is among `links`.
void mark_full(const TopPairs& tp, const std::vector<uint32_t>& jobs,
               const std::vector<NodePair>& links, std::vector<uint8_t>& full) {
    const PairIndex index(tp, jobs);
    full.resize(tp.pairs.size(), 0);
    for (const auto& [a, b] : links)
        if (const int64_t i = index.find(a, b); i >= 0) full[size_t(i)] = 1;
}

}  // namespace

VisibilityMap probe(const PointSet& points, const BuildParams& params, int ranks, TopPairs& tp,
                    BuildStats& stats, const std::string& source) {
    VisibilityMap vm = detail::build_octree(points, params, stats, source);
    tp = make_top_pairs_for(vm.octree(), ranks);
    return vm;
}

void build_round(VisibilityMap& base, const BuildParams& params, const TopPairs& tp,
                 const std::vector<uint32_t>& jobs, bool keep, const std::string& source,
                 ShareResult& out) {
    bool given = false;
    build_rounds(base, params, tp,
                 [&]() { return std::exchange(given, true) ? nullptr : &jobs; }, keep, source,
                 out);
}

void build_rounds(VisibilityMap& base, const BuildParams& params, const TopPairs& tp,
                  const std::function<const std::vector<uint32_t>*()>& next, bool keep,
                  const std::string& source, ShareResult& out) {
    const auto t0 = std::chrono::steady_clock::now();
    BuildParams p = params;
    p.keep_links = true;  // a job's own link says whether it came back fully visible
    std::vector<uint32_t> done;  // every job of every chunk taken
    int chunks = 0;
    p.top_pairs = [&](const Octree&) {
        // An empty chunk would read as "no more" to build_vmap: take the next one instead.
        const std::vector<uint32_t>* jobs = next();
        for (; jobs && jobs->empty(); jobs = next()) ++chunks;
        if (!jobs) return std::vector<NodePair>{};
        ++chunks;
        done.insert(done.end(), jobs->begin(), jobs->end());
        return job_pairs(tp, *jobs);
    };
    BuildStats st;
    std::vector<NodePair> raw;
    base = detail::build_links(std::move(base), p, &st, source, &raw);
    mark_full(tp, done, raw, out.full);
    out.links_counted += raw.size();
    if (keep) {
        for (auto& [a, b] : raw)
            if (a > b) std::swap(a, b);
        if (out.links.empty())
            out.links = std::move(raw);
        else
            out.links.insert(out.links.end(), raw.begin(), raw.end());
    }
    const Octree& t = base.octree();
    const size_t levels = size_t(t.height()) + 1, leaves = size_t(t.num_leaves());
    if (out.rounds == 0) {
        out.stats = st;
    } else {
        add_counters(out.stats, counters_of(st, levels, leaves), levels, leaves);
        out.stats.seconds_plan += st.seconds_plan, out.stats.seconds_wait += st.seconds_wait;
        out.stats.seconds_backend += st.seconds_backend;
        out.stats.seconds_extract += st.seconds_extract;
        out.stats.seconds_links += st.seconds_links;
        out.stats.peak_device_bytes = std::max(out.stats.peak_device_bytes, st.peak_device_bytes);
    }
    out.rounds += chunks;
    out.seconds += seconds_since(t0);
}

void drop_merged(const TopPairs& tp, const Merge& m, std::vector<NodePair>& links) {
    const PairIndex gone(tp, m.drop);
    if (gone.empty()) return;
    std::erase_if(links, [&](const NodePair& l) { return gone.find(l.first, l.second) >= 0; });
}

size_t counter_count(size_t levels, size_t leaves) {
    return kWork + kLevel * levels + kScalars + leaves;
}

std::vector<uint64_t> counters_of(const BuildStats& st, size_t levels, size_t leaves) {
    std::vector<uint64_t> c;
    c.reserve(counter_count(levels, leaves));
    const WorkCounters& w = st.work;
    c.insert(c.end(), {w.pairs, w.facing_pairs, w.visible_pairs, w.node_tests, w.occluder_tests,
                       w.cells_stepped});
    for (size_t l = 0; l < levels; ++l) {
        const ConstructionLevel x = l < st.levels.size() ? st.levels[l] : ConstructionLevel{};
        c.insert(c.end(), {x.pairs, x.tested, x.visible, x.invisible, x.split, x.walked,
                           x.leaf_pairs_decided, x.leaf_pairs_visible, x.leaf_pairs_walked});
    }
    c.insert(c.end(),
             {st.leaf_pairs_walked, st.node_pairs_tested, st.shaft_node_tests, st.batches});
    for (size_t l = 0; l < leaves; ++l)
        c.push_back(l < st.leaf_walked.size() ? st.leaf_walked[l] : 0);
    return c;
}

void add_counters(BuildStats& st, const std::vector<uint64_t>& c, size_t levels, size_t leaves) {
    const uint64_t* p = c.data();
    WorkCounters w{p[0], p[1], p[2], p[3], p[4], p[5]};
    st.work += w;
    p += kWork;
    st.levels.resize(std::max(st.levels.size(), levels));
    for (size_t l = 0; l < levels; ++l, p += kLevel) {
        ConstructionLevel& x = st.levels[l];
        x.pairs += p[0], x.tested += p[1], x.visible += p[2], x.invisible += p[3];
        x.split += p[4], x.walked += p[5], x.leaf_pairs_decided += p[6];
        x.leaf_pairs_visible += p[7], x.leaf_pairs_walked += p[8];
    }
    st.leaf_pairs_walked += p[0], st.node_pairs_tested += p[1], st.shaft_node_tests += p[2];
    st.batches += p[3];
    p += kScalars;
    st.leaf_walked.resize(std::max(st.leaf_walked.size(), leaves), 0);
    for (size_t l = 0; l < leaves; ++l) st.leaf_walked[l] += p[l];
}

LinkRange link_range(const std::vector<NodePair>& links, int32_t n0, int32_t n1) {
    // Each end in range counted per node, placed at its node's cursor, then each node's
    // targets sorted: the arrays' order, as a sort of (node, target) keys gives it. The threads
    // share the nodes: each scans every link for the ends of its own nodes, so no count or
    // cursor is shared (the scan is a sequential read; the writes are what cost).
    LinkRange r;
    r.n0 = n0, r.n1 = n1;
    const size_t nodes = size_t(n1 - n0);
    r.offsets.assign(nodes + 1, 0);
    // At most kMaxParts: each part reads every link, so more would cost more reading than
    // their writes save.
    constexpr size_t kMaxParts = 8;
    const size_t parts = std::clamp<size_t>(size_t(tbb::this_task_arena::max_concurrency()), 1,
                                            std::min(kMaxParts, std::max<size_t>(1, nodes)));
    // Part p holds nodes [cut[p], cut[p + 1]) (relative to n0).
    auto by_part = [&](const std::vector<size_t>& cut, auto&& f) {
        parallel_for(parts, [&](size_t p) {
            const int32_t lo = n0 + int32_t(cut[p]), hi = n0 + int32_t(cut[p + 1]);
            for (const auto& [a, b] : links) {
                if (a >= lo && a < hi) f(a, b);
                if (b >= lo && b < hi) f(b, a);
            }
        });
    };
    std::vector<size_t> cut(parts + 1);
    for (size_t p = 0; p <= parts; ++p) cut[p] = nodes * p / parts;
    by_part(cut, [&](int32_t a, int32_t) { r.offsets[size_t(a - n0) + 1]++; });
    for (size_t i = 1; i < r.offsets.size(); ++i) r.offsets[i] += r.offsets[i - 1];
    // The placing's parts: about equal ends each.
    for (size_t p = 1, n = 0; p < parts; ++p) {
        const uint64_t want = r.offsets.back() * p / parts;
        while (n < nodes && r.offsets[n] < want) ++n;
        cut[p] = std::max(n, cut[p - 1]);
    }
    r.targets.resize(r.offsets.back());
    std::vector<uint64_t> at(r.offsets.begin(), r.offsets.end() - 1);
    by_part(cut, [&](int32_t a, int32_t b) { r.targets[at[size_t(a - n0)]++] = b; });
    parallel_for(size_t(0), nodes, [&](size_t i) {
        std::sort(r.targets.begin() + ptrdiff_t(r.offsets[i]),
                  r.targets.begin() + ptrdiff_t(r.offsets[i + 1]));
    });
    return r;
}

std::vector<std::vector<NodePair>> by_owner(const std::vector<NodePair>& links,
                                            const std::vector<int32_t>& bounds) {
    const size_t parts = bounds.size() - 1;
    auto owner = [&](int32_t n) {
        return size_t(std::upper_bound(bounds.begin(), bounds.end(), n) - bounds.begin()) - 1;
    };
    // Blocks of links counted per owner, each block's place in each owner's list from the
    // counts before it, then the blocks copied in parallel: the serial loop's order.
    constexpr size_t kBlock = size_t(1) << 16;
    const size_t blocks = (links.size() + kBlock - 1) / kBlock;
    std::vector<uint64_t> at(blocks * parts, 0);
    auto each = [&](size_t k, auto&& f) {
        for (size_t i = k * kBlock, end = std::min(links.size(), i + kBlock); i < end; ++i) {
            const size_t oa = owner(links[i].first), ob = owner(links[i].second);
            f(oa, links[i]);
            if (ob != oa) f(ob, links[i]);
        }
    };
    parallel_for(blocks,
                 [&](size_t k) { each(k, [&](size_t o, NodePair) { at[k * parts + o]++; }); });
    std::vector<std::vector<NodePair>> out(parts);
    for (size_t o = 0; o < parts; ++o) {
        uint64_t run = 0;
        for (size_t k = 0; k < blocks; ++k) run += std::exchange(at[k * parts + o], run);
        out[o].resize(run);
    }
    parallel_for(blocks, [&](size_t k) {
        each(k, [&](size_t o, NodePair l) { out[o][at[k * parts + o]++] = l; });
    });
    return out;
}

std::vector<int32_t> split_nodes(const std::vector<uint32_t>& degree, int parts) {
    const int32_t nodes = int32_t(degree.size());
    uint64_t total = 0;
    for (uint32_t d : degree) total += d;
    std::vector<int32_t> b{0};
    uint64_t run = 0;
    for (int32_t n = 0; n < nodes && int(b.size()) < parts; ++n) {
        run += degree[n];
        // Cut after n once the ends so far reach the next share, leaving a node for each part.
        const uint64_t want = total * uint64_t(b.size()) / uint64_t(parts);
        if (run >= want && run > 0 && nodes - (n + 1) >= parts - int(b.size())) b.push_back(n + 1);
    }
    while (int(b.size()) < parts) b.push_back(std::min(nodes, b.back() + (b.back() < nodes)));
    b.push_back(nodes);
    return b;
}

}  // namespace vmap::mpi
