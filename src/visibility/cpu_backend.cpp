// Leaf-pair visibility on all CPU cores (oneTBB), the predicate from leaf_pair.h.
#include <tbb/task_arena.h>

#include <string>

#include "octree/records.h"
#include "visibility/host_backend.h"
#include "visibility/leaf_pair.h"
#include "visibility/node_pair.h"
#include "visibility/packet_walk.h"

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

    // With node bounds (construction "nodes"), a job of at least kShaftPairs leaf pairs walks
    // only the part of the tree its shaft meets (shaft_walk_nodes: the same answers, less
    // work), built when its first facing pair needs a walk.
    static constexpr uint64_t kShaftPairs = 64;
    void set_node_context(const NodePairContext* ctx) override { ctx_ = ctx; }
    // The pairs of a job walk in packets (packet_walk.h: the answers and counts of
    // leaf_pair_visible, less time a pair).
    static constexpr int kPacketLanes = 32;
    struct JobState {
        const PairJob* job = nullptr;
        bool ready = false;
        std::vector<WalkNode> walk;
        std::vector<int32_t> scratch;
        OctreeView view;
        SegmentPacket<kPacketLanes> packet;
    };
    void begin_job(const PairJob& job, JobState& s) const {
        s.job = &job;
        s.view = view_;
        s.ready = !ctx_ || !(ctx_->margin > 0) || uint64_t(job.rows) * job.cols < kShaftPairs;
    }
    uint32_t visible_packet(JobState& s, const int32_t* a, const int32_t* b, int count,
                            WorkCounters* wc) const {
        if (!s.packet.load(view_, a, b, count, vp_, wc)) return 0;
        if (!s.ready) {
            shaft_walk_nodes(*ctx_, s.job->a, s.job->b, s.walk, s.scratch);
            s.view.walk = s.walk.data();
            s.view.num_nodes = int32_t(s.walk.size());
            s.ready = true;
        }
        return s.packet.walk(s.view, vp_, wc);
    }

  private:
    OctreeView view_;
    VisibilityParams vp_;
    const NodePairContext* ctx_ = nullptr;
};

}  // namespace

std::unique_ptr<Backend> make_cpu_backend() { return std::make_unique<CpuBackend>(); }

}  // namespace vmap::detail
