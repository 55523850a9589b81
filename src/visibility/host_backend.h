// The batching both CPU backends share (the box walk of leaf_pair.h, in packets, and the grid
// walk of grid_walk.h): a batch is evaluated on all cores when it is submitted. Work items are
// words: 32 consecutive columns of one row (neighbouring segments, so the walks share cache
// lines), indexed across jobs by a prefix sum. Derived supplies either
//   bool visible(int32_t a, int32_t b, WorkCounters* wc) const;
// and may supply, to evaluate a job's pairs with state prepared once per job and thread,
//   struct JobState; void begin_job(const PairJob&, JobState&) const;
//   bool visible(JobState&, int32_t a, int32_t b, WorkCounters* wc) const;
// or, with JobState and begin_job, to evaluate up to kPacketLanes pairs of one job at once
// (packet_walk.h),
//   static constexpr int kPacketLanes;
//   uint32_t visible_packet(JobState&, const int32_t* a, const int32_t* b, int count,
//                           WorkCounters* wc) const;  // the mask of the visible pairs;
// which counts facing pairs, node and occluder tests (pairs and visible pairs are counted here),
// and, to keep pairs that cannot be visible out of the packets (which then fill with pairs that
// walk),
//   bool may_be_visible(int32_t a, int32_t b) const;  // false: the pair is not visible.
// or, the same for up to 8 columns of two rows at once,
//   uint32_t facing_rows(int32_t a0, int32_t a1, int32_t b0, int32_t n) const;
//   // bit i: (a0, b0 + i) may be visible, bit 8 + i: (a1, b0 + i)
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <vector>

#include "visibility/backend.h"

namespace vmap::detail {

template <class Derived>
class HostBackend : public Backend {
  public:
    void submit(std::span<const PairJob> jobs, uint64_t words, int slot) override {
        const auto t0 = std::chrono::steady_clock::now();
        const Derived& self = static_cast<const Derived&>(*this);
        std::vector<uint32_t>& bits = buf_[slot];
        bits.assign(words, 0u);
        std::vector<uint64_t> first(jobs.size() + 1, 0);
        for (size_t i = 0; i < jobs.size(); ++i) first[i + 1] = first[i] + job_words(jobs[i]);
        tbb::combinable<WorkCounters> counters;
        tbb::enumerable_thread_specific<State> states;
        tbb::parallel_for(tbb::blocked_range<uint64_t>(0, first.back(), 16),
                          [&](const auto& range) {
                              if (progress_ && progress_->cancelled()) return;
                              WorkCounters& wc = counters.local();
                              // The state of the job this thread worked on last carries over to the
                              // next range of the same job (a job's shaft is prepared once per
                              // thread, not once per 16 words).
                              State& st = states.local();
                              const Range rg{jobs.data(),   first.data(), jobs.size(),
                                             range.begin(), range.end(),  bits.data()};
                              if constexpr (packets())
                                  packet_range(self, rg, st, wc);
                              else
                                  pair_range(self, rg, st, wc);
                              if (progress_) progress_->add(rg.pairs);
                          });
        if (progress_) progress_->throw_if_cancelled();
        pending_[slot] = counters.combine([](WorkCounters x, const WorkCounters& y) {
            x += y;
            return x;
        });
        busy_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }

    const uint32_t* wait(int slot, WorkCounters& wc) override {
        wc += pending_[slot];
        pending_[slot] = {};
        return buf_[slot].data();
    }

    double busy_seconds() const override { return busy_; }
    bool counts_progress() const override { return true; }
    // About 4.5e7 leaf pairs (of all, decided or walked) per second per core with the packet
    // walk in vectors and node decisions (docs/results.md "The CPU walk in vectors": 5.1e7 on
    // the default scene, user time, AVX-512; 3e7 before, and about that without AVX-512).
    double expected_pairs_per_second() const override {
        return 4.5e7 * tbb::this_task_arena::max_concurrency();
    }

  private:
    struct NoState {};
    template <class D>
    static auto state_type() {
        if constexpr (requires { typename D::JobState; })
            return typename D::JobState{};
        else
            return NoState{};
    }
    // (Functions, not constants: Derived is complete only where they are called.)
    static constexpr bool job_state() {
        return requires { typename Derived::JobState; };
    }
    static constexpr bool packets() {
        return requires { Derived::kPacketLanes; };
    }
    struct State {
        int64_t job = -1;
        decltype(state_type<Derived>()) state;
    };
    // The words [begin, end) of a batch (indexed across its jobs by the prefix sum `first`,
    // num_jobs + 1 long) and the batch's table.
    struct Range {
        const PairJob* jobs;
        const uint64_t* first;
        size_t num_jobs;
        uint64_t begin, end;
        uint32_t* bits;
        mutable uint64_t pairs = 0;  // leaf pairs evaluated
        size_t first_job() const {
            return std::upper_bound(first, first + num_jobs + 1, begin) - first - 1;
        }
    };
    // The job of word `item` (j: the job of a word before it), its state made current.
    static size_t enter_job(const Derived& self, const Range& rg, uint64_t item, size_t j,
                            State& st) {
        while (item >= rg.first[j + 1]) ++j;
        if constexpr (job_state()) {
            if (st.job != int64_t(j)) self.begin_job(rg.jobs[j], st.state), st.job = j;
        }
        return j;
    }
    // The row leaf and the column range [c0, c1) of word `local` of a job.
    struct WordPos {
        int32_t a, c0, c1;
    };
    static WordPos word_pos(const PairJob& job, uint64_t local) {
        const uint64_t rw = row_words(job.cols);
        const int32_t c0 = static_cast<int32_t>(local % rw) * 32;
        return {job.row0 + static_cast<int32_t>(local / rw), c0, std::min(job.cols, c0 + 32)};
    }

    // One pair at a time (Derived::visible).
    static void pair_range(const Derived& self, const Range& rg, State& st, WorkCounters& wc) {
        size_t j = rg.first_job();
        for (uint64_t item = rg.begin; item < rg.end; ++item) {
            j = enter_job(self, rg, item, j, st);
            const PairJob& job = rg.jobs[j];
            const uint64_t local = item - rg.first[j];
            const WordPos at = word_pos(job, local);
            uint32_t word = 0;
            for (int32_t c = at.c0; c < at.c1; ++c) {
                bool vis;
                if constexpr (job_state())
                    vis = self.visible(st.state, at.a, job.col0 + c, &wc);
                else
                    vis = self.visible(at.a, job.col0 + c, &wc);
                if (vis) word |= 1u << (c - at.c0);
            }
            wc.pairs += at.c1 - at.c0;
            rg.pairs += at.c1 - at.c0;
            wc.visible_pairs += __builtin_popcount(word);
            rg.bits[job.word_offset + local] = word;
        }
    }

    // Derived::kPacketLanes pairs at a time (Derived::visible_packet), pairs of one job in tiles
    // of 8 columns by a few rows (a packet's segments then spread less at both ends than 32
    // columns of one row): the words of the range are taken in chunks of up to kChunk words
    // of one job, and a chunk's pairs go by word column, block of 8 columns, row, column.
    static void packet_range(const Derived& self, const Range& rg, State& st, WorkCounters& wc) {
        Packer pk{self, st, wc, rg};
        size_t j = rg.first_job();
        for (uint64_t item = rg.begin; item < rg.end;) {
            j = enter_job(self, rg, item, j, st);
            const PairJob& job = rg.jobs[j];
            const uint64_t local = item - rg.first[j];
            const uint64_t n = std::min<uint64_t>({kChunk, rg.end - item, rg.first[j + 1] - item});
            const uint64_t rw = row_words(job.cols);
            WordPos pos[kChunk];
            for (uint64_t k = 0; k < n; ++k) pos[k] = word_pos(job, local + k);
            uint32_t* const w0 = rg.bits + job.word_offset + local;
            for (uint64_t k0 = 0; k0 < std::min(n, rw); ++k0)
                for (int32_t blk = 0; blk < 32; blk += kBlock) {
                    // The words k0, k0 + rw, ...: one column range in consecutive rows.
                    const int32_t cb = pos[k0].c0 + blk;
                    const int32_t ce = std::min(pos[k0].c1, pos[k0].c0 + blk + kBlock);
                    if (cb >= ce) continue;
                    if constexpr (requires { self.facing_rows(0, 0, 0, 0); }) {
                        uint64_t k = k0;
                        for (; k + rw < n; k += 2 * rw) {  // two rows at a time
                            const uint32_t m =
                                self.facing_rows(pos[k].a, pos[k + rw].a, job.col0 + cb, ce - cb);
                            pk.add_mask(pos[k].a, job.col0 + cb, ce - cb, m & 0xffu, w0 + k,
                                        cb - pos[k].c0);
                            pk.add_mask(pos[k + rw].a, job.col0 + cb, ce - cb, m >> 8,
                                        w0 + k + rw, cb - pos[k].c0);
                        }
                        if (k < n) {
                            const uint32_t m =
                                self.facing_rows(pos[k].a, pos[k].a, job.col0 + cb, ce - cb);
                            pk.add_mask(pos[k].a, job.col0 + cb, ce - cb, m & 0xffu, w0 + k,
                                        cb - pos[k].c0);
                        }
                    } else {
                        for (uint64_t k = k0; k < n; k += rw)
                            for (int32_t c = cb; c < ce; ++c)
                                pk.add(pos[k].a, job.col0 + c, w0 + k, 1u << (c - pos[k].c0));
                    }
                }
            item += n;
            if (item >= rg.end || item >= rg.first[j + 1]) pk.flush();  // pairs of one job

        }
    }
    static constexpr uint64_t kChunk = 16;
    static constexpr int32_t kBlock = 8;
    // The pairs of one packet and where their bits go.
    struct Packer {
        static constexpr int P = Derived::kPacketLanes;
        const Derived& self;
        State& st;
        WorkCounters& wc;
        const Range& rg;
        int32_t pa[P] = {}, pb[P] = {};
        uint32_t* word[P] = {};
        uint32_t bit[P] = {};
        int count = 0;
        void add(int32_t a, int32_t b, uint32_t* w, uint32_t m) {
            if constexpr (requires { self.may_be_visible(a, b); }) {
                if (!self.may_be_visible(a, b)) {  // not visible: its bit stays 0
                    wc.pairs++;
                    rg.pairs++;
                    return;
                }
            }
            pa[count] = a, pb[count] = b, word[count] = w, bit[count] = m;
            if (++count == P) flush();
        }
        // Columns b0 .. b0 + n - 1 of row a (bits bit0 .. of word w): those in m (that face:
        // Derived::facing_rows) go into packets; the others are not visible.
        void add_mask(int32_t a, int32_t b0, int32_t n, uint32_t m, uint32_t* w, int32_t bit0) {
            const int32_t skipped = n - __builtin_popcount(m);
            wc.pairs += uint64_t(skipped);
            rg.pairs += uint64_t(skipped);
            for (; m; m &= m - 1) {
                const int i = __builtin_ctz(m);
                pa[count] = a, pb[count] = b0 + i, word[count] = w, bit[count] = 1u << (bit0 + i);
                if (++count == P) flush();
            }
        }
        void flush() {
            if (count == 0) return;
            const uint32_t vis = self.visible_packet(st.state, pa, pb, count, &wc);
            for (uint32_t m = vis; m; m &= m - 1) {  // the visible lanes only
                const int i = __builtin_ctz(m);
                *word[i] |= bit[i];
            }
            wc.pairs += count;
            rg.pairs += count;
            wc.visible_pairs += __builtin_popcount(vis);
            count = 0;
        }
    };

  protected:
    // A copy made for a lane starts with no batches and no time of its own.
    void start_lane() {
        busy_ = 0;
        for (auto& b : buf_) b = {};
        for (auto& p : pending_) p = {};
    }

  private:
    double busy_ = 0;
    std::vector<uint32_t> buf_[2];
    WorkCounters pending_[2];
};

}  // namespace vmap::detail
