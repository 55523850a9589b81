// V-map construction (paper §3 and §4.3, DESIGN.md "The V-map").
//
// Every unordered leaf pair (a, b) lies in exactly one "sibling rectangle": leaves(A) x leaves(B)
// for the two distinct children A, B of the lowest common ancestor of a and b. Since leaves are in
// depth-first order, each such rectangle is contiguous in the leaf-by-leaf matrix. The builder
// lists those rectangles (splitting any larger than a job into sub-rectangles of child pairs),
// has a backend evaluate them in batches into bit-packed tables (the paper's LVS), and extracts
// links from each table on the host while the backend works on the next batch.
#include <fmt/format.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <numeric>

#include "util/progress.h"
#include "visibility/backend.h"
#include "visibility/bresenham.h"
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

// A node pair to resolve: either one job (a rectangle evaluated whole) or split into the pairs
// of its children (kids), when its rectangle is larger than a job may be.
struct Entry {
    int32_t a, b;
    int32_t job = -1;
    uint32_t kids_begin = 0, kids_end = 0;
};

struct Planner {
    const Octree& t;
    uint64_t max_job_pairs;
    std::vector<Entry> entries;
    std::vector<int32_t> kids;
    std::vector<PairJob> jobs;

    uint64_t area(int32_t a, int32_t b) const {
        return uint64_t(t.leaf_end[a] - t.leaf_begin[a]) *
               uint64_t(t.leaf_end[b] - t.leaf_begin[b]);
    }

    int32_t expand(int32_t a, int32_t b) {
        const int32_t e = static_cast<int32_t>(entries.size());
        entries.push_back({a, b});
        if (area(a, b) <= max_job_pairs) {
            PairJob j;
            j.a = a, j.b = b;
            j.row0 = t.leaf_begin[a], j.rows = t.leaf_end[a] - t.leaf_begin[a];
            j.col0 = t.leaf_begin[b], j.cols = t.leaf_end[b] - t.leaf_begin[b];
            entries[e].job = static_cast<int32_t>(jobs.size());
            jobs.push_back(j);
            return e;
        }
        std::vector<int32_t> mine;
        if (!t.is_leaf(a) && !t.is_leaf(b)) {
            t.for_each_child(a, [&](int32_t ca) {
                t.for_each_child(b, [&](int32_t cb) { mine.push_back(expand(ca, cb)); });
            });
        } else if (t.is_leaf(a)) {
            t.for_each_child(b, [&](int32_t cb) { mine.push_back(expand(a, cb)); });
        } else {
            t.for_each_child(a, [&](int32_t ca) { mine.push_back(expand(ca, b)); });
        }
        entries[e].kids_begin = static_cast<uint32_t>(kids.size());
        kids.insert(kids.end(), mine.begin(), mine.end());
        entries[e].kids_end = static_cast<uint32_t>(kids.size());
        return e;
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

VisibilityMap build_vmap(PointSet points, const BuildParams& params, BuildStats* stats,
                         const std::string& source) {
    const auto t0 = Clock::now();
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
            fmt::format("{}: --occluders: unknown kernel '{}' (expected spheres or bresenham)",
                        source, params.occluders));
    if (params.max_batch_pairs < 1024)
        throw Error(fmt::format("{}: batch of {} pairs is too small (>= 1024)", source,
                                params.max_batch_pairs));

    BuildStats st;
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
    Planner plan{t, std::max<uint64_t>(1, params.max_batch_pairs / 16), {}, {}, {}};
    std::vector<int32_t> roots;
    for (int32_t n = 0; n < t.num_nodes(); ++n) {
        if (t.is_leaf(n)) continue;
        std::vector<int32_t> ch;
        t.for_each_child(n, [&](int32_t c) { ch.push_back(c); });
        for (size_t i = 0; i < ch.size(); ++i)
            for (size_t j = i + 1; j < ch.size(); ++j) roots.push_back(plan.expand(ch[i], ch[j]));
    }

    st.seconds_plan = seconds_since(t1);
    std::string note;
    std::unique_ptr<detail::Backend> backend;
    if (params.occluders == "bresenham") {
        if (params.backend == "cuda")
            note = "--occluders bresenham: the GPU backend does spheres only; using the CPU";
        else if (params.backend != "auto" && params.backend != "cpu")
            detail::make_backend(params.backend, &note);  // throws for an unknown name
        backend = detail::make_bresenham_backend();
    } else {
        backend = detail::make_backend(params.backend, &note);
    }
    st.backend = backend->name();
    st.note = note;
    // Words per batch: a batch's rows are padded to 32 bits, so allow for that.
    const uint64_t max_words = params.max_batch_pairs / 32 + 1;
    uint64_t max_job_words = 0;
    for (const PairJob& j : plan.jobs)
        max_job_words = std::max(max_job_words, detail::job_words(j));
    const uint64_t batch_words = std::max(max_words, max_job_words);
    backend->prepare(t, vp, batch_words);

    // Batches: consecutive jobs up to batch_words.
    struct Batch {
        size_t begin, end;
        uint64_t words;
    };
    std::vector<Batch> batches;
    for (size_t j = 0; j < plan.jobs.size();) {
        Batch b{j, j, 0};
        while (b.end < plan.jobs.size() &&
               (b.end == b.begin || b.words + detail::job_words(plan.jobs[b.end]) <= batch_words)) {
            plan.jobs[b.end].word_offset = b.words;
            b.words += detail::job_words(plan.jobs[b.end]);
            ++b.end;
        }
        batches.push_back(b);
        j = b.end;
    }

    // Nodes whose split reaches leaves at once (a leaf, or all children leaves).
    std::vector<uint8_t> leafy(t.num_nodes(), 1);
    tbb::parallel_for(int32_t(0), t.num_nodes(), [&](int32_t n) {
        if (!t.is_leaf(n)) t.for_each_child(n, [&](int32_t c) { leafy[n] &= t.is_leaf(c); });
    });

    // Links stay in the blocks the extraction wrote them to (no copies). A fully visible job
    // makes no link during extraction: whether its link stands or is replaced by one at its
    // parents' level is settled after the last batch.
    std::vector<std::vector<Link>> pieces;
    LinkArrays arrays(t.num_nodes());
    std::vector<uint8_t> job_full(plan.jobs.size(), 0);
    Sinks sinks;
    const uint64_t total_pairs = uint64_t(t.num_leaves()) * (t.num_leaves() - 1) / 2;
    detail::Progress progress("leaf pairs", total_pairs, params.progress);
    uint64_t done_pairs = 0;
    uint64_t counted_links = 0;  // when the links are not kept

    auto submit = [&](size_t i) {
        const Batch& b = batches[i];
        backend->submit(std::span<const PairJob>(plan.jobs.data() + b.begin, b.end - b.begin),
                        b.words, int(i % 2));
    };
    if (!batches.empty()) {
        const auto tw = Clock::now();
        submit(0);
        st.seconds_wait += seconds_since(tw);
    }
    for (size_t i = 0; i < batches.size(); ++i) {
        auto tw = Clock::now();
        if (i + 1 < batches.size()) submit(i + 1);
        const uint32_t* bits = backend->wait(int(i % 2), st.work);
        st.seconds_wait += seconds_since(tw);
        const auto te = Clock::now();
        const Batch& b = batches[i];
        // Extract the batch's jobs in parallel (large partial pairs split further into tasks),
        // each thread into its own sink.
        tbb::parallel_for(b.begin, b.end, [&](size_t j) {
            const PairJob& job = plan.jobs[j];
            job_full[j] = Extractor{t, leafy, job, bits + job.word_offset, sinks}.run();
        });
        const size_t first_piece = pieces.size();
        for (LinkSink& sk : sinks) {
            for (auto& blk : sk.blocks) pieces.push_back(std::move(blk));
            sk.blocks.clear();
        }
        // Count this batch's link ends now, while the backend evaluates the next batch.
        if (params.keep_links) {
            std::vector<std::span<const Link>> fresh;
            for (size_t c = first_piece; c < pieces.size(); ++c) fresh.emplace_back(pieces[c]);
            arrays.count(fresh);
        } else {
            for (size_t c = first_piece; c < pieces.size(); ++c) counted_links += pieces[c].size();
            pieces.resize(first_piece);
        }
        for (size_t k = b.begin; k < b.end; ++k)
            done_pairs += uint64_t(plan.jobs[k].rows) * plan.jobs[k].cols;
        progress.update(done_pairs);
        st.seconds_extract += seconds_since(te);
    }
    st.batches = batches.size();
    st.peak_device_bytes = backend->peak_device_bytes();
    st.seconds_backend = backend->busy_seconds();
    const auto tl = Clock::now();

    // The fully visible pairs: an entry whose every part is fully visible makes one link at its
    // own level, and its parts none.
    std::vector<int8_t> full(plan.entries.size(), -1);
    auto is_full = [&](auto&& self, int32_t e) -> bool {
        if (full[e] >= 0) return full[e];
        const Entry& en = plan.entries[e];
        bool f = true;
        if (en.job >= 0)
            f = job_full[en.job];
        else
            for (uint32_t k = en.kids_begin; k < en.kids_end; ++k)
                f = self(self, plan.kids[k]) && f;
        full[e] = f;
        return f;
    };
    std::vector<Link> merged;
    auto settle = [&](auto&& self, int32_t e) -> void {
        const Entry& en = plan.entries[e];
        if (is_full(is_full, e)) {
            merged.emplace_back(en.a, en.b);
        } else if (en.job < 0) {
            for (uint32_t k = en.kids_begin; k < en.kids_end; ++k) self(self, plan.kids[k]);
        }
    };
    for (int32_t r : roots) settle(settle, r);
    if (params.keep_links) {
        arrays.count({std::span<const Link>(merged)});
        std::vector<std::span<const Link>> spans;
        for (const auto& p : pieces) spans.emplace_back(p);
        spans.emplace_back(merged);
        arrays.finish(vm, spans);
        st.links = vm.num_links();
    } else {
        vm.link_offsets.clear();  // has_links() is false: queries and save refuse the map
        st.links = counted_links + merged.size();
    }
    st.seconds_links = seconds_since(tl);
    st.seconds_visibility = seconds_since(t1);
    st.seconds_total = seconds_since(t0);
    if (stats) *stats = st;
    return vm;
}

}  // namespace vmap
