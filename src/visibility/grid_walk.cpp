// The grid-walk occluder kernel of reference [7] (see grid_walk.h) and its CPU backend.
#include "octree/records.h"
#include "visibility/grid_walk.h"

#include <tbb/task_arena.h>

#include <memory>
#include <string>

#include "visibility/host_backend.h"
#include "visibility/leaf_pair.h"
#include "vmap/parallel.h"

namespace vmap::detail {

LeafGrid::LeafGrid(const Octree& t) : t_(t), level_(t.height()) {
    cell_ = double(t.root_size()) / double(1u << level_);
    child_.assign(size_t(t.num_nodes()) * 8, -1);
    for (int32_t n = 0; n < t.num_nodes(); ++n) {
        if (t.is_leaf(n)) continue;
        const Vec3 pc = t.spheres()[n].center;  // the cell centre (octree.cpp)
        t.for_each_child(n, [&](int32_t c) {
            const Vec3 cc = t.spheres()[c].center;
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
            return t_.node_leaf()[n];
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

bool grid_walk_leaf_pair_visible(const Octree& t, const LeafGrid& g, int32_t a, int32_t b,
                                 const VisibilityParams& vp, WorkCounters* wc) {
    const PairSegment s = pair_segment(leaf_discs(t)[a], leaf_discs(t)[b], vp);
    if (!s.faces) return false;
    wc->facing_pairs++;
    // Only crossings with eps < t < 1 - eps count (counts_as_occluder), so only that part of
    // the segment is walked, a little wider for rounding (as leaf_pair_visible does).
    int occluders = 0;
    return g.for_each_leaf(
        s.p, s.q, vp.eps * 0.999f, 1.f - vp.eps * 0.999f, a, b, &wc->cells_stepped,
        [&](int32_t l) {
            wc->occluder_tests++;
            occluders += occluder_weight(s, leaf_discs(t)[l], vp);
            return occluders < vp.K;
        });
}

namespace {

// The same batching as the sphere-walk CPU backend (host_backend.h).
class GridWalkBackend final : public HostBackend<GridWalkBackend> {
  public:
    std::string name() const override {
        return "cpu grid walk (" + cpu_threads() + ")";
    }

    void prepare(const Octree& tree, const VisibilityParams& vp, uint64_t) override {
        tree_ = &tree;
        grid_ = std::make_unique<LeafGrid>(tree);
        vp_ = vp;
    }

    bool visible(int32_t a, int32_t b, WorkCounters* wc) const {
        return grid_walk_leaf_pair_visible(*tree_, *grid_, a, b, vp_, wc);
    }

  private:
    const Octree* tree_ = nullptr;
    std::unique_ptr<LeafGrid> grid_;
    VisibilityParams vp_;
};

}  // namespace

std::unique_ptr<Backend> make_grid_walk_backend() { return std::make_unique<GridWalkBackend>(); }

}  // namespace vmap::detail
