// The prior kernel of the paper's reference [7] (docs/design.md "Leaf-pair visibility"): potential
// occluders of a leaf pair are the leaves whose cells a 3D grid walk along the segment visits, at
// the octree's finest level, instead of the leaves reached by the hierarchical sphere/box walk of
// leaf_pair.h. The actual-occluder test and the K rule are the same (is_actual_occluder).
//
// The grid walk is the exact 3D DDA (Amanatides and Woo): every finest-level cell the segment
// passes through is visited, the supercover of Bresenham's 3D line, so it misses no cell the
// line touches. A leaf's cell is its octree cube; its occluder disc can reach outside that cube,
// and such an occluder is missed when the segment crosses the disc outside the cube: the known
// weakness of this kernel, which the sphere walk (bounding every disc) does not have.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <vector>

#include "visibility/backend.h"
#include "vmap/octree.h"
#include "vmap/visibility.h"

namespace vmap::detail {

// The finest-level grid over an octree: per node its eight children by octant (-1 where the
// octant is empty), so the leaf holding a grid cell is found by descending from the root.
class LeafGrid {
  public:
    explicit LeafGrid(const Octree& t);

    int level() const { return level_; }  // grid resolution is 2^level cells per axis
    // Leaves (other than a and b) whose cells segment p + t (q - p), t in [t0, t1], passes
    // through, each once, in order along the segment; f(leaf) returns false to stop. Adds the
    // cells stepped to *cells. Returns false when f stopped the walk.
    template <class F>
    bool for_each_leaf(Vec3 p, Vec3 q, float t0, float t1, int32_t a, int32_t b, uint64_t* cells,
                       F&& f) const;

  private:
    // The leaf holding cell (x, y, z), or -1 for an empty region; *lvl is the level of the
    // node (or empty octant) that decided it, so every cell sharing its coordinates above that
    // level has the same answer.
    int32_t lookup(uint32_t x, uint32_t y, uint32_t z, int* lvl) const;

    const Octree& t_;
    int level_ = 0;
    double cell_ = 0;             // cell edge
    std::vector<int32_t> child_;  // 8 per node
};

// Visibility of leaves a != b with the grid walk's occluders (same facing test, eps window,
// actual-occluder test and K as leaf_pair_visible). Counts into wc: facing_pairs, cells stepped
// (cells_stepped) and occluder tests.
bool grid_walk_leaf_pair_visible(const Octree& t, const LeafGrid& g, int32_t a, int32_t b,
                                 const VisibilityParams& vp, WorkCounters* wc);

// A CPU backend (oneTBB) that evaluates leaf pairs with grid_walk_leaf_pair_visible.
std::unique_ptr<Backend> make_grid_walk_backend();

// ---- implementation of the template ----------------------------------------------------------

template <class F>
bool LeafGrid::for_each_leaf(Vec3 p, Vec3 q, float t0, float t1, int32_t a, int32_t b,
                             uint64_t* cells, F&& f) const {
    // Grid coordinates in double: cell indices must not suffer float rounding at 2^21 cells.
    const double n = double(1u << level_);
    const double o[3] = {t_.root_min().x, t_.root_min().y, t_.root_min().z};
    const double P[3] = {p.x, p.y, p.z},
                 D[3] = {double(q.x) - p.x, double(q.y) - p.y, double(q.z) - p.z};
    double g0[3], dir[3];
    for (int i = 0; i < 3; ++i) {
        g0[i] = (P[i] + D[i] * t0 - o[i]) / cell_;
        dir[i] = D[i] * (double(t1) - t0) / cell_;  // grid units over s in [0, 1]
    }
    int64_t c[3], step[3], last[3];
    double tmax[3], tdelta[3];
    for (int i = 0; i < 3; ++i) {
        auto clampc = [&](double v) { return int64_t(std::clamp(std::floor(v), 0.0, n - 1)); };
        c[i] = clampc(g0[i]);
        last[i] = clampc(g0[i] + dir[i]);
        if (dir[i] > 0) {
            step[i] = 1;
            tmax[i] = (double(c[i] + 1) - g0[i]) / dir[i];
            tdelta[i] = 1.0 / dir[i];
        } else if (dir[i] < 0) {
            step[i] = -1;
            tmax[i] = (double(c[i]) - g0[i]) / dir[i];
            tdelta[i] = -1.0 / dir[i];
        } else {
            step[i] = 0;
            tmax[i] = INFINITY;
            tdelta[i] = INFINITY;
        }
    }
    int32_t prev = -1;
    int cached_lvl = -1;  // the node that answered the last lookup covers the current cell
    int64_t cached[3] = {-1, -1, -1};
    // At most one cell per unit of grid travel per axis, plus the first.
    const int64_t max_steps =
        std::llabs(last[0] - c[0]) + std::llabs(last[1] - c[1]) + std::llabs(last[2] - c[2]) + 1;
    for (int64_t s = 0; s < max_steps; ++s) {
        ++*cells;
        const int sh = level_ - cached_lvl;
        const bool same = cached_lvl >= 0 && (c[0] >> sh) == cached[0] &&
                          (c[1] >> sh) == cached[1] && (c[2] >> sh) == cached[2];
        if (!same) {
            int lvl = 0;
            const int32_t l = lookup(uint32_t(c[0]), uint32_t(c[1]), uint32_t(c[2]), &lvl);
            cached_lvl = lvl;
            const int s2 = level_ - lvl;
            for (int i = 0; i < 3; ++i) cached[i] = c[i] >> s2;
            // A leaf's cube is convex: the segment's cells in it are consecutive, so comparing
            // with the previous leaf visits each leaf once.
            if (l >= 0 && l != prev) {
                prev = l;
                if (l != a && l != b && !f(l)) return false;
            }
        }
        if (c[0] == last[0] && c[1] == last[1] && c[2] == last[2]) break;
        // Advance along the axis whose next cell boundary comes first.
        int ax = 0;
        if (tmax[1] < tmax[ax]) ax = 1;
        if (tmax[2] < tmax[ax]) ax = 2;
        if (!(tmax[ax] <= 1.0)) break;
        c[ax] += step[ax];
        if (c[ax] < 0 || c[ax] >= int64_t(n)) break;
        tmax[ax] += tdelta[ax];
    }
    return true;
}

}  // namespace vmap::detail
