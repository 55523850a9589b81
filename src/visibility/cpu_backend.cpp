// Leaf-pair visibility on all CPU cores (oneTBB), the predicate from leaf_pair.h.
#include <tbb/task_arena.h>

#include <string>

#include "octree/records.h"
#include "visibility/host_backend.h"
#include "visibility/leaf_pair.h"
#include "visibility/node_pair.h"

namespace vmap::detail {
namespace {

class CpuBackend final : public HostBackend<CpuBackend> {
  public:
    std::string name() const override {
        return "cpu (" + std::to_string(tbb::this_task_arena::max_concurrency()) + " threads)";
    }

    void prepare(const Octree& tree, const VisibilityParams& vp, uint64_t) override {
        view_ = octree_view(tree);
        vp_ = vp;
    }

    bool visible(int32_t a, int32_t b, WorkCounters* wc) const {
        return leaf_pair_visible<true>(view_, a, b, vp_, wc);
    }

    // With node bounds (construction "nodes"), a job of at least kShaftPairs leaf pairs walks
    // only the part of the tree its shaft meets (shaft_walk_nodes: the same answers, less
    // work), built when its first facing pair needs a walk.
    static constexpr uint64_t kShaftPairs = 64;
    void set_node_context(const NodePairContext* ctx) override { ctx_ = ctx; }
    struct JobState {
        const PairJob* job = nullptr;
        bool ready = false;
        std::vector<WalkNode> walk;
        std::vector<int32_t> scratch;
        OctreeView view;
    };
    void begin_job(const PairJob& job, JobState& s) const {
        s.job = &job;
        s.view = view_;
        s.ready = !ctx_ || !(ctx_->margin > 0) || uint64_t(job.rows) * job.cols < kShaftPairs;
    }
    bool visible(JobState& s, int32_t a, int32_t b, WorkCounters* wc) const {
        if (!s.ready) {
            if (!pair_segment(view_.leaves[a], view_.leaves[b], vp_).faces) return false;
            shaft_walk_nodes(*ctx_, s.job->a, s.job->b, s.walk, s.scratch);
            s.view.walk = s.walk.data();
            s.view.num_nodes = int32_t(s.walk.size());
            s.ready = true;
        }
        return leaf_pair_visible<true>(s.view, a, b, vp_, wc);
    }

  private:
    OctreeView view_;
    VisibilityParams vp_;
    const NodePairContext* ctx_ = nullptr;
};

}  // namespace

std::unique_ptr<Backend> make_cpu_backend() { return std::make_unique<CpuBackend>(); }

}  // namespace vmap::detail
