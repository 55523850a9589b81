// The grid-walk occluder kernel of reference [7] (see bresenham.h) and its CPU backend.
#include "visibility/bresenham.h"

#include <tbb/combinable.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <chrono>

#include "visibility/leaf_pair.h"

namespace vmap::detail {

LeafGrid::LeafGrid(const Octree& t) : t_(t), level_(t.height()) {
    cell_ = double(t.root_size) / double(1u << level_);
    child_.assign(size_t(t.num_nodes()) * 8, -1);
    for (int32_t n = 0; n < t.num_nodes(); ++n) {
        if (t.is_leaf(n)) continue;
        const Vec3 pc = t.spheres[n].center;  // the cell centre (octree.cpp)
        t.for_each_child(n, [&](int32_t c) {
            const Vec3 cc = t.spheres[c].center;
            const int oct = (cc.x > pc.x ? 1 : 0) | (cc.y > pc.y ? 2 : 0) | (cc.z > pc.z ? 4 : 0);
            child_[size_t(n) * 8 + oct] = c;
        });
    }
}

int32_t LeafGrid::lookup(uint32_t x, uint32_t y, uint32_t z, int* lvl) const {
    int32_t n = 0;
    for (int l = 0;; ++l) {
        if (t_.is_leaf(n)) {
            *lvl = l;
            return t_.node_leaf[n];
        }
        const int sh = level_ - 1 - l;
        const int oct = ((x >> sh) & 1) | ((y >> sh) & 1) << 1 | ((z >> sh) & 1) << 2;
        const int32_t c = child_[size_t(n) * 8 + oct];
        if (c < 0) {
            *lvl = l + 1;  // an empty octant: no points, no leaf
            return -1;
        }
        n = c;
    }
}

bool bresenham_leaf_pair_visible(const Octree& t, const LeafGrid& g, int32_t a, int32_t b,
                                 const VisibilityParams& vp, WorkCounters* wc) {
    const LeafDisc la = t.leaves[a], lb = t.leaves[b];
    const Vec3 p = la.centroid;
    const Vec3 d = lb.centroid - p;
    const float len = sqrtf(length2(d));
    if (!(len > 0.f)) return false;
    if (!leaves_face(la, lb, d, len, vp)) return false;
    wc->facing_pairs++;
    // Only crossings with eps < t < 1 - eps count (is_actual_occluder), so only that part of
    // the segment is walked, a little wider for rounding (as leaf_pair_visible does).
    int occluders = 0;
    return g.for_each_leaf(
        p, lb.centroid, vp.eps * 0.999f, 1.f - vp.eps * 0.999f, a, b, &wc->cells_stepped,
        [&](int32_t l) {
            wc->occluder_tests++;
            return !(is_actual_occluder(p, d, len, t.leaves[l], vp) && ++occluders >= vp.K);
        });
}

namespace {

// The same batching as the sphere-walk CPU backend (cpu_backend.cpp): work items are words of
// 32 consecutive columns of one row, across jobs by a prefix sum.
class BresenhamBackend final : public Backend {
  public:
    std::string name() const override {
        return "cpu bresenham (" + std::to_string(tbb::this_task_arena::max_concurrency()) +
               " threads)";
    }

    void prepare(const Octree& tree, const VisibilityParams& vp, uint64_t) override {
        tree_ = &tree;
        grid_ = std::make_unique<LeafGrid>(tree);
        vp_ = vp;
    }

    void submit(std::span<const PairJob> jobs, uint64_t words, int slot) override {
        const auto t0 = std::chrono::steady_clock::now();
        std::vector<uint32_t>& bits = buf_[slot];
        bits.assign(words, 0u);
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
                        if (bresenham_leaf_pair_visible(*tree_, *grid_, a, job.col0 + c, vp_, &wc))
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
    const Octree* tree_ = nullptr;
    std::unique_ptr<LeafGrid> grid_;
    VisibilityParams vp_;
    std::vector<uint32_t> buf_[2];
    WorkCounters pending_[2];
};

}  // namespace

std::unique_ptr<Backend> make_bresenham_backend() { return std::make_unique<BresenhamBackend>(); }

}  // namespace vmap::detail
