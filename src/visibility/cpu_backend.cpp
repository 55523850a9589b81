// Leaf-pair visibility on all CPU cores (oneTBB), the predicate from leaf_pair.h.
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <vector>

#include "visibility/backend.h"
#include "visibility/leaf_pair.h"

namespace vmap::detail {
namespace {

class CpuBackend final : public Backend {
  public:
    std::string name() const override {
        return "cpu (" + std::to_string(tbb::this_task_arena::max_concurrency()) + " threads)";
    }

    void prepare(const Octree& tree, const VisibilityParams& vp, uint64_t) override {
        view_ = tree.view();
        vp_ = vp;
    }

    void submit(std::span<const PairJob> jobs, uint64_t words, int slot) override {
        const auto t0 = std::chrono::steady_clock::now();
        std::vector<uint32_t>& bits = buf_[slot];
        bits.assign(words, 0u);
        // Work items are words: 32 consecutive columns of one row (neighbouring segments, so
        // the walks share cache lines). Index them across jobs by a prefix sum.
        std::vector<uint64_t> first(jobs.size() + 1, 0);
        for (size_t i = 0; i < jobs.size(); ++i) first[i + 1] = first[i] + job_words(jobs[i]);
        tbb::combinable<WorkCounters> counters;
        tbb::parallel_for(
            tbb::blocked_range<uint64_t>(0, first.back(), 16), [&](const auto& range) {
                WorkCounters& wc = counters.local();
                size_t j =
                    std::upper_bound(first.begin(), first.end(), range.begin()) - first.begin() - 1;
                for (uint64_t item = range.begin(); item < range.end(); ++item) {
                    while (item >= first[j + 1]) ++j;
                    const PairJob& job = jobs[j];
                    const uint64_t rw = row_words(job.cols);
                    const uint64_t local = item - first[j];
                    const int32_t r = static_cast<int32_t>(local / rw);
                    const int32_t c0 = static_cast<int32_t>(local % rw) * 32;
                    const int32_t c1 = std::min(job.cols, c0 + 32);
                    const int32_t a = job.row0 + r;
                    uint32_t word = 0;
                    for (int32_t c = c0; c < c1; ++c)
                        if (leaf_pair_visible<true>(view_, a, job.col0 + c, vp_, &wc))
                            word |= 1u << (c - c0);
                    wc.pairs += c1 - c0;
                    wc.visible_pairs += __builtin_popcount(word);
                    bits[job.word_offset + local] = word;
                }
            });
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

  private:
    double busy_ = 0;
    OctreeView view_;
    VisibilityParams vp_;
    std::vector<uint32_t> buf_[2];
    WorkCounters pending_[2];
};

}  // namespace

std::unique_ptr<Backend> make_cpu_backend() { return std::make_unique<CpuBackend>(); }

}  // namespace vmap::detail
