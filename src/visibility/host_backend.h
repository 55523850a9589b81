// The batching both CPU backends share (the sphere walk of leaf_pair.h and the grid walk of
// grid_walk.h): a batch is evaluated on all cores when it is submitted. Work items are words:
// 32 consecutive columns of one row (neighbouring segments, so the walks share cache lines),
// indexed across jobs by a prefix sum. Derived supplies
//   bool visible(int32_t a, int32_t b, WorkCounters* wc) const;
// and may supply, to evaluate a job's pairs with state prepared once per job and thread,
//   struct JobState; void begin_job(const PairJob&, JobState&) const;
//   bool visible(JobState&, int32_t a, int32_t b, WorkCounters* wc) const;
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
        constexpr bool kJobState = requires { typename Derived::JobState; };
        struct State {
            int64_t job = -1;
            decltype(state_type<Derived>()) state;
        };
        tbb::enumerable_thread_specific<State> states;
        tbb::parallel_for(
            tbb::blocked_range<uint64_t>(0, first.back(), 16), [&](const auto& range) {
                if (progress_ && progress_->cancelled()) return;
                WorkCounters& wc = counters.local();
                uint64_t range_pairs = 0;
                // The state of the job this thread worked on last carries over to the next
                // range of the same job (a job's shaft is prepared once per thread, not once
                // per 16 words).
                State& st = states.local();
                size_t j =
                    std::upper_bound(first.begin(), first.end(), range.begin()) - first.begin() - 1;
                for (uint64_t item = range.begin(); item < range.end(); ++item) {
                    while (item >= first[j + 1]) ++j;
                    const PairJob& job = jobs[j];
                    if constexpr (kJobState) {
                        if (st.job != int64_t(j)) self.begin_job(job, st.state), st.job = j;
                    }
                    const uint64_t rw = row_words(job.cols);
                    const uint64_t local = item - first[j];
                    const int32_t r = static_cast<int32_t>(local / rw);
                    const int32_t c0 = static_cast<int32_t>(local % rw) * 32;
                    const int32_t c1 = std::min(job.cols, c0 + 32);
                    const int32_t a = job.row0 + r;
                    uint32_t word = 0;
                    for (int32_t c = c0; c < c1; ++c) {
                        bool vis;
                        if constexpr (kJobState)
                            vis = self.visible(st.state, a, job.col0 + c, &wc);
                        else
                            vis = self.visible(a, job.col0 + c, &wc);
                        if (vis) word |= 1u << (c - c0);
                    }
                    wc.pairs += c1 - c0;
                    range_pairs += c1 - c0;
                    wc.visible_pairs += __builtin_popcount(word);
                    bits[job.word_offset + local] = word;
                }
                if (progress_) progress_->add(range_pairs);
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
    // About 2.5e6 leaf pairs per second per core (docs/results.md; 2-4e6 by scene).
    double expected_pairs_per_second() const override {
        return 2.5e6 * tbb::this_task_arena::max_concurrency();
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

    double busy_ = 0;
    std::vector<uint32_t> buf_[2];
    WorkCounters pending_[2];
};

}  // namespace vmap::detail
