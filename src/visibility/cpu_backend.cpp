// Leaf-pair visibility on all CPU cores (oneTBB), the predicate from leaf_pair.h.
#include <tbb/task_arena.h>

#include <string>

#include "visibility/host_backend.h"
#include "visibility/leaf_pair.h"

namespace vmap::detail {
namespace {

class CpuBackend final : public HostBackend<CpuBackend> {
  public:
    std::string name() const override {
        return "cpu (" + std::to_string(tbb::this_task_arena::max_concurrency()) + " threads)";
    }

    void prepare(const Octree& tree, const VisibilityParams& vp, uint64_t) override {
        view_ = tree.view();
        vp_ = vp;
    }

    bool visible(int32_t a, int32_t b, WorkCounters* wc) const {
        return leaf_pair_visible<true>(view_, a, b, vp_, wc);
    }

  private:
    OctreeView view_;
    VisibilityParams vp_;
};

}  // namespace

std::unique_ptr<Backend> make_cpu_backend() { return std::make_unique<CpuBackend>(); }

}  // namespace vmap::detail
