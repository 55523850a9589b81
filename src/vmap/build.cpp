// V-map construction (paper §3 and §4.3, DESIGN.md "The V-map").
//
// Every unordered leaf pair (a, b) lies in exactly one "sibling rectangle": leaves(A) x leaves(B)
// for the two distinct children A, B of the lowest common ancestor of a and b. Since leaves are in
// depth-first order, each such rectangle is contiguous in the leaf-by-leaf matrix. The builder
// starts from those sibling pairs and, level by level, decides node pairs whole where the bounds
// of visibility/node_pair.h prove all or none of their leaf pairs visible (construction "nodes";
// "leaf-pairs" decides nothing, the oracle), splits the undecided ones into child pairs, and
// hands the rest as rectangles to a backend, which evaluates them in batches into bit-packed
// tables (the paper's LVS); links are extracted from each table on the host while the backend
// works on the next batch.
#include <fmt/format.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <numeric>

#include "util/progress.h"
#include "visibility/backend.h"
#include "visibility/bresenham.h"
#include "visibility/node_pair.h"
#include "vmap/build_checks.h"
#include "vmap/error.h"
#include "vmap/vmap.h"

namespace vmap {
namespace {

using detail::PairJob;
using Link = std::pair<int32_t, int32_t>;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

// One node pair of the construction: decided at node level (full: all its leaf pairs visible;
// empty: none), split into the pairs of its children, or walked as one job (a rectangle).
enum class Kind : uint8_t { kFull, kEmpty, kSplit, kJob };
struct Entry {
    int32_t a, b;
    int32_t parent;
    int32_t job = -1;                       // kJob: its index in Plan::jobs
    uint32_t kids_begin = 0, kids_end = 0;  // kSplit: its children in Plan::entries
    Kind kind = Kind::kJob;
};

struct NodeCounters {
    uint64_t shaft_node_tests = 0;
};

// The frontier of node pairs, level by level of the split (breadth first): every pair of a
// level is classified in parallel, then the undecided ones large enough are split into the next
// level's pairs (a prefix sum places each pair's children together, in order, so the plan does
// not depend on the thread count).
struct Planner {
    // Pairs with fewer leaf pairs are walked untested: a node-pair test costs a few walks.
    static constexpr uint64_t kMinTestPairs = 2;
    const Octree& t;
    const detail::NodePairContext* ctx;  // nullptr: no node tests (leaf-pairs)
    uint64_t max_job_pairs, walk_pairs;
    std::vector<Entry> entries;
    std::vector<PairJob> jobs;
    std::vector<ConstructionLevel> levels;
    uint64_t shaft_node_tests = 0;

    uint64_t size(int32_t n) const { return uint64_t(t.leaf_end[n] - t.leaf_begin[n]); }
    uint32_t num_kids(int32_t a, int32_t b) const {
        uint32_t ka = 0, kb = 0;
        t.for_each_child(a, [&](int32_t) { ++ka; });
        t.for_each_child(b, [&](int32_t) { ++kb; });
        return (ka ? ka : 1) * (kb ? kb : 1);
    }
    void put_kids(int32_t e, Entry* out) const {
        const int32_t a = entries[e].a, b = entries[e].b;
        auto put = [&](int32_t x, int32_t y) { *out++ = Entry{x, y, e}; };
        if (!t.is_leaf(a) && !t.is_leaf(b)) {
            t.for_each_child(
                a, [&](int32_t ca) { t.for_each_child(b, [&](int32_t cb) { put(ca, cb); }); });
        } else if (t.is_leaf(a)) {
            t.for_each_child(b, [&](int32_t cb) { put(a, cb); });
        } else {
            t.for_each_child(a, [&](int32_t ca) { put(ca, b); });
        }
    }

    Kind classify(const Entry& e, ConstructionLevel& lv, NodeCounters& nc) const {
        const uint64_t area = size(e.a) * size(e.b);
        lv.pairs++;
        if (!ctx || area < kMinTestPairs) return area <= max_job_pairs ? Kind::kJob : Kind::kSplit;
        lv.tested++;
        const detail::PairDecision d = detail::decide_node_pair(*ctx, e.a, e.b, &nc);
        if (d == detail::PairDecision::kAllVisible) return Kind::kFull;
        if (d == detail::PairDecision::kNoneVisible) return Kind::kEmpty;
        return area <= std::min(walk_pairs, max_job_pairs) ? Kind::kJob : Kind::kSplit;
    }

    // Classifies entries [begin, end) and appends their children; returns the new end.
    size_t level(size_t begin, size_t end) {
        tbb::enumerable_thread_specific<std::vector<ConstructionLevel>> lvs(levels.size());
        tbb::enumerable_thread_specific<NodeCounters> ncs;
        tbb::parallel_for(tbb::blocked_range<size_t>(begin, end, 64), [&](const auto& r) {
            auto& lv = lvs.local();
            auto& nc = ncs.local();
            for (size_t i = r.begin(); i < r.end(); ++i) {
                Entry& e = entries[i];
                ConstructionLevel& l = lv[std::max(t.level[e.a], t.level[e.b])];
                e.kind = classify(e, l, nc);
                const uint64_t area = size(e.a) * size(e.b);
                if (e.kind == Kind::kFull)
                    l.visible++, l.leaf_pairs_decided += area, l.leaf_pairs_visible += area;
                if (e.kind == Kind::kEmpty) l.invisible++, l.leaf_pairs_decided += area;
                if (e.kind == Kind::kSplit) l.split++;
                if (e.kind == Kind::kJob) l.walked++, l.leaf_pairs_walked += area;
            }
        });
        for (auto& lv : lvs)
            for (size_t k = 0; k < levels.size(); ++k) {
                ConstructionLevel& o = levels[k];
                const ConstructionLevel& x = lv[k];
                o.pairs += x.pairs, o.tested += x.tested, o.visible += x.visible;
                o.invisible += x.invisible, o.split += x.split, o.walked += x.walked;
                o.leaf_pairs_decided += x.leaf_pairs_decided;
                o.leaf_pairs_visible += x.leaf_pairs_visible;
                o.leaf_pairs_walked += x.leaf_pairs_walked;
            }
        for (auto& nc : ncs) shaft_node_tests += nc.shaft_node_tests;
        // Children and jobs, placed by prefix sums in entry order.
        size_t next = end;
        for (size_t i = begin; i < end; ++i) {
            Entry& e = entries[i];
            if (e.kind == Kind::kJob) {
                PairJob j;
                j.a = e.a, j.b = e.b;
                j.row0 = t.leaf_begin[e.a], j.rows = int32_t(size(e.a));
                j.col0 = t.leaf_begin[e.b], j.cols = int32_t(size(e.b));
                e.job = int32_t(jobs.size());
                jobs.push_back(j);
            } else if (e.kind == Kind::kSplit) {
                e.kids_begin = uint32_t(next);
                next += num_kids(e.a, e.b);
                e.kids_end = uint32_t(next);
            }
        }
        if (next > UINT32_MAX)
            throw Error(fmt::format("{} node pairs to resolve: more than 2^32", next));
        entries.resize(next);
        tbb::parallel_for(begin, end, [&](size_t i) {
            if (entries[i].kind == Kind::kSplit)
                put_kids(int32_t(i), &entries[entries[i].kids_begin]);
        });
        return next;
    }

    void run(const std::vector<std::pair<int32_t, int32_t>>& roots) {
        levels.assign(size_t(t.height()) + 1, {});
        for (auto [a, b] : roots) entries.push_back(Entry{a, b, -1});
        size_t begin = 0, end = entries.size();
        while (begin < end) {
            const size_t next = level(begin, end);
            begin = end;
            end = next;
        }
    }
};

// Link extraction from one job's bit table (paper §3, Fig. 5 (b)-(d)): resolve(A, B) stores a
// link when all leaf pairs under (A, B) are visible, else splits, down to leaf pairs.
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

struct Extractor {
    const Octree& t;
    const std::vector<uint8_t>& leafy;  // per node: a leaf, or every child is a leaf
    const PairJob& job;
    const uint32_t* bits;  // this job's table
    Sinks& sinks;
    // A partial node pair with more leaf pairs than this splits into parallel tasks (one thread
    // per job would leave cores idle on batches of a few large jobs).
    static constexpr uint64_t kParallelArea = uint64_t(1) << 16;

    // Set bits in rows [r0, r1) x cols [c0, c1), job-relative.
    uint64_t count(int32_t r0, int32_t r1, int32_t c0, int32_t c1) const {
        const uint64_t rw = detail::row_words(job.cols);
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
    void emit_bits(int32_t r0, int32_t r1, int32_t c0, int32_t c1) {
        const uint64_t rw = detail::row_words(job.cols);
        const int32_t w0 = c0 / 32, w1 = (c1 - 1) / 32;
        LinkSink& out = sinks.local();
        for (int32_t r = r0; r < r1; ++r) {
            const uint32_t* row = bits + r * rw;
            const int32_t la = t.leaf_node[job.row0 + r];
            for (int32_t w = w0; w <= w1; ++w) {
                uint32_t word = row[w];
                if (w == w0) word &= ~0u << (c0 % 32);
                if (w == w1) word &= ~0u >> (31 - (c1 - 1) % 32);
                while (word) {
                    const int32_t c = w * 32 + __builtin_ctz(word);
                    out.push(la, t.leaf_node[job.col0 + c]);
                    word &= word - 1;
                }
            }
        }
    }

    // The job's own pair: true when it is fully visible (its one link is then made by the
    // caller, which may replace it by one at the parents' level), else its links go to sinks.
    bool run() {
        const uint64_t n = count(0, job.rows, 0, job.cols);
        if (n == uint64_t(job.rows) * uint64_t(job.cols)) return true;
        if (n > 0) split(job.a, job.b);
        return false;
    }

    void resolve(int32_t a, int32_t b) {
        const int32_t r0 = t.leaf_begin[a] - job.row0, r1 = t.leaf_end[a] - job.row0;
        const int32_t c0 = t.leaf_begin[b] - job.col0, c1 = t.leaf_end[b] - job.col0;
        const uint64_t n = count(r0, r1, c0, c1);
        if (n == 0) return;  // nothing visible below either: no link anywhere under (a, b)
        if (n == uint64_t(r1 - r0) * uint64_t(c1 - c0)) {
            sinks.local().push(a, b);
            return;
        }
        split(a, b);
    }

    // (a, b) is partly visible: resolve the pairs it splits into.
    void split(int32_t a, int32_t b) {
        const int32_t r0 = t.leaf_begin[a] - job.row0, r1 = t.leaf_end[a] - job.row0;
        const int32_t c0 = t.leaf_begin[b] - job.col0, c1 = t.leaf_end[b] - job.col0;
        if (leafy[a] && leafy[b]) {
            // The split reaches leaf pairs at once: each visible one is a link of its own. Read
            // them off the table a word at a time (most links of a large V-map are made here).
            emit_bits(r0, r1, c0, c1);
            return;
        }
        std::array<std::pair<int32_t, int32_t>, 64> kids;
        int nk = 0;
        const bool la = t.is_leaf(a), lb = t.is_leaf(b);
        if (!la && !lb) {
            t.for_each_child(a, [&](int32_t ca) {
                t.for_each_child(b, [&](int32_t cb) { kids[nk++] = {ca, cb}; });
            });
        } else if (la) {
            t.for_each_child(b, [&](int32_t cb) { kids[nk++] = {a, cb}; });
        } else {
            t.for_each_child(a, [&](int32_t ca) { kids[nk++] = {ca, b}; });
        }
        if (uint64_t(r1 - r0) * uint64_t(c1 - c0) > kParallelArea) {
            tbb::parallel_for(0, nk, [&](int k) { resolve(kids[k].first, kids[k].second); });
        } else {
            for (int k = 0; k < nk; ++k) resolve(kids[k].first, kids[k].second);
        }
    }
};

}  // namespace

namespace {

// Both-direction compact arrays from pieces of links, in parallel: count ends per node
// (relaxed atomics; the builder counts each batch's links while the backend works on the next),
// then scatter, then sort each node's targets (so the result does not depend on the order).
class LinkArrays {
  public:
    explicit LinkArrays(int32_t nodes) : nn_(nodes), deg_(size_t(nodes) + 1, 0) {}

    void count(const std::vector<std::span<const Link>>& pieces) {
        const auto tasks = split(pieces);
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
    void finish(VisibilityMap& vm, const std::vector<std::span<const Link>>& pieces) {
        std::vector<uint64_t>& deg = deg_;
        for (int32_t n = 0; n < nn_; ++n) deg[n + 1] += deg[n];
        vm.link_offsets = deg;
        vm.link_targets.resize(deg.back());  // uninitialised: every slot is written below
        std::vector<uint64_t> fill(deg.begin(), deg.end() - 1);
        int32_t* out = vm.link_targets.data();
        const auto tasks = split(pieces);
        tbb::parallel_for(size_t(0), tasks.size(), [&](size_t k) {
            for (auto [a, b] : tasks[k]) {
                out[std::atomic_ref<uint64_t>(fill[a]).fetch_add(1, std::memory_order_relaxed)] = b;
                out[std::atomic_ref<uint64_t>(fill[b]).fetch_add(1, std::memory_order_relaxed)] = a;
            }
        });
        tbb::parallel_for(int32_t(0), nn_,
                          [&](int32_t n) { std::sort(out + deg[n], out + deg[n + 1]); });
    }

  private:
    static std::vector<std::span<const Link>> split(
        const std::vector<std::span<const Link>>& pieces) {
        std::vector<std::span<const Link>> tasks;
        for (auto sp : pieces)
            for (size_t i = 0; i < sp.size(); i += (1u << 20))
                tasks.push_back(sp.subspan(i, std::min<size_t>(1u << 20, sp.size() - i)));
        return tasks;
    }
    int32_t nn_;
    std::vector<uint64_t> deg_;  // 64-bit: a million leaves can mean over 2^32 link ends
};

}  // namespace

void set_links(VisibilityMap& vm, std::vector<std::pair<int32_t, int32_t>> pairs) {
    LinkArrays la(vm.octree.num_nodes());
    const std::vector<std::span<const Link>> one{std::span<const Link>(pairs)};
    la.count(one);
    la.finish(vm, one);
}

namespace {

struct Batch {
    size_t begin, end;
    uint64_t words;
};

// The walked part: batches of jobs through the backend, double buffered (paper §6.2): while
// the backend evaluates batch i + 1, the host extracts links from batch i. Links stay in the
// blocks the extraction wrote them to (no copies). A fully visible job makes no link during
// extraction: whether its link stands or is replaced by one at its parents' level is settled
// after the last batch.
struct Walked {
    const Octree& t;
    const BuildParams& params;
    std::vector<uint8_t> leafy;  // per node: a leaf, or every child is a leaf
    std::vector<std::vector<Link>> pieces;
    LinkArrays arrays;
    std::vector<uint8_t> job_full;
    uint64_t counted_links = 0;  // when the links are not kept

    Walked(const Octree& tree, size_t jobs, const BuildParams& p)
        : t(tree),
          params(p),
          leafy(tree.num_nodes(), 1),
          arrays(tree.num_nodes()),
          job_full(jobs, 0) {
        tbb::parallel_for(int32_t(0), t.num_nodes(), [&](int32_t n) {
            if (!t.is_leaf(n)) t.for_each_child(n, [&](int32_t c) { leafy[n] &= t.is_leaf(c); });
        });
    }

    // Extracts one batch's jobs in parallel (large partial pairs split further into tasks),
    // each thread into its own sink, and counts the new link ends.
    void extract(const std::vector<PairJob>& jobs, const Batch& b, const uint32_t* bits,
                 Sinks& sinks) {
        tbb::parallel_for(b.begin, b.end, [&](size_t j) {
            const PairJob& job = jobs[j];
            job_full[j] = Extractor{t, leafy, job, bits + job.word_offset, sinks}.run();
        });
        const size_t first_piece = pieces.size();
        for (LinkSink& sk : sinks) {
            for (auto& blk : sk.blocks) pieces.push_back(std::move(blk));
            sk.blocks.clear();
        }
        if (params.keep_links) {
            std::vector<std::span<const Link>> fresh;
            for (size_t c = first_piece; c < pieces.size(); ++c) fresh.emplace_back(pieces[c]);
            arrays.count(fresh);
        } else {
            for (size_t c = first_piece; c < pieces.size(); ++c) counted_links += pieces[c].size();
            pieces.resize(first_piece);
        }
    }

    void run(detail::Backend& backend, const std::vector<PairJob>& jobs,
             const std::vector<Batch>& batches, BuildStats& st) {
        Sinks sinks;
        // The first report says the job's size and an estimate before the work starts.
        const double rate = backend.expected_pairs_per_second();
        const uint64_t total = st.leaf_pairs_walked;
        detail::Progress progress("leaf pairs", total, &params.progress, st.backend, st.note,
                                  rate > 0 ? double(total) / rate : 0.0);
        backend.set_progress(&progress);
        uint64_t done_pairs = 0;
        auto submit = [&](size_t i) {
            const Batch& b = batches[i];
            backend.submit(std::span<const PairJob>(jobs.data() + b.begin, b.end - b.begin),
                           b.words, int(i % 2));
        };
        if (!batches.empty()) {
            const auto tw = Clock::now();
            submit(0);
            st.seconds_wait += seconds_since(tw);
        }
        for (size_t i = 0; i < batches.size(); ++i) {
            const auto tw = Clock::now();
            if (i + 1 < batches.size()) submit(i + 1);
            const uint32_t* bits = backend.wait(int(i % 2), st.work);
            st.seconds_wait += seconds_since(tw);
            const auto te = Clock::now();
            extract(jobs, batches[i], bits, sinks);
            for (size_t k = batches[i].begin; k < batches[i].end; ++k)
                done_pairs += uint64_t(jobs[k].rows) * jobs[k].cols;
            progress.set(done_pairs);
            progress.throw_if_cancelled();
            st.seconds_extract += seconds_since(te);
        }
        backend.set_progress(nullptr);
        progress.finish();
    }
};

}  // namespace

namespace {

void check_params(const BuildParams& params, const std::string& source) {
    const VisibilityParams& vp = params.visibility;
    if (vp.K < 1 || vp.K > 1000)
        throw Error(fmt::format("{}: K {} out of range (1..1000)", source, vp.K));
    if (!(vp.eps >= 0 && vp.eps < 0.5f))
        throw Error(fmt::format("{}: eps {} out of range [0, 0.5)", source, vp.eps));
    if (!(vp.facing_tol >= 0 && vp.facing_tol < 1))
        throw Error(
            fmt::format("{}: facing tolerance {} out of range [0, 1)", source, vp.facing_tol));
    if (!(vp.parallel_tol >= 0 && vp.parallel_tol < 1))
        throw Error(
            fmt::format("{}: parallel tolerance {} out of range [0, 1)", source, vp.parallel_tol));
    if (params.occluders != "spheres" && params.occluders != "bresenham")
        throw Error(
            fmt::format("{}: occluders: unknown search '{}' (expected spheres or bresenham)",
                        source, params.occluders));
    if (params.construction != "nodes" && params.construction != "leaf-pairs" &&
        params.construction != "auto")
        throw Error(
            fmt::format("{}: construction: unknown method '{}' (expected auto, nodes or leaf-pairs)",
                        source, params.construction));
    if (params.max_batch_pairs < 1024)
        throw Error(fmt::format("{}: max_batch_pairs {} is too small (>= 1024)", source,
                                params.max_batch_pairs));
}

std::unique_ptr<detail::Backend> pick_backend(const BuildParams& params, std::string* note,
                                              const std::string& source) {
    if (params.occluders != "bresenham")
        return detail::make_backend(params.backend, note, params.device);
    if (params.backend == "cuda")
        throw Error(
            fmt::format("{}: backend cuda: the GPU does occluders spheres only "
                        "(bresenham runs on the CPU; use backend auto or cpu)",
                        source));
    if (params.backend != "auto" && params.backend != "cpu")
        detail::make_backend(params.backend, note);  // throws for an unknown name
    return detail::make_bresenham_backend();
}

// The sibling pairs: every unordered pair of distinct children of every internal node.
std::vector<std::pair<int32_t, int32_t>> sibling_pairs(const Octree& t) {
    std::vector<std::pair<int32_t, int32_t>> roots;
    for (int32_t n = 0; n < t.num_nodes(); ++n) {
        if (t.is_leaf(n)) continue;
        std::vector<int32_t> ch;
        t.for_each_child(n, [&](int32_t c) { ch.push_back(c); });
        for (size_t i = 0; i < ch.size(); ++i)
            for (size_t j = i + 1; j < ch.size(); ++j) roots.emplace_back(ch[i], ch[j]);
    }
    return roots;
}

// Consecutive jobs up to batch_words each; sets the jobs' word offsets.
std::vector<Batch> make_batches(std::vector<PairJob>& jobs, uint64_t batch_words) {
    std::vector<Batch> batches;
    for (size_t j = 0; j < jobs.size();) {
        Batch b{j, j, 0};
        while (b.end < jobs.size() &&
               (b.end == b.begin || b.words + detail::job_words(jobs[b.end]) <= batch_words)) {
            jobs[b.end].word_offset = b.words;
            b.words += detail::job_words(jobs[b.end]);
            ++b.end;
        }
        batches.push_back(b);
        j = b.end;
    }
    return batches;
}

// Per leaf: the walked leaf pairs it takes part in (a difference array over the jobs' ranges).
std::vector<uint64_t> walked_per_leaf(const Octree& t, const std::vector<PairJob>& jobs) {
    std::vector<int64_t> diff(size_t(t.num_leaves()) + 1, 0);
    for (const PairJob& j : jobs) {
        diff[j.row0] += j.cols, diff[j.row0 + j.rows] -= j.cols;
        diff[j.col0] += j.rows, diff[j.col0 + j.cols] -= j.rows;
    }
    std::vector<uint64_t> out(t.num_leaves());
    int64_t run = 0;
    for (int32_t l = 0; l < t.num_leaves(); ++l) out[l] = uint64_t(run += diff[l]);
    return out;
}

// Links at the highest level where all is visible: an entry is full when decided so, when its
// job's table is all set, or when all its children are full (deepest level first); it makes a
// link when full and its parent is not.
std::vector<Link> settle_links(const std::vector<Entry>& entries,
                               const std::vector<uint8_t>& job_full) {
    std::vector<uint8_t> full(entries.size(), 0);
    for (size_t i = entries.size(); i-- > 0;) {
        const Entry& e = entries[i];
        bool f = e.kind == Kind::kFull || (e.kind == Kind::kJob && job_full[e.job]);
        if (e.kind == Kind::kSplit) {
            f = true;
            for (uint32_t k = e.kids_begin; k < e.kids_end && f; ++k) f = full[k];
        }
        full[i] = f;
    }
    std::vector<Link> links;
    for (size_t i = 0; i < entries.size(); ++i)
        if (full[i] && (entries[i].parent < 0 || !full[entries[i].parent]))
            links.emplace_back(entries[i].a, entries[i].b);
    return links;
}

// Node bounds and the context of the node tests, when the construction decides node pairs.
struct NodeTests {
    bool on = false;
    detail::NodeBoundsSet nb;
    detail::NodePairContext ctx;
};
void prepare_node_tests(const Octree& t, const BuildParams& params, bool gpu, NodeTests& nt) {
    // Node-level decisions are proofs about the box walk of leaf_pair.h, not the grid walk.
    const bool nodes =
        params.construction == "nodes" || (params.construction == "auto" && !gpu);
    nt.on = nodes && params.occluders == "spheres";
    if (!nt.on) return;
    nt.nb = detail::node_bounds(t);
    nt.ctx = {t.view(),      nt.nb.nodes.data(), nt.nb.cones.data(),
              t.skip.data(), params.visibility,  detail::node_pair_margin(t.boxes[0])};
}

// The node pairs: decided at node level where the construction allows it, the rest as jobs.
Planner plan_pairs(const Octree& t, const BuildParams& params, const NodeTests& nt,
                   BuildStats& st) {
    st.construction = nt.on ? "nodes" : "leaf-pairs";
    const bool gpu = st.backend.rfind("cuda", 0) == 0;
    const uint64_t walk_pairs = params.walk_pairs ? params.walk_pairs : (gpu ? 1024 : 4096);
    Planner plan{t,
                 nt.on ? &nt.ctx : nullptr,
                 std::max<uint64_t>(1, params.max_batch_pairs / 16),
                 walk_pairs,
                 {},
                 {},
                 {}};
    plan.run(params.top_pairs ? params.top_pairs(t) : sibling_pairs(t));
    st.levels = plan.levels;
    for (const ConstructionLevel& l : plan.levels) {
        st.node_pairs_tested += l.tested;
        st.leaf_pairs_walked += l.leaf_pairs_walked;
    }
    st.shaft_node_tests = plan.shaft_node_tests;
    st.leaf_pairs = uint64_t(t.num_leaves()) * (t.num_leaves() - 1) / 2;
    st.leaf_walked = walked_per_leaf(t, plan.jobs);
    return plan;
}

}  // namespace

namespace {

VisibilityMap build_in_arena(PointSet points, const BuildParams& params, BuildStats* stats,
                             const std::string& source) {
    const auto t0 = Clock::now();
    check_params(params, source);
    const VisibilityParams& vp = params.visibility;
    BuildStats st;
    detail::prepare_points(points, st, source);
    VisibilityMap vm;
    vm.octree_params = params.octree;
    vm.visibility_params = vp;
    vm.octree = Octree::build_in_unit_frame(points, params.octree, vm.order, source);
    vm.points = std::move(points);
    vm.inverse.resize(vm.order.size());
    for (uint32_t k = 0; k < vm.order.size(); ++k) vm.inverse[vm.order[k]] = k;
    st.seconds_octree = seconds_since(t0);

    const auto t1 = Clock::now();
    const Octree& t = vm.octree;
    std::string note;
    std::unique_ptr<detail::Backend> backend = pick_backend(params, &note, source);
    st.backend = backend->name();
    st.note = note;
    NodeTests nt;
    prepare_node_tests(t, params, st.backend.rfind("cuda", 0) == 0, nt);
    Planner plan = plan_pairs(t, params, nt, st);
    st.seconds_decide = st.seconds_plan = seconds_since(t1);

    // Words per batch: a batch's rows are padded to 32 bits, so allow for that.
    const uint64_t max_words = params.max_batch_pairs / 32 + 1;
    uint64_t max_job_words = 0;
    for (const PairJob& j : plan.jobs)
        max_job_words = std::max(max_job_words, detail::job_words(j));
    const uint64_t batch_words = std::max(max_words, max_job_words);
    backend->prepare(t, vp, batch_words);
    backend->set_node_context(nt.on ? &nt.ctx : nullptr);
    const std::vector<Batch> batches = make_batches(plan.jobs, batch_words);

    Walked walked(t, plan.jobs.size(), params);
    walked.run(*backend, plan.jobs, batches, st);
    st.batches = batches.size();
    st.peak_device_bytes = backend->peak_device_bytes();
    st.seconds_backend = backend->busy_seconds();
    const auto tl = Clock::now();

    // The links of full entries (decided at node level, or full tables) go straight into the
    // arrays with the links extracted from the tables.
    const std::vector<Link> merged = settle_links(plan.entries, walked.job_full);
    if (params.keep_links) {
        walked.arrays.count({std::span<const Link>(merged)});
        std::vector<std::span<const Link>> spans;
        for (const auto& p : walked.pieces) spans.emplace_back(p);
        spans.emplace_back(merged);
        walked.arrays.finish(vm, spans);
        st.links = vm.num_links();
    } else {
        vm.link_offsets.clear();  // has_links() is false: queries and save refuse the map
        st.links = walked.counted_links + merged.size();
    }
    st.seconds_links = seconds_since(tl);
    st.seconds_visibility = seconds_since(t1);
    st.seconds_total = seconds_since(t0);
    if (!params.top_pairs) detail::check_facing(st);  // a share cannot judge the whole
    if (stats) *stats = std::move(st);
    return vm;
}

}  // namespace

VisibilityMap build_vmap(PointSet points, const BuildParams& params, BuildStats* stats,
                         const std::string& source) {
    if (params.threads < 0 || params.threads > 4096)
        throw Error(fmt::format("{}: threads {} out of range (0 = all cores, up to 4096)", source,
                                params.threads));
    if (params.threads == 0) return build_in_arena(std::move(points), params, stats, source);
    tbb::task_arena arena(params.threads);
    return arena.execute([&] { return build_in_arena(std::move(points), params, stats, source); });
}

}  // namespace vmap
