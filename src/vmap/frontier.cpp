// The bounded frontier of node pairs (frontier.h).
#include "vmap/frontier.h"

#include <fmt/format.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <exception>
#include <mutex>
#include <numeric>
#include <thread>
#include <utility>

#include "vmap/error.h"

namespace vmap::detail {
namespace {

using Clock = std::chrono::steady_clock;

struct Batch {
    size_t begin, end;
    uint64_t words;
};

// Consecutive jobs up to batch_words each; sets the jobs' word offsets.
std::vector<Batch> make_batches(std::vector<PairJob>& jobs, uint64_t batch_words) {
    std::vector<Batch> batches;
    for (size_t j = 0; j < jobs.size();) {
        Batch b{j, j, 0};
        while (b.end < jobs.size() &&
               (b.end == b.begin || b.words + job_words(jobs[b.end]) <= batch_words)) {
            jobs[b.end].word_offset = b.words;
            b.words += job_words(jobs[b.end]);
            ++b.end;
        }
        batches.push_back(b);
        j = b.end;
    }
    return batches;
}

// One level's counters into another's.
void add_level(ConstructionLevel& o, const ConstructionLevel& x) {
    o.pairs += x.pairs, o.tested += x.tested, o.visible += x.visible;
    o.invisible += x.invisible, o.split += x.split, o.walked += x.walked;
    o.leaf_pairs_decided += x.leaf_pairs_decided;
    o.leaf_pairs_visible += x.leaf_pairs_visible;
    o.leaf_pairs_walked += x.leaf_pairs_walked;
}

}  // namespace

// The lanes' pool (the lead's): slices offered by a lane in split(), taken by whichever lane is
// free, the offering lane too, depth first inside a slice. A lane that has taken its offer's
// last slice waits for the others' (taking slices of other offers meanwhile would nest
// recursions on its stack without bound). Each helper lane's thread runs in an arena of its
// own, so no thread waiting inside one lane's parallel loop runs another lane's slice.
struct Frontier::Offer {
    size_t slices = 0;
    const std::function<void(Frontier&, size_t)>* one = nullptr;
    std::atomic<size_t> next{0};  // the next slice to take
    size_t done = 0;              // slices resolved (under the pool's m)
    std::exception_ptr error;     // the first slice's error (under m)
};
struct Frontier::Pool {
    std::mutex m;
    std::condition_variable cv;
    std::vector<Offer*> open;  // offers with slices left, the latest last
    bool stop = false;
    // Under m: the latest offer with a slice left, and that slice taken (an offer outlives its
    // taken slices: its lane waits until each is done).
    std::pair<Offer*, size_t> claim() {
        for (auto it = open.rbegin(); it != open.rend(); ++it) {
            const size_t s = (*it)->next.fetch_add(1);
            if (s < (*it)->slices) return {*it, s};
        }
        return {nullptr, 0};
    }
};

Frontier::Frontier(const Octree& t, const NodePairContext* ctx, Backend& backend,
                   const BuildParams& params, const FrontierParams& fp, BuildStats& st)
    : arrays(t.num_nodes()),
      t_(t),
      ctx_(ctx),
      backend_(backend),
      params_(params),
      fp_(fp),
      st_(st),
      lead_(this),
      leafy_(leafy_nodes(t)),
      walked_diff_(size_t(t.num_leaves()) + 1, 0) {
    fp_.max_level_pairs = std::max<size_t>(fp_.max_level_pairs, 1);
}

Frontier::Frontier(Frontier& lead, std::unique_ptr<Backend> backend)
    : arrays(0),
      own_backend_(std::move(backend)),
      t_(lead.t_),
      ctx_(lead.ctx_),
      backend_(*own_backend_),
      params_(lead.params_),
      fp_(lead.fp_),
      st_(own_st_),
      lead_(&lead) {}

Frontier::~Frontier() = default;

void Frontier::add_lanes(std::vector<std::unique_ptr<Backend>> backends) {
    for (auto& b : backends)
        if (b) helpers_.push_back(std::unique_ptr<Frontier>(new Frontier(*this, std::move(b))));
    if (!helpers_.empty() && !pool_) pool_ = std::make_unique<Pool>();
}

// A helper's counters, links and backend time into the lead's (after the last slice).
void Frontier::absorb(Frontier& h) {
    const BuildStats& o = h.st_;
    for (size_t k = 0; k < o.levels.size() && k < st_.levels.size(); ++k)
        add_level(st_.levels[k], o.levels[k]);
    st_.work += o.work;
    st_.batches += o.batches;
    st_.shaft_node_tests += o.shaft_node_tests;
    st_.seconds_decide += o.seconds_decide;
    st_.seconds_wait += o.seconds_wait;
    st_.seconds_extract += o.seconds_extract;
    for (auto& p : h.pieces) pieces.push_back(std::move(p));
    h.pieces.clear();
    counted_links += h.counted_links;
}

uint32_t Frontier::num_kids(NodePairRef p) const {
    uint32_t ka = 0, kb = 0;
    t_.for_each_child(p.a, [&](int32_t) { ++ka; });
    t_.for_each_child(p.b, [&](int32_t) { ++kb; });
    return (ka ? ka : 1) * (kb ? kb : 1);
}

void Frontier::run(const std::vector<NodePairRef>& roots) {
    bool given = false;
    run([&] { return std::exchange(given, true) ? std::vector<NodePairRef>{} : roots; });
}

void Frontier::run(const std::function<std::vector<NodePairRef>()>& next) {
    st_.levels.assign(size_t(t_.height()) + 1, {});
    st_.leaf_pairs = uint64_t(t_.num_leaves()) * (t_.num_leaves() - 1) / 2;
    // The first report says the job's size and an estimate (as if every pair were walked).
    const double rate = backend_.expected_pairs_per_second();
    Progress progress("leaf pairs", st_.leaf_pairs, &params_.progress, st_.backend, st_.note,
                      rate > 0 ? double(st_.leaf_pairs) / rate : 0.0);
    progress_ = &progress;
    backend_.set_progress(&progress);
    for (auto& h : helpers_) {
        h->st_.levels.assign(st_.levels.size(), {});
        h->progress_ = &progress;
        h->backend_.set_progress(&progress);
    }
    // The helper lanes wait for offered slices on threads of their own until the roots are done.
    std::vector<std::thread> lanes;
    auto stop_lanes = [&] {
        if (lanes.empty()) return;
        {
            std::lock_guard<std::mutex> lock(pool()->m);
            pool()->stop = true;
        }
        pool()->cv.notify_all();
        for (std::thread& th : lanes) th.join();
        lanes.clear();
    };
    if (pool()) {
        pool()->stop = false;
        const int threads = tbb::this_task_arena::max_concurrency();
        for (auto& h : helpers_) lanes.emplace_back([&h, threads] { h->serve(threads); });
    }
    try {
        for (std::vector<NodePairRef> roots; !(roots = next()).empty();)
            for (size_t s = 0; s < roots.size(); s += fp_.max_level_pairs) {
                const std::vector<NodePairRef> slice(
                    roots.begin() + s,
                    roots.begin() + std::min(roots.size(), s + fp_.max_level_pairs));
                const std::vector<uint8_t> full = resolve(slice);
                // A root has no parent pair here: a full one is a link.
                LinkSink& out = sinks_.local();
                for (size_t i = 0; i < slice.size(); ++i)
                    if (full[i]) out.push(slice[i].a, slice[i].b);
                collect_sinks(sinks_);
            }
    } catch (...) {
        stop_lanes();
        throw;
    }
    stop_lanes();
    finish_extraction(0);
    finish_extraction(1);
    backend_.set_progress(nullptr);
    progress_ = nullptr;
    for (auto& h : helpers_) {
        h->backend_.set_progress(nullptr);
        h->progress_ = nullptr;
        absorb(*h);
    }
    progress.finish();
    st_.leaf_walked.resize(t_.num_leaves());
    int64_t run = 0;
    for (int32_t l = 0; l < t_.num_leaves(); ++l)
        st_.leaf_walked[l] = uint64_t(run += walked_diff_[l]);
    for (const ConstructionLevel& l : st_.levels) {
        st_.node_pairs_tested += l.tested;
        st_.leaf_pairs_walked += l.leaf_pairs_walked;
    }
}

// One level (or a slice of it): full[i] says whether every leaf pair under level[i] is visible;
// the links under the pairs that are not full are made.
std::vector<uint8_t> Frontier::resolve(const std::vector<NodePairRef>& level) {
    const std::vector<Kind> kinds = classify(level);
    std::vector<uint8_t> full(level.size(), 0);
    for (size_t i = 0; i < level.size(); ++i) full[i] = kinds[i] == Kind::kFull;
    walk(level, kinds, full);
    split(level, kinds, full);
    return full;
}

// The kind of each pair: the node tests' decision where they run, else walked or split by size.
std::vector<Frontier::Kind> Frontier::classify(const std::vector<NodePairRef>& level) {
    const auto t0 = Clock::now();
    std::vector<uint8_t> d(level.size(), uint8_t(PairDecision::kUndecided));
    if (ctx_) decide(level, d);
    std::vector<Kind> kinds(level.size());
    const uint64_t walk_max = std::min(fp_.walk_pairs, fp_.max_job_pairs);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, level.size(), 4096), [&](const auto& r) {
        for (size_t i = r.begin(); i < r.end(); ++i) {
            const uint64_t a = area(level[i]);
            const bool tested = ctx_ && worth_deciding(*ctx_, level[i].a, level[i].b);
            const auto dk = PairDecision(d[i]);
            kinds[i] = dk == PairDecision::kAllVisible                ? Kind::kFull
                       : dk == PairDecision::kNoneVisible             ? Kind::kEmpty
                       : a <= (tested ? walk_max : fp_.max_job_pairs) ? Kind::kJob
                                                                      : Kind::kSplit;
        }
    });
    count_level(level, kinds);
    st_.seconds_decide += seconds_since(t0);
    return kinds;
}

// decide_node_pair for every pair worth deciding: on the backend when it can, else on all cores.
void Frontier::decide(const std::vector<NodePairRef>& level, std::vector<uint8_t>& out) {
    uint64_t shaft = 0;
    if (!backend_.decide(level, out.data(), &shaft)) {
        struct NodeCounters {
            uint64_t shaft_node_tests = 0;
        };
        tbb::combinable<NodeCounters> ncs;
        tbb::parallel_for(tbb::blocked_range<size_t>(0, level.size(), 64), [&](const auto& r) {
            NodeCounters& nc = ncs.local();
            for (size_t i = r.begin(); i < r.end(); ++i)
                if (worth_deciding(*ctx_, level[i].a, level[i].b))
                    out[i] = uint8_t(decide_node_pair(*ctx_, level[i].a, level[i].b, &nc));
        });
        ncs.combine_each([&](const NodeCounters& c) { shaft += c.shaft_node_tests; });
    }
    st_.shaft_node_tests += shaft;
}

// The per-level counters (the deeper level of the pair's nodes) and the progress of decisions.
void Frontier::count_level(const std::vector<NodePairRef>& level, const std::vector<Kind>& kinds) {
    using Levels = std::vector<ConstructionLevel>;
    tbb::combinable<Levels> per_thread([&] { return Levels(st_.levels.size()); });
    tbb::parallel_for(tbb::blocked_range<size_t>(0, level.size(), 4096), [&](const auto& r) {
        Levels& lv = per_thread.local();
        for (size_t i = r.begin(); i < r.end(); ++i) {
            const NodePairRef p = level[i];
            ConstructionLevel& l = lv[std::max(t_.level()[p.a], t_.level()[p.b])];
            const uint64_t a = area(p);
            l.pairs++;
            l.tested += ctx_ && worth_deciding(*ctx_, p.a, p.b);
            if (kinds[i] == Kind::kFull) l.visible++, l.leaf_pairs_visible += a;
            if (kinds[i] == Kind::kFull || kinds[i] == Kind::kEmpty) l.leaf_pairs_decided += a;
            l.invisible += kinds[i] == Kind::kEmpty;
            l.split += kinds[i] == Kind::kSplit;
            if (kinds[i] == Kind::kJob) l.walked++, l.leaf_pairs_walked += a;
        }
    });
    uint64_t decided = 0;
    per_thread.combine_each([&](const Levels& lv) {
        for (size_t k = 0; k < lv.size(); ++k) {
            add_level(st_.levels[k], lv[k]);
            decided += lv[k].leaf_pairs_decided;
        }
    });
    if (decided) progress_->add(decided);
}

// The walked pairs of a level as rectangles (in level order), each with its pair's index.
std::vector<PairJob> Frontier::make_jobs(const std::vector<NodePairRef>& level,
                                         const std::vector<Kind>& kinds,
                                         std::vector<size_t>& owner) {
    for (size_t i = 0; i < level.size(); ++i)
        if (kinds[i] == Kind::kJob) owner.push_back(i);
    std::vector<PairJob> jobs(owner.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, jobs.size(), 4096), [&](const auto& r) {
        for (size_t k = r.begin(); k < r.end(); ++k) {
            PairJob& j = jobs[k];
            j.a = level[owner[k]].a, j.b = level[owner[k]].b;
            j.row0 = t_.leaf_begin()[j.a], j.rows = t_.leaf_end()[j.a] - j.row0;
            j.col0 = t_.leaf_begin()[j.b], j.cols = t_.leaf_end()[j.b] - j.col0;
            auto add = [&](int32_t at, int64_t v) {
                std::atomic_ref<int64_t>(lead_->walked_diff_[at])
                    .fetch_add(v, std::memory_order_relaxed);
            };
            add(j.row0, j.cols), add(j.row0 + j.rows, -j.cols);
            add(j.col0, j.rows), add(j.col0 + j.cols, -j.rows);
        }
    });
    return jobs;
}

// The walked pairs of a level in batches through the backend, double buffered (paper §6.2):
// while the backend evaluates batch i + 1 the host extracts links from batch i, and that
// extraction may still run when the frontier moves on. A job whose table is all set is full:
// its link (or one at a level above) is made when its parent is settled.
void Frontier::walk(const std::vector<NodePairRef>& level, const std::vector<Kind>& kinds,
                    std::vector<uint8_t>& full) {
    std::vector<size_t> owner;
    std::vector<PairJob> jobs = make_jobs(level, kinds, owner);
    if (jobs.empty()) return;
    const std::vector<Batch> batches = make_batches(jobs, fp_.batch_words);
    std::vector<uint8_t> job_full(jobs.size(), 0);
    const uint64_t slot0 = st_.batches;
    auto slot = [&](size_t i) { return int((slot0 + i) % 2); };
    auto submit = [&](size_t i) {
        const Batch& b = batches[i];
        finish_extraction(slot(i));  // the slot's table is read until then
        backend_.submit(std::span<const PairJob>(jobs.data() + b.begin, b.end - b.begin), b.words,
                        slot(i));
        st_.batches++;
    };
    auto tw = Clock::now();
    submit(0);
    for (size_t i = 0; i < batches.size(); ++i) {
        if (i + 1 < batches.size()) submit(i + 1);
        const uint32_t* bits = backend_.wait(slot(i), st_.work);
        st_.seconds_wait += seconds_since(tw);
        const auto te = Clock::now();
        extract(slot(i), jobs, batches[i].begin, batches[i].end, bits, job_full);
        if (!backend_.counts_progress()) {
            uint64_t done = 0;
            for (size_t k = batches[i].begin; k < batches[i].end; ++k)
                done += uint64_t(jobs[k].rows) * jobs[k].cols;
            progress_->add(done);
        }
        progress_->throw_if_cancelled();
        st_.seconds_extract += seconds_since(te);
        tw = Clock::now();
    }
    for (size_t k = 0; k < jobs.size(); ++k) full[owner[k]] = job_full[k];
}

// Which jobs [begin, end) of one batch are full, at once; the links of the partly visible ones
// are extracted in the background, each thread into its own sink.
void Frontier::extract(int slot, const std::vector<PairJob>& jobs, size_t begin, size_t end,
                       const uint32_t* bits, std::vector<uint8_t>& job_full) {
    std::vector<uint8_t> partial(end - begin, 0);
    tbb::parallel_for(tbb::blocked_range<size_t>(begin, end, 256), [&](const auto& r) {
        for (size_t j = r.begin(); j < r.end(); ++j) {
            const PairJob& job = jobs[j];
            const uint64_t n =
                Extractor{t_, lead_->leafy_, job, bits + job.word_offset, sinks_}.visible();
            job_full[j] = n == uint64_t(job.rows) * uint64_t(job.cols);
            partial[j - begin] = n > 0 && !job_full[j];
        }
    });
    Extraction& x = extraction_[slot];
    x.jobs.clear();
    for (size_t j = begin; j < end; ++j)
        if (partial[j - begin]) x.jobs.push_back(jobs[j]);
    if (x.jobs.empty()) return;
    x.bits = bits;
    x.busy = true;
    x.group.run([this, &x] {
        tbb::parallel_for(size_t(0), x.jobs.size(), [&](size_t j) {
            const PairJob& job = x.jobs[j];
            Extractor{t_, lead_->leafy_, job, x.bits + job.word_offset, x.sinks}.run();
        });
    });
}

// Waits for the slot's background extraction and takes its links.
void Frontier::finish_extraction(int slot) {
    Extraction& x = extraction_[slot];
    if (!x.busy) return;
    const auto te = Clock::now();
    x.group.wait();
    x.busy = false;
    collect_sinks(x.sinks);
    st_.seconds_extract += seconds_since(te);
}

// Moves the sinks' blocks to the pieces and counts their link ends (or only counts the links).
void Frontier::collect_sinks(Sinks& sinks) {
    const size_t first = pieces.size();
    for (LinkSink& sk : sinks) {
        for (auto& blk : sk.blocks) pieces.push_back(std::move(blk));
        sk.blocks.clear();
    }
    if (params_.keep_links) {
        std::vector<std::span<const Link>> fresh;
        for (size_t c = first; c < pieces.size(); ++c) fresh.emplace_back(pieces[c]);
        lead_->arrays.count(fresh);
    } else {
        for (size_t c = first; c < pieces.size(); ++c) counted_links += pieces[c].size();
        pieces.resize(first);
    }
}

// The split pairs' children, a slice of at most about max_level_pairs children at a time
// (the children of one pair are never cut apart), each slice resolved and then settled. With
// lanes, several slices are offered to all lanes (offer).
void Frontier::split(const std::vector<NodePairRef>& level, const std::vector<Kind>& kinds,
                     std::vector<uint8_t>& full) {
    std::vector<uint8_t> nks(level.size(), 0);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, level.size(), 4096), [&](const auto& r) {
        for (size_t i = r.begin(); i < r.end(); ++i)
            if (kinds[i] == Kind::kSplit) nks[i] = uint8_t(num_kids(level[i]));
    });
    // (Smaller slices to share among lanes, about eight a lane, made many small levels and
    // batches: on the GPU each costs a synchronous decide and a launch, and the build took
    // 1.3-1.8x longer: docs/results.md "Construction lanes".)
    std::vector<size_t> parents;    // the split pairs, slice after slice
    std::vector<size_t> starts{0};  // slice s: parents[starts[s], starts[s + 1])
    uint64_t kids = 0;
    for (size_t i = 0; i < level.size(); ++i) {
        if (kinds[i] != Kind::kSplit) continue;
        if (kids > 0 && kids + nks[i] > fp_.max_level_pairs)
            starts.push_back(parents.size()), kids = 0;
        parents.push_back(i);
        kids += nks[i];
    }
    if (parents.empty()) return;
    starts.push_back(parents.size());
    const size_t slices = starts.size() - 1;
    auto one = [&](Frontier& lane, size_t s) {
        const std::span<const size_t> slice(parents.data() + starts[s], starts[s + 1] - starts[s]);
        lane.resolve_slice(level, slice, nks, full);
    };
    if (slices > 1 && pool())
        offer(slices, one);
    else
        for (size_t s = 0; s < slices; ++s) one(*this, s);
}

// The children of `parents` (pairs of `level`), resolved, then their parents settled.
void Frontier::resolve_slice(const std::vector<NodePairRef>& level, std::span<const size_t> parents,
                             const std::vector<uint8_t>& nks, std::vector<uint8_t>& full) {
    std::vector<uint64_t> first(parents.size() + 1, 0);
    for (size_t k = 0; k < parents.size(); ++k) first[k + 1] = first[k] + nks[parents[k]];
    std::vector<NodePairRef> kids(first.back());
    tbb::parallel_for(size_t(0), parents.size(), [&](size_t k) {
        NodePairRef* out = kids.data() + first[k];
        for_each_child_pair(t_, level[parents[k]].a, level[parents[k]].b,
                            [&](int32_t x, int32_t y) {
                                *out++ = NodePairRef{x, y};
                            });
    });
    const std::vector<uint8_t> kid_full = resolve(kids);
    settle(kids, kid_full, parents, first, full);
}

// Resolves slice s of `o` and the next ones left, reporting each done (the next is taken first,
// so `o` is never touched after its last slice is reported).
void Frontier::take(Offer& o, size_t s) {
    const size_t slices = o.slices;  // (o may be gone once its last slice is reported)
    while (s < slices) {
        std::exception_ptr error;
        try {
            (*o.one)(*this, s);
        } catch (...) {
            error = std::current_exception();
        }
        const size_t next = o.next.fetch_add(1);
        {
            std::lock_guard<std::mutex> lock(pool()->m);
            if (error && !o.error) o.error = error;
            ++o.done;
        }
        pool()->cv.notify_all();
        s = next;
    }
}

// one(lane, s) for every slice s by this lane and whichever lanes are free; returns when all are
// done, with the first error thrown.
void Frontier::offer(size_t slices, const std::function<void(Frontier&, size_t)>& one) {
    Offer o;
    o.slices = slices;
    o.one = &one;
    {
        std::lock_guard<std::mutex> lock(pool()->m);
        pool()->open.push_back(&o);
    }
    pool()->cv.notify_all();
    take(o, o.next.fetch_add(1));
    std::unique_lock<std::mutex> lock(pool()->m);
    pool()->cv.wait(lock, [&] { return o.done == slices; });
    std::erase(pool()->open, &o);
    lock.unlock();
    if (o.error) std::rethrow_exception(o.error);
}

// A helper lane's thread: takes offered slices until the lead stops the pool.
void Frontier::serve(int threads) {
    tbb::task_arena arena(threads);
    arena.execute([&] {
        std::unique_lock<std::mutex> lock(pool()->m);
        for (;;) {
            const auto [o, s] = pool()->claim();
            if (o) {
                lock.unlock();
                take(*o, s);
                lock.lock();
            } else if (pool()->stop) {
                break;
            } else {
                pool()->cv.wait(lock);
            }
        }
        lock.unlock();
        finish_extraction(0);
        finish_extraction(1);
    });
}

// A split pair is full when all its children are; otherwise each full child makes its link.
void Frontier::settle(const std::vector<NodePairRef>& kids, const std::vector<uint8_t>& kid_full,
                      std::span<const size_t> parents, const std::vector<uint64_t>& first,
                      std::vector<uint8_t>& full) {
    tbb::parallel_for(size_t(0), parents.size(), [&](size_t k) {
        bool f = true;
        for (uint64_t c = first[k]; c < first[k + 1] && f; ++c) f = kid_full[c];
        full[parents[k]] = f;
        if (f) return;
        LinkSink& out = sinks_.local();
        for (uint64_t c = first[k]; c < first[k + 1]; ++c)
            if (kid_full[c]) out.push(kids[c].a, kids[c].b);
    });
    collect_sinks(sinks_);
}

}  // namespace vmap::detail
