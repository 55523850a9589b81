// Leaf-pair visibility on all CPU cores (oneTBB), the predicate from leaf_pair.h.
#include <tbb/task_arena.h>

#include <memory>
#include <string>
#include <utility>

#include "octree/records.h"
#include "visibility/host_backend.h"
#include "visibility/leaf_pair.h"
#include "visibility/node_pair.h"
#include "visibility/packet_walk.h"
#include "vmap/parallel.h"

namespace vmap::detail {
namespace {

class CpuBackend final : public HostBackend<CpuBackend> {
  public:
    std::string name() const override {
        return "cpu (" + cpu_threads() + ")";
    }

    void prepare(const Octree& tree, const VisibilityParams& vp, uint64_t) override {
        view_ = octree_view(tree);
        columns_ = LeafColumns(view_);
        parent_ = tree.parent().data();
        vp_ = vp;
    }

    // A lane (Backend::lane): the same tree and bounds, batch buffers of its own. Only when
    // asked for (BuildParams::lanes): on the CPU one frontier already keeps every core busy.
    std::unique_ptr<Backend> lane() override {
        auto l = std::make_unique<CpuBackend>(*this);
        l->start_lane();
        return l;
    }

    // With node bounds (construction "nodes"), a job of at least kShaftPairs leaf pairs walks
    // only the part of the tree the shaft of its enclosing pair meets (make_list; the same
    // answers, less work), built when its first facing pair needs a walk.
    static constexpr uint64_t kShaftPairs = 64;
    void set_node_context(const NodePairContext* ctx) override {
        ctx_ = ctx;
        pads_ = ctx && ctx->margin > 0 ? node_pads(*ctx) : std::vector<NodePad>{};
    }
    // The pairs of a job walk in packets (packet_walk.h: the answers and counts of
    // leaf_pair_visible, less time a pair).
    static constexpr int kPacketLanes = 32;
    struct JobState {
        const PairJob* job = nullptr;
        bool ready = false;
        std::vector<WalkNode> list;  // the shaft list of node pair (list_a, list_b)
        std::vector<int32_t> scratch;
        int32_t list_a = -1, list_b = -1;
        OctreeView view;
        SegmentPacket<kPacketLanes> packet;
    };
    void begin_job(const PairJob& job, JobState& s) const {
        s.job = &job;
        s.view = view_;
        s.ready = !ctx_ || !(ctx_->margin > 0) || uint64_t(job.rows) * job.cols < kShaftPairs;
    }
    // Only pairs that face go into packets (leaf_pair_visible: no other is visible), found 8
    // columns of two rows at a time (packet_walk.h facing_rows).
    uint32_t facing_rows(int32_t a0, int32_t a1, int32_t b0, int32_t n) const {
        return detail::facing_rows(view_, columns_, a0, a1, b0, n, vp_);
    }
    uint32_t visible_packet(JobState& s, const int32_t* a, const int32_t* b, int count,
                            WorkCounters* wc) const {
        if (!s.packet.load_faced(view_, a, b, count, vp_, wc)) return 0;
        if (!s.ready) make_list(s);
        return s.packet.walk(s.view, vp_, wc);
    }

  private:
    // The shaft list of the job's enclosing pair (A', B') = enclosing(a, b), made once per thread
    // for all the jobs under that pair, which come one after another (the children of one split
    // pair). Every leaf pair under (a, b) is one under (A', B') (a lies under A', b under B'), and
    // the list (box_walk_nodes: shaft_walk_nodes' list without its plane and disc tests, which
    // left the walks' node tests unchanged at 60% of the list's cost) gives every leaf pair
    // under its node pair the answers of the whole walk, so the answers stay those of
    // leaf_pair_visible. Measured on the default scene (docs/results.md): one list per job from
    // the root cost 18% of the build, a job's list filtered from (A', B')'s 11% (its walks test a
    // sixth fewer nodes), and sharing (A', B')'s list costs almost nothing for about 20% more
    // node tests: the least time of the three. Lists filtered again per job or per chunk of 4-16
    // rows (by the box test alone, from the chunk's centroid boxes) cut the node tests by 20-31%
    // but cost more time than they saved (docs/results.md, "The CPU walk in vectors").
    void make_list(JobState& s) const {
        const auto [oa, ob] = enclosing(s.job->a, s.job->b);
        if (s.list_a != oa || s.list_b != ob) {
            box_walk_nodes(*ctx_, oa, ob, s.list, s.scratch, pads_.data());
            s.list_a = oa, s.list_b = ob;
        }
        s.view.walk = s.list.data();
        s.view.num_nodes = int32_t(s.list.size());
        s.ready = true;
    }
    // The pair of the parents of a and b (the split pair the job came from, or one that holds
    // it), one of them only where the other's parent would hold both, or (a, b) itself.
    std::pair<int32_t, int32_t> enclosing(int32_t a, int32_t b) const {
        const int32_t* skip = ctx_->skip;
        auto disjoint = [&](int32_t x, int32_t y) {
            return x >= 0 && y >= 0 && !(y >= x && y < skip[x]) && !(x >= y && x < skip[y]);
        };
        const int32_t pa = parent_[a], pb = parent_[b];
        if (disjoint(pa, pb)) return {pa, pb};
        if (disjoint(a, pb)) return {a, pb};
        if (disjoint(pa, b)) return {pa, b};
        return {a, b};
    }

    const int32_t* parent_ = nullptr;
    OctreeView view_;
    LeafColumns columns_;
    std::vector<NodePad> pads_;  // per node, for box_walk_nodes
    VisibilityParams vp_;
    const NodePairContext* ctx_ = nullptr;
};

}  // namespace

std::unique_ptr<Backend> make_cpu_backend() { return std::make_unique<CpuBackend>(); }

}  // namespace vmap::detail
