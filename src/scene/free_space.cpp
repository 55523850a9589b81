// Free space on either side of a surface point: voxel regions and their nesting, then rays.
// Everything parallel writes only its own point's slots; the flood fill and the region graph are
// serial, so the result does not depend on the number of threads.

#include "scene/free_space.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <deque>
#include <limits>
#include <map>
#include <numeric>
#include <optional>

#include "scene/cloud_knn.h"
#include "util/small_solve.h"
#include "vmap/parallel.h"

namespace vmap::detail {
namespace {

constexpr int kPad = 3;              // empty cells around the cloud: the outside wraps around it
constexpr int kMaxCells = 240;       // per axis, so the grid stays below 16 M cells
// A surface stacked behind another along a probe: their normal axes within 60 degrees.
constexpr float kStackedCos = 0.5f;
constexpr int kProbeSteps = 8;       // half-cell steps: out of the surface layer (1-2 cells)
constexpr float kSpacing = 1.7725f;  // sample spacing / splat radius: sqrt(pi)

struct Grid {
    Vec3 lo;
    float h = 1;
    std::array<int, 3> n{};

    size_t size() const { return size_t(n[0]) * n[1] * n[2]; }
    size_t at(int x, int y, int z) const { return (size_t(z) * n[1] + y) * n[0] + x; }
    // The cell holding p, or false when p is outside the grid.
    bool cell(Vec3 p, std::array<int, 3>& c) const {
        const float v[3] = {p.x - lo.x, p.y - lo.y, p.z - lo.z};
        for (int a = 0; a < 3; ++a) {
            const float f = std::floor(v[a] / h);
            if (!(f >= 0 && f < float(n[a]))) return false;
            c[a] = int(f);
        }
        return true;
    }
};

struct Bounds {
    Vec3 lo, hi;
};

// Grows b to hold p.
void grow(Bounds& b, Vec3 p) {
    b.lo = {std::min(b.lo.x, p.x), std::min(b.lo.y, p.y), std::min(b.lo.z, p.z)};
    b.hi = {std::max(b.hi.x, p.x), std::max(b.hi.y, p.y), std::max(b.hi.z, p.z)};
}

Bounds bounds_of(const std::vector<Vec3>& pts) {
    Bounds b{pts[0], pts[0]};
    for (const Vec3& p : pts) grow(b, p);
    return b;
}

float max_extent(const Bounds& b) {
    return std::max({b.hi.x - b.lo.x, b.hi.y - b.lo.y, b.hi.z - b.lo.z});
}

float median_radius(const std::vector<float>& radii) {
    std::vector<float> r;
    for (float x : radii)
        if (x > 0) r.push_back(x);
    if (r.empty()) return 0;
    std::nth_element(r.begin(), r.begin() + r.size() / 2, r.end());
    return r[r.size() / 2];
}

Grid make_grid(const Bounds& b, float h, int pad) {
    Grid g;
    g.h = h;
    g.lo = {b.lo.x - pad * h, b.lo.y - pad * h, b.lo.z - pad * h};
    const float ext[3] = {b.hi.x - b.lo.x, b.hi.y - b.lo.y, b.hi.z - b.lo.z};
    for (int a = 0; a < 3; ++a) g.n[a] = int(std::ceil(ext[a] / h)) + 1 + 2 * pad;
    return g;
}

// Cells that the points' discs (three splat radii) pass through: a cell is marked when the
// disc's plane cuts the cube (|n . (c - p)| <= h/2 (|nx| + |ny| + |nz|)) within the disc's
// reach of the point (plus half a cell). A cell stays empty only if no sample lies within about
// 3.9 splat radii of it along the surface: for random (Poisson) samples, 15 expected, so a hole
// that would let the flood fill through a closed surface is a 3e-7 event per cell (at two radii
// it was 2e-4: several leaks per surface of 20000 cells). The layer stays one to two cells
// thick, so thin parts keep their insides.
std::vector<uint8_t> occupancy(const std::vector<Vec3>& pts, const std::vector<Vec3>& normals,
                               const std::vector<float>& radii, float cap, const Grid& g) {
    std::vector<uint8_t> occ(g.size(), 0);
    parallel_for_range<size_t>(pts.size(), 1024, [&](size_t chunk_begin, size_t chunk_end) {
        for (size_t i = chunk_begin; i < chunk_end; ++i) {
            const Vec3 p = pts[i], n = normals[i];
            const float r = std::min(3 * radii[i], cap);
            const float slab = 0.5f * g.h * (std::fabs(n.x) + std::fabs(n.y) + std::fabs(n.z));
            const float reach2 = (r + 0.5f * g.h) * (r + 0.5f * g.h);
            int lo[3], hi[3];
            const float pc[3] = {p.x - g.lo.x, p.y - g.lo.y, p.z - g.lo.z};
            for (int a = 0; a < 3; ++a) {
                lo[a] = std::max(0, int(std::floor((pc[a] - r) / g.h)));
                hi[a] = std::min(g.n[a] - 1, int(std::floor((pc[a] + r) / g.h)));
            }
            for (int z = lo[2]; z <= hi[2]; ++z)
                for (int y = lo[1]; y <= hi[1]; ++y)
                    for (int x = lo[0]; x <= hi[0]; ++x) {
                        const Vec3 c{g.lo.x + (float(x) + 0.5f) * g.h,
                                     g.lo.y + (float(y) + 0.5f) * g.h,
                                     g.lo.z + (float(z) + 0.5f) * g.h};
                        const Vec3 d = c - p;
                        const float off = dot(n, d);
                        if (std::fabs(off) > slab || length2(d) - off * off > reach2) continue;
                        // Threads may mark one cell at once; each writes 1, so any order gives
                        // the same.
                        std::atomic_ref<uint8_t>(occ[g.at(x, y, z)])
                            .store(1, std::memory_order_relaxed);
                    }
        }
    });
    return occ;
}

struct Regions {
    std::vector<int32_t> label;   // per cell: region, or -1 where occupied
    std::vector<uint64_t> cells;  // per region: its volume in cells inside the cloud's bounding
                                  // box (the padding excluded); region 0 is the outside
};

// 6-connected flood fill of the empty cells, starting from a corner (empty: the grid is padded).
Regions flood_fill(const Grid& g, const std::vector<uint8_t>& occ) {
    auto inside = [&](int x, int y, int z) {
        return x >= kPad && y >= kPad && z >= kPad && x < g.n[0] - kPad && y < g.n[1] - kPad &&
               z < g.n[2] - kPad;
    };
    Regions r;
    r.label.assign(g.size(), -2);
    std::deque<std::array<int, 3>> queue;
    auto fill = [&](int x0, int y0, int z0, int32_t id) {
        uint64_t count = 0;
        r.label[g.at(x0, y0, z0)] = id;
        queue.push_back({x0, y0, z0});
        while (!queue.empty()) {
            const auto [x, y, z] = queue.front();
            queue.pop_front();
            count += inside(x, y, z);
            const int nb[6][3] = {{x - 1, y, z}, {x + 1, y, z}, {x, y - 1, z},
                                  {x, y + 1, z}, {x, y, z - 1}, {x, y, z + 1}};
            for (const auto& c : nb) {
                if (c[0] < 0 || c[1] < 0 || c[2] < 0 || c[0] >= g.n[0] || c[1] >= g.n[1] ||
                    c[2] >= g.n[2])
                    continue;
                int32_t& l = r.label[g.at(c[0], c[1], c[2])];
                if (l != -2 || occ[g.at(c[0], c[1], c[2])]) continue;
                l = id;
                queue.push_back({c[0], c[1], c[2]});
            }
        }
        r.cells.push_back(count);
    };
    fill(0, 0, 0, 0);
    for (int z = 0; z < g.n[2]; ++z)
        for (int y = 0; y < g.n[1]; ++y)
            for (int x = 0; x < g.n[0]; ++x) {
                const size_t i = g.at(x, y, z);
                if (occ[i]) {
                    r.label[i] = -1;
                } else if (r.label[i] == -2) {
                    fill(x, y, z, int32_t(r.cells.size()));
                }
            }
    return r;
}

// The region first reached stepping from p along d (half a cell at a time), 0 (the outside)
// when the walk leaves the grid, -1 when it stays in occupied cells.
int32_t probe(const Grid& g, const Regions& r, Vec3 p, Vec3 d) {
    std::array<int, 3> c;
    for (int s = 1; s <= kProbeSteps; ++s) {
        if (!g.cell(p + d * (0.5f * g.h * float(s)), c)) return 0;
        const int32_t l = r.label[g.at(c[0], c[1], c[2])];
        if (l >= 0) return l;
    }
    return -1;
}

// Nesting depth of each region from the outside (breadth first over region pairs that enough
// points separate; -1 unreached), and the points separating depth 1 from depth 2.
struct Nesting {
    std::vector<int> level;
    uint64_t deep_points = 0;
};

Nesting nest(const std::vector<std::array<int32_t, 2>>& sides, size_t regions, size_t npts) {
    std::map<std::pair<int32_t, int32_t>, uint64_t> weight;
    for (const auto& s : sides)
        if (s[0] >= 0 && s[1] >= 0 && s[0] != s[1])
            ++weight[{std::min(s[0], s[1]), std::max(s[0], s[1])}];
    // A link that only a handful of points make is a leak or a bubble, not a surface.
    const uint64_t min_weight = std::max<uint64_t>(3, npts / 2000);
    std::vector<std::vector<int32_t>> adj(regions);
    for (const auto& [pair, w] : weight) {
        if (w < min_weight) continue;
        adj[pair.first].push_back(pair.second);
        adj[pair.second].push_back(pair.first);
    }
    Nesting n;
    n.level.assign(regions, -1);
    n.level[0] = 0;
    std::deque<int32_t> queue{0};
    while (!queue.empty()) {
        const int32_t a = queue.front();
        queue.pop_front();
        for (int32_t b : adj[a])
            if (n.level[b] < 0) {
                n.level[b] = n.level[a] + 1;
                queue.push_back(b);
            }
    }
    for (const auto& [pair, w] : weight) {
        const int la = n.level[pair.first], lb = n.level[pair.second];
        if (w >= min_weight && std::min(la, lb) == 1 && std::max(la, lb) == 2) n.deep_points += w;
    }
    return n;
}

// Which parity of nesting depth is free space, and the verdict in words. `faces` counts, per
// region, the point sides that face it (its surface area, for area-uniform samples).
int free_parity(const Nesting& n, const Regions& r, const std::vector<uint64_t>& faces, size_t npts,
                std::string& method) {
    // Something two levels deep, separated by at least 0.5% of the points, is a room with things
    // in it or a shell around a cavity. Free space is roomy and solids are thin: the depth-1
    // regions are free (a room's air) when their volume per area of surface is larger than that
    // of the depth-2 regions (the things in it); otherwise (a shell's solid around a larger
    // cavity) the outside and the cavities are. Without anything that deep, a lone object: its
    // outside is free.
    double vol[3] = {}, area[3] = {};
    for (size_t i = 0; i < n.level.size(); ++i) {
        if (n.level[i] == 1 || n.level[i] == 2) {
            vol[n.level[i]] += double(r.cells[i]);
            area[n.level[i]] += double(faces[i]);
        }
    }
    const bool deep = n.deep_points * 200 >= npts && area[1] > 0 && area[2] > 0;
    if (deep && vol[1] / area[1] > vol[2] / area[2]) {
        method = "free space: an enclosure with things inside (room: walls face inward)";
        return 1;
    }
    method = deep ? "free space: shells around cavities (surfaces face the outside and cavities)"
                  : "free space: the outside (objects face outward)";
    return 0;
}

// Splat discs in a uniform grid of cells, for first-hit rays.
class DiscCaster {
  public:
    // b: every point's bounds (the cell grid); walls: the box whose faces count as the scene's
    // bounds for escaping rays (wall_box), walled: which of its faces hold a room's wall.
    DiscCaster(const std::vector<Vec3>& pts, const std::vector<Vec3>& normals,
               const std::vector<float>& radii, const Bounds& b, const Bounds& walls,
               const std::array<bool, 6>& walled, float r_med, float immediate)
        : pts_(pts),
          normals_(normals),
          box_(walls),
          walled_(walled),
          immediate_(immediate),
          far_(8 * max_extent(b)) {
        // Discs twice the splat radius: samples' discs of one radius cover a surface only once
        // on average (gaps where rays would slip through); doubled, gaps are about 2%.
        const float cap = 4 * r_med;
        rad_.resize(pts.size());
        for (size_t i = 0; i < pts.size(); ++i) rad_[i] = std::min(2 * radii[i], cap);
        grid_ = make_grid(b, std::max(2 * cap, max_extent(b) / kMaxCells), 1);
        fill();
    }

    // Mean distance rays from point i travel into the hemisphere of `side` before meeting
    // another disc. A ray that meets none escapes into unbounded free space (it counts as
    // travelling far), unless it leaves the bounding box at once (the outer side of a room's
    // wall, which lies on the box, sees nothing) or through a face that holds a room's wall
    // (escape).
    struct Depth {
        float mean = 0;  // over the rays
        int hits = 0;    // rays that met a disc
    };
    Depth side_depth(uint32_t i, Vec3 side, float tmin) const {
        Vec3 u = std::fabs(side.x) < 0.6f ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
        u = cross(side, u);
        u = u / length(u);
        const Vec3 v = cross(side, u);
        // The axis and a ring of six at 40 degrees, the ring turned per point (golden angle)
        // so neighbouring points do not sample the same directions.
        const float ring = 0.6428f, axial = 0.7660f, turn = 2.39996f * float(i % 1024);
        Depth out;
        auto add = [&](Vec3 d) {
            const float t = travel(i, d, tmin);
            out.mean += t >= 0 ? t : escape(i, d);
            out.hits += t >= 0;
        };
        add(side);
        for (int k = 0; k < 6; ++k) {
            const float a = turn + 1.0472f * float(k);
            add(side * axial + u * (ring * std::cos(a)) + v * (ring * std::sin(a)));
        }
        out.mean /= 7;
        return out;
    }

    // Distance from point i along d to the first disc beyond tmin, or -1 if it meets none; the
    // disc's point in `who` when one is met.
    float first_hit(uint32_t i, Vec3 d, float tmin, uint32_t* who = nullptr) const {
        return travel(i, d, tmin, std::numeric_limits<float>::max(), who);
    }

    // Whether point i sees the place v: no disc between them past tmin.
    bool sees(uint32_t i, Vec3 v, float tmin) const {
        const Vec3 to = v - pts_[i];
        const float dist = length(to);
        if (!(dist > tmin)) return false;
        const float t = travel(i, to / dist, tmin, dist);
        return t < 0;
    }

    static constexpr uint32_t kNoSelf = std::numeric_limits<uint32_t>::max();
    // Of `dirs` rays from the place x, those that meet no disc and leave the box through a face
    // that holds a room's wall: holes in what x sees (a gap between discs, or a shadow no
    // scanner saw into).
    size_t holes_from(Vec3 x, const std::vector<Vec3>& dirs) const {
        size_t holes = 0;
        for (const Vec3 d : dirs) {
            if (travel_from(x, kNoSelf, d, 0.0f) >= 0) continue;
            holes += walled_[size_t(exit_face(box_, x, d))];
        }
        return holes;
    }

    // Distance from o along d to the cloud's bounding box.
    float box_exit(Vec3 o, Vec3 d) const { return box_exit(box_, o, d); }
    static float box_exit(const Bounds& box, Vec3 o, Vec3 d) {
        float t = std::numeric_limits<float>::max();
        const float oo[3] = {o.x, o.y, o.z}, dd[3] = {d.x, d.y, d.z};
        const float lo[3] = {box.lo.x, box.lo.y, box.lo.z};
        const float hi[3] = {box.hi.x, box.hi.y, box.hi.z};
        for (int a = 0; a < 3; ++a) {
            if (dd[a] > 0) t = std::min(t, (hi[a] - oo[a]) / dd[a]);
            if (dd[a] < 0) t = std::min(t, (lo[a] - oo[a]) / dd[a]);
        }
        return std::max(t, 0.0f);
    }

    // The face of the bounding box that o + t d leaves through (axis * 2 + (d_axis > 0)).
    static int exit_face(const Bounds& box, Vec3 o, Vec3 d) {
        float t = std::numeric_limits<float>::max();
        int face = 0;
        const float oo[3] = {o.x, o.y, o.z}, dd[3] = {d.x, d.y, d.z};
        const float lo[3] = {box.lo.x, box.lo.y, box.lo.z}, hi[3] = {box.hi.x, box.hi.y, box.hi.z};
        for (int a = 0; a < 3; ++a) {
            const float ta = dd[a] > 0   ? (hi[a] - oo[a]) / dd[a]
                             : dd[a] < 0 ? (lo[a] - oo[a]) / dd[a]
                                         : std::numeric_limits<float>::max();
            if (ta < t) t = ta, face = a * 2 + (dd[a] > 0);
        }
        return face;
    }

  private:
    void fill() {
        const size_t cells = grid_.size();
        start_.assign(cells + 1, 0);
        auto each_cell = [&](size_t i, auto&& f) {
            const Vec3 p = pts_[i];
            const float r = rad_[i];
            std::array<int, 3> a{}, b{};
            if (!grid_.cell(p - Vec3{r, r, r}, a) || !grid_.cell(p + Vec3{r, r, r}, b)) {
                grid_.cell(p, a);
                b = a;
            }
            for (int z = a[2]; z <= b[2]; ++z)
                for (int y = a[1]; y <= b[1]; ++y)
                    for (int x = a[0]; x <= b[0]; ++x) f(grid_.at(x, y, z));
        };
        for (size_t i = 0; i < pts_.size(); ++i) each_cell(i, [&](size_t c) { ++start_[c + 1]; });
        std::partial_sum(start_.begin(), start_.end(), start_.begin());
        items_.resize(start_[cells]);
        std::vector<uint32_t> next(start_.begin(), start_.end() - 1);
        for (size_t i = 0; i < pts_.size(); ++i)
            each_cell(i, [&](size_t c) { items_[next[c]++] = uint32_t(i); });
    }

    // The nearest disc crossing in cell c beyond tmin and before best. A disc whose centre lies
    // behind the point's tangent plane (seen from the ray's side) and within the disc's reach is
    // a neighbour on a curve poking into the hemisphere, not something the point sees: on a
    // tight curve (a tube a few radii thick) such discs would stop the rays on its outer side.
    // The other face of a thin plate lies in front of the plane and stays.
    float hit_in_cell(size_t c, uint32_t self, Vec3 o, Vec3 d, float tmin, float best,
                      uint32_t* who) const {
        // From a place (kNoSelf) there is no own plane: `own` is zero and drops no disc.
        const Vec3 own = self == kNoSelf                  ? Vec3{0, 0, 0}
                         : dot(normals_[self], d) >= 0 ? normals_[self]
                                                       : -normals_[self];
        for (uint32_t k = start_[c]; k < start_[c + 1]; ++k) {
            const uint32_t j = items_[k];
            if (j == self) continue;
            const Vec3 to = pts_[j] - o;
            const float off = dot(own, to), dist2 = length2(to);
            if (off < 0 && dist2 < 4 * rad_[j] * rad_[j]) continue;
            const Vec3 n = normals_[j];
            const float den = dot(n, d);
            if (std::fabs(den) < 1e-6f) continue;
            const float t = dot(n, to) / den;
            if (!(t > tmin && t < best)) continue;
            if (length2(o + d * t - pts_[j]) <= rad_[j] * rad_[j]) {
                best = t;
                if (who) *who = j;
            }
        }
        return best;
    }

    // How far an escaping ray counts as travelling: to the box when it leaves at once (a
    // wall's outer side), unboundedly far through an open side of the scene, and nowhere
    // through a face that holds a room's wall. There it slipped through a hole in the wall: a
    // gap between discs, or in a scan a shadow: wall that no scanner saw. A surface seen from
    // one side only (a table top scanned from below) casts its shadow behind itself, so its
    // back's rays find the holes while its front's meet the scanned walls: the hole counts as
    // what lies behind a wall, where nothing was seen either. (Counted as travelling to the
    // wall, the shadowed side of such a sheet won as often as not: docs/validation.md "Scans".)
    float escape(uint32_t self, Vec3 d) const {
        const float t_box = box_exit(pts_[self], d);
        if (t_box <= immediate_) return t_box;
        return walled_[size_t(exit_face(box_, pts_[self], d))] ? 0.f : far_;
    }

    // Distance to the first disc along the ray (3D DDA over the cells) before tmax, or -1 if
    // none.
    float travel(uint32_t self, Vec3 d, float tmin, float tmax = std::numeric_limits<float>::max(),
                 uint32_t* who = nullptr) const {
        return travel_from(pts_[self], self, d, tmin, tmax, who);
    }
    float travel_from(Vec3 o, uint32_t self, Vec3 d, float tmin,
                      float tmax = std::numeric_limits<float>::max(),
                      uint32_t* who = nullptr) const {
        std::array<int, 3> c;
        if (!grid_.cell(o, c)) return -1;
        const float oo[3] = {o.x - grid_.lo.x, o.y - grid_.lo.y, o.z - grid_.lo.z};
        const float dd[3] = {d.x, d.y, d.z};
        int step[3];
        float t_next[3], t_delta[3];
        for (int a = 0; a < 3; ++a) {
            step[a] = dd[a] > 0 ? 1 : -1;
            const float inv = std::fabs(dd[a]) > 1e-12f ? 1.0f / std::fabs(dd[a]) : 1e30f;
            const float edge = dd[a] > 0 ? float(c[a] + 1) * grid_.h : float(c[a]) * grid_.h;
            t_next[a] = std::fabs(edge - oo[a]) * inv;
            t_delta[a] = grid_.h * inv;
        }
        float best = tmax;
        for (;;) {
            best = hit_in_cell(grid_.at(c[0], c[1], c[2]), self, o, d, tmin, best, who);
            const int a = t_next[0] < t_next[1] ? (t_next[0] < t_next[2] ? 0 : 2)
                                                : (t_next[1] < t_next[2] ? 1 : 2);
            if (best <= t_next[a]) return best < tmax ? best : -1;
            c[a] += step[a];
            if (c[a] < 0 || c[a] >= grid_.n[a]) return best < tmax ? best : -1;
            t_next[a] += t_delta[a];
        }
    }

    const std::vector<Vec3>& pts_;
    const std::vector<Vec3>& normals_;
    Bounds box_;
    std::array<bool, 6> walled_;
    float immediate_, far_;
    std::vector<float> rad_;
    Grid grid_;
    std::vector<uint32_t> start_, items_;
};

// The normal axis (sign ignored) that the most sampled normals lie within 10 degrees of, among
// up to 256 sampled normals that satisfy `usable`; nothing when none does.
template <class Usable>
std::optional<Vec3> dominant_axis(const std::vector<Vec3>& normals, Usable usable) {
    const size_t n = normals.size();
    const size_t cand_step = std::max<size_t>(1, n / 256),
                 vote_step = std::max<size_t>(1, n / 4096);
    std::optional<Vec3> best;
    size_t best_votes = 0;
    for (size_t c = 0; c < n; c += cand_step) {
        if (!usable(normals[c])) continue;
        size_t votes = 0;
        for (size_t i = 0; i < n; i += vote_step)
            votes += std::fabs(dot(normals[c], normals[i])) > 0.985f;
        if (votes > best_votes) {
            best_votes = votes;
            best = normals[c];
        }
    }
    if (!best) return best;
    // The mean of the normals near the winner (signs aligned): a fitted normal is a few degrees
    // off, and the box must follow a wall to within a fraction of a cell over its length.
    Vec3 sum{0, 0, 0};
    for (const Vec3& m : normals) {
        const float d = dot(m, *best);
        if (std::fabs(d) > 0.985f) sum += d > 0 ? m : -m;
    }
    return sum / length(sum);
}

// The box of a room's walls: each face of the cloud's bounds moved in to the outermost wall
// plane when only a few stray points lie beyond it. A room's walls are told by their outer side
// leaving the box at once (room_wall_faces, the rays' escape); a few points outside the room (a
// speck seen past a corner, a registration outlier) would push the box out and turn the walls
// on that side outward. From each face inward, over slabs two splat radii thick: the first slab
// whose points facing along the axis (|n| component over 0.9) number at least kWallPoints and
// span at least half the cloud's core extent (2nd-98th percentile) in both other axes is a
// wall; the face moves to it if at most kStrayShare of the points lie beyond it, and counts as
// walled (`walled`, by face: axis * 2 + (side > 0)) when the wall covers at least kWallCover
// of the face. A face with no wall near it (an open side, a lone object) keeps its place. In
// the room's frame (vote_sides), where walls are perpendicular to the axes.
constexpr double kStrayShare = 0.02;
constexpr float kFaceNoiseSigmas = 8;
constexpr size_t kWallPoints = 64;
constexpr int kWallCells = 16;      // the face's grid for its cover (wall_box's `walled`)
constexpr double kWallCover = 0.5;  // the share of its cells a room's wall covers at least

Bounds wall_box(const std::vector<Vec3>& pts, const std::vector<Vec3>& normals, const Bounds& full,
                float r_med, float noise, std::array<bool, 6>& walled) {
    walled.fill(false);
    auto at = [](const Vec3& v, int a) { return a == 0 ? v.x : a == 1 ? v.y : v.z; };
    auto set = [](Vec3& v, int a, float x) { (a == 0 ? v.x : a == 1 ? v.y : v.z) = x; };
    const size_t n = pts.size();
    const size_t stray = size_t(kStrayShare * double(n));
    float core[3];
    for (int a = 0; a < 3; ++a) {
        std::vector<float> c(n);
        for (size_t i = 0; i < n; ++i) c[i] = at(pts[i], a);
        std::nth_element(c.begin(), c.begin() + ptrdiff_t(n / 50), c.end());
        const float lo = c[n / 50];
        std::nth_element(c.begin(), c.begin() + ptrdiff_t(n - 1 - n / 50), c.end());
        core[a] = c[n - 1 - n / 50] - lo;
    }
    Bounds b = full;
    const float slab = 2 * r_med;
    for (int a = 0; a < 3; ++a) {
        const int u = (a + 1) % 3, w = (a + 2) % 3;
        const float lo = at(full.lo, a), ext = at(full.hi, a) - lo;
        if (!(ext > 0) || !(slab > 0)) continue;
        const size_t slabs = size_t(std::min(ext / slab, float(1 << 22))) + 1;
        std::vector<uint32_t> all(slabs, 0), wall(slabs, 0);
        // Of the wall points in each slab: u min, u max, w min, w max, a min, a max.
        constexpr float kBig = std::numeric_limits<float>::max();
        std::vector<float> span(6 * slabs);
        for (size_t k = 0; k < slabs; ++k)
            for (int j = 0; j < 6; ++j) span[6 * k + size_t(j)] = j % 2 ? -kBig : kBig;
        for (size_t i = 0; i < n; ++i) {
            const size_t k =
                std::min(slabs - 1, size_t((at(pts[i], a) - lo) / ext * float(slabs - 1) + 0.5f));
            ++all[k];
            if (!(std::fabs(at(normals[i], a)) > 0.9f)) continue;
            ++wall[k];
            float* sp = &span[6 * k];
            sp[0] = std::min(sp[0], at(pts[i], u)), sp[1] = std::max(sp[1], at(pts[i], u));
            sp[2] = std::min(sp[2], at(pts[i], w)), sp[3] = std::max(sp[3], at(pts[i], w));
            sp[4] = std::min(sp[4], at(pts[i], a)), sp[5] = std::max(sp[5], at(pts[i], a));
        }
        auto is_wall = [&](size_t k) {
            const float* sp = &span[6 * k];
            return wall[k] >= kWallPoints && sp[1] - sp[0] >= 0.5f * core[u] &&
                   sp[3] - sp[2] >= 0.5f * core[w];
        };
        // Whether the wall points of slab k cover most of the face (kWallCells squared cells
        // over the cloud's bounds in the other two axes): a room's floor or wall does, less its
        // shadows in a scan; objects standing on one level (their feet, a lone object's base)
        // make a "wall" of a few cells.
        // A noisy wall's points scatter over several slabs (about 4 sigma either way of its
        // plane, kFaceNoiseSigmas in all): its cover counts the slabs within that reach of the
        // one found. Counted in the found slab alone, a wall at a quarter of a spacing of noise
        // covered too little of its face (test-tight's and test-thin-plates' two-scanner scans: 2
        // faces of 5 walled), and the room went unrecognised (scanned_room).
        const size_t band = size_t(std::ceil(kFaceNoiseSigmas * noise / slab));
        auto covers = [&](size_t k) {
            constexpr int kCells = kWallCells;
            std::vector<uint8_t> cell(size_t(kCells) * kCells, 0);
            const float u0 = at(full.lo, u), w0 = at(full.lo, w);
            const float du = (at(full.hi, u) - u0) / kCells, dw = (at(full.hi, w) - w0) / kCells;
            if (!(du > 0) || !(dw > 0)) return false;
            for (size_t i = 0; i < n; ++i) {
                if (!(std::fabs(at(normals[i], a)) > 0.9f)) continue;
                const size_t ki = std::min(
                    slabs - 1, size_t((at(pts[i], a) - lo) / ext * float(slabs - 1) + 0.5f));
                if (ki + band < k || ki > k + band) continue;
                const int cu = std::clamp(int((at(pts[i], u) - u0) / du), 0, kCells - 1);
                const int cw = std::clamp(int((at(pts[i], w) - w0) / dw), 0, kCells - 1);
                cell[size_t(cu) * kCells + size_t(cw)] = 1;
            }
            size_t marked = 0;
            for (uint8_t c : cell) marked += c;
            return double(marked) >= kWallCover * double(cell.size());
        };
        // From the high face down, then from the low face up; the face moves to the wall's
        // outermost point.
        size_t beyond = 0;
        for (size_t k = slabs; k-- > 0 && beyond <= stray;) {
            if (is_wall(k)) {
                if (beyond > 0) set(b.hi, a, span[6 * k + 5]);
                walled[size_t(2 * a + 1)] = covers(k);
                break;
            }
            beyond += all[k];
        }
        beyond = 0;
        for (size_t k = 0; k < slabs && beyond <= stray; ++k) {
            if (is_wall(k)) {
                if (beyond > 0) set(b.lo, a, span[6 * k + 4]);
                walled[size_t(2 * a)] = covers(k);
                break;
            }
            beyond += all[k];
        }
    }
    return b;
}

// A frame whose axes follow the two most common normal directions: a room's floor and walls. In
// it the cloud's bounding box hugs a room's walls however the scan was turned, which the rays'
// "leaves the box at once" relies on. Any frame does for clouds without such directions.
std::array<Vec3, 3> room_frame(const std::vector<Vec3>& normals) {
    const std::optional<Vec3> a = dominant_axis(normals, [](Vec3) { return true; });
    if (!a) return {Vec3{1, 0, 0}, Vec3{0, 1, 0}, Vec3{0, 0, 1}};
    const std::optional<Vec3> b0 =
        dominant_axis(normals, [&](Vec3 c) { return std::fabs(dot(c, *a)) < 0.1f; });
    Vec3 b = b0 ? *b0 : (std::fabs(a->x) < 0.6f ? Vec3{1, 0, 0} : Vec3{0, 1, 0});
    b = b - *a * dot(b, *a);
    b = b / length(b);
    return {*a, b, cross(*a, b)};
}

std::vector<Vec3> in_frame(const std::vector<Vec3>& v, const std::array<Vec3, 3>& f) {
    std::vector<Vec3> out(v.size());
    for (size_t i = 0; i < v.size(); ++i)
        out[i] = {dot(v[i], f[0]), dot(v[i], f[1]), dot(v[i], f[2])};
    return out;
}

// Which region each point's two sides face, and which regions are free.
struct FreeSpace {
    std::vector<int32_t> label;                 // per cell: Regions::label
    std::vector<std::array<int32_t, 2>> sides;  // per point: the region along +n, along -n
    Nesting nesting;
    int parity = 0;  // regions of this nesting-depth parity are free
    std::string method;

    int state(int32_t region) const {  // 1 free, 0 solid, -1 unknown
        if (region < 0 || nesting.level[region] < 0) return -1;
        return nesting.level[region] % 2 == parity ? 1 : 0;
    }
};

FreeSpace free_space(const std::vector<Vec3>& pts, const std::vector<Vec3>& normals,
                     const std::vector<float>& radii, const Grid& g, float r_med) {
    Regions regions = flood_fill(g, occupancy(pts, normals, radii, 6 * r_med, g));
    FreeSpace fs;
    const size_t n = pts.size();
    fs.sides.resize(n);
    parallel_for_range<size_t>(n, 1024, [&](size_t chunk_begin, size_t chunk_end) {
        for (size_t i = chunk_begin; i < chunk_end; ++i)
            fs.sides[i] = {probe(g, regions, pts[i], normals[i]),
                           probe(g, regions, pts[i], -normals[i])};
    });
    fs.nesting = nest(fs.sides, regions.cells.size(), n);
    std::vector<uint64_t> faces(regions.cells.size(), 0);
    for (const auto& sd : fs.sides)
        for (int32_t region : sd)
            if (region >= 0) ++faces[region];
    fs.parity = free_parity(fs.nesting, regions, faces, n, fs.method);
    fs.label = std::move(regions.label);
    return fs;
}

// The side that the regions make free (+1 along n, -1 against it), or 0 for no verdict.
// plus, minus: the sides' states (1 free, 0 solid, -1 occupied all along the probe).
int space_side(int plus, int minus, float box_exit_free_side, bool room_wall, float on_face) {
    const bool on_box_face = box_exit_free_side <= on_face;
    // Free space that is only the padding beyond a room's open-air wall (room_wall_faces: the
    // outer side of its wall, floor or ceiling) is no evidence: nothing there was scanned.
    // Without this, a wall point with an object a few millimetres in front of it (the probe
    // crosses the gap's occupied cells into the object's solid) took the outside for its free
    // side. A lone object's faces also lie on the box, but their inner side is solid.
    if ((plus == 1 && minus == 0) || (minus == 1 && plus == 0))
        return on_box_face && room_wall ? 0 : (plus == 1 ? 1 : -1);
    // Free on one side, occupied cells all along the other (the inside of a part too thin for
    // the grid, or a surface close to another): trusted unless the free side is the bounding
    // box's face itself (a floor under an object standing on it).
    if ((plus == 1 && minus < 0) || (minus == 1 && plus < 0))
        return on_box_face ? 0 : (plus == 1 ? 1 : -1);
    // Solid on one side, occupied cells all along the other (a narrow gap, as under an object's
    // belly near the floor): the gap is the free side.
    if ((plus == 0 && minus < 0) || (minus == 0 && plus < 0)) return plus == 0 ? -1 : 1;
    return 0;
}

// Where a ray from a point starts to count hits: past the point's own neighbours' discs, which
// a ray leaves at once, and on a noisy surface past the noise's slab too (neighbours raised by
// the noise stand about 3 sigma off the point's plane on either side, 4 sigma along a ring ray
// at 40 degrees: kRayNoiseSigmas).
constexpr float kRayNoiseSigmas = 6;
float ray_start(float radius, float r_med, float noise) {
    return 0.5f * std::max(radius, 0.25f * r_med) + kRayNoiseSigmas * noise;
}

// The side whose rays travel farther, signed (+ along n), weighted by the depth contrast
// (far - near) / (far + near); 0 without clear evidence.
float ray_side(const DiscCaster& caster, uint32_t i, Vec3 n, float radius, float r_med,
               float noise) {
    const float tmin = ray_start(radius, r_med, noise);
    const DiscCaster::Depth p = caster.side_depth(i, n, tmin), m = caster.side_depth(i, -n, tmin);
    // No surface seen on either side (a lone plane), or a weak preference (less than half as far
    // again): no evidence, so the point takes its sign from its neighbours.
    if (p.hits + m.hits == 0 ||
        std::max(p.mean, m.mean) <= 1.5f * std::min(p.mean, m.mean) + 0.1f * r_med)
        return 0;
    const float contrast = (p.mean - m.mean) / (p.mean + m.mean);
    return contrast != 0 ? contrast : (p.mean > m.mean ? 1e-6f : -1e-6f);
}

// A voxel probe walks through occupied cells to the first empty one, so through anything
// thinner than its reach. The inner wall of a hollow shell thinner than a cell (test-open-hollow:
// a 0-10 mm gap) is crossed by its outer side's probe, which reaches the outside: the cavity,
// reached from the outside through one layer of points, counts as one level deep (solid), and the
// whole inner wall takes the outside for its free side (0% of its signs right). Such a verdict
// contradicts the surface it faces: the first disc met along its free side, within the probe's
// reach, is stacked on it (normal axes within 60 degrees) with its own free side, by its own
// verdict, turned away, so the side facing this point is solid by that surface's verdict. One of
// the two is wrong; where the rays clearly say this point's other side travels farther (the
// cavity against the gap), the rays decide. The outer wall keeps its verdict: its rays agree with
// it. An object a few millimetres from a wall does not contradict: the wall's free side faces
// the object. Left out: a disc of the point's own sheet (a box's edge, where blended normals
// meet the other face's), and points whose free side leaves the box within `near_box` (the rays'
// "at once": a lone object's faces lie on the box, where the rays count the outside as near). Reads a snapshot of the space verdicts, so the result does not depend on the order.
// Returns the points turned.
size_t stacked_verdicts(const DiscCaster& caster, const std::vector<Vec3>& pts,
                        const std::vector<Vec3>& normals, const std::vector<float>& radii,
                        float r_med, float noise, float reach, float near_box, SideVotes& v) {
    const size_t n = pts.size();
    std::vector<int8_t> space_dir(n, 0);
    for (size_t i = 0; i < n; ++i)
        if (v.cue[i] == SideCue::kSpace) space_dir[i] = v.sign[i];
    std::vector<uint8_t> turn(n, 0);
    parallel_for_range<size_t>(n, 64, [&](size_t chunk_begin, size_t chunk_end) {
        for (size_t i = chunk_begin; i < chunk_end; ++i) {
            if (space_dir[i] == 0) continue;
            const Vec3 d = normals[i] * float(space_dir[i]);
            uint32_t j = 0;
            const float t = caster.first_hit(uint32_t(i), d, ray_start(radii[i], r_med, noise), &j);
            if (t < 0 || t > reach || space_dir[j] == 0 || caster.box_exit(pts[i], d) <= near_box)
                continue;
            if (dot(normals[j] * float(space_dir[j]), d) <= kStackedCos ||
                same_surface(pts[i], normals[i], pts[j], normals[j]))
                continue;
            const float side = ray_side(caster, uint32_t(i), normals[i], radii[i], r_med, noise);
            if (side == 0 || (side > 0) == (space_dir[i] > 0)) continue;
            v.sign[i] = int8_t(side > 0 ? 1 : -1);
            v.cue[i] = SideCue::kRays;
            v.weight[i] = std::fabs(side);
            turn[i] = 1;
        }
    });
    return size_t(std::count(turn.begin(), turn.end(), uint8_t(1)));
}

// The faces of the bounding box (axis * 2 + (side > 0)) that are a room's open-air walls: most
// points lying on the face (one side leaves the box within half a splat radius) are free on
// both sides (the room's air, and the padding beyond the face, one region through the room's
// opening). A lone object's faces or extreme points have solid on their inner side.
std::array<bool, 6> room_wall_faces(const FreeSpace& fs, const std::vector<Vec3>& pts,
                                    const std::vector<Vec3>& normals, const Bounds& b,
                                    float on_face) {
    std::array<uint64_t, 6> on{}, both{};
    for (size_t i = 0; i < pts.size(); ++i) {
        const bool free2 = fs.state(fs.sides[i][0]) == 1 && fs.state(fs.sides[i][1]) == 1;
        for (const Vec3 d : {normals[i], -normals[i]}) {
            if (DiscCaster::box_exit(b, pts[i], d) > on_face) continue;
            const size_t f = size_t(DiscCaster::exit_face(b, pts[i], d));
            ++on[f];
            both[f] += free2;
        }
    }
    std::array<bool, 6> wall{};
    for (size_t f = 0; f < 6; ++f) wall[f] = on[f] >= 16 && 2 * both[f] > on[f];
    return wall;
}

// Where the scanner stood (step 7 of vote_sides). A scanner records only what it sees, from the
// side it faces, so from where it stood it sees every point it recorded: the free place that
// sees the most points finds it, or a place that sees as much. Candidates are the cells of a
// kViewLattice lattice over the room's box whose neighbourhood (kViewClear cells each way) is
// free space, clear of every surface, and places 1.5 diagonals from the box's centre in 26
// directions, beyond faces that are not a room's walls (its open side): the outer side of a
// wall is not free. The best candidate is then refined by steps along the axes toward more
// points seen, halved down to a cell. As far as the points tell, the scanner stood anywhere that
// sees within kViewTolerance as many: the view's region (the box of such candidates and of the
// places probed around the refined one, in 26 directions at doubling distances), which a point's
// tangent plane must not cut for the view to sign it.
//
// Only where the cloud is a scan from inside a room (scanned_room): in a sampler's cloud every
// surface is there, the backs of open meshes too, and their sides follow the modeller's winding
// (the shape rule), not the side a place in the room sees; and a lone object scanned from one
// side looks the same from inside its cap as from outside.
constexpr int kViewLattice = 6;
constexpr int kViewClear = 2;
constexpr size_t kViewSamples = 1024;    // the points that choose the view
constexpr float kViewMinCos = 0.1f;      // not grazing: about 6 degrees off the tangent plane
constexpr double kViewTolerance = 0.01;  // places this close in coverage may be the scanner's

// A scan's spacing follows the scanner's distance and obliquity (the beams' angular step times
// the range, over the cosine), over a factor of several in a room; a sampler's does not: the
// standard deviation of the log of the splat radii is 0.07-0.10 on the test scenes' even
// samples, 0.23-0.25 on uniform ones, 0.64-0.91 on scans of their rooms from one to four
// scanners (docs/validation.md, "Scans: where the scanner stood").
constexpr double kScanSpread = 0.4;
// ... and a room around the scanner fixes where it stood: its walls on at least this many faces.
// A wall here is a face that is a room's open-air wall (room_wall_faces) and that a wall covers
// (wall_box's `walled`). The first alone also holds for an object scanned without its room: its
// shell, open where no scanner saw it, is free on both sides, and on a noisy scan the face's reach
// (on_face, widened by the noise) takes in much of it. A cornell-bunny scanned from two places
// with a quarter of a spacing of noise, its room left out, was taken for a room scanned from
// inside, the place that sees the most of it inside the bunny: 2.4% of its signs right; 70.7%
// with the cover (docs/validation.md "Scans: noisy scans of objects").
constexpr int kScanRoomFaces = 3;

// The spread (standard deviation) of the log of the splat radii.
double log_spread(const std::vector<float>& radii) {
    double sum = 0, sum2 = 0, count = 0;
    for (const float r : radii) {
        if (!(r > 0)) continue;
        const double l = std::log(double(r));
        sum += l, sum2 += l * l, count += 1;
    }
    if (count < 2) return 0;
    const double mean = sum / count;
    return std::sqrt(std::max(0.0, sum2 / count - mean * mean));
}

bool scanned_room(const std::vector<float>& radii, const std::array<bool, 6>& walled) {
    return std::count(walled.begin(), walled.end(), true) >= kScanRoomFaces &&
           log_spread(radii) >= kScanSpread;
}

// The 26 directions to a cube's faces, edges and corners from its centre, unit length.
const std::array<Vec3, 26>& around() {
    static const std::array<Vec3, 26> dirs = [] {
        std::array<Vec3, 26> out{};
        size_t k = 0;
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    if (dx == 0 && dy == 0 && dz == 0) continue;
                    const Vec3 d{float(dx), float(dy), float(dz)};
                    out[k++] = d / length(d);
                }
        return out;
    }();
    return dirs;
}

std::vector<Vec3> view_candidates(const Grid& g, const FreeSpace& fs, const Bounds& box,
                                  const std::array<bool, 6>& room_wall) {
    std::vector<Vec3> out;
    const Vec3 ext = box.hi - box.lo;
    auto clear = [&](const std::array<int, 3>& c) {
        for (int dz = -kViewClear; dz <= kViewClear; ++dz)
            for (int dy = -kViewClear; dy <= kViewClear; ++dy)
                for (int dx = -kViewClear; dx <= kViewClear; ++dx) {
                    const int x = c[0] + dx, y = c[1] + dy, z = c[2] + dz;
                    if (x < 0 || y < 0 || z < 0 || x >= g.n[0] || y >= g.n[1] || z >= g.n[2])
                        return false;
                    if (fs.state(fs.label[g.at(x, y, z)]) != 1) return false;
                }
        return true;
    };
    const auto at = [](int m) { return (float(m) + 0.5f) / float(kViewLattice); };
    for (int k = 0; k < kViewLattice; ++k)
        for (int j = 0; j < kViewLattice; ++j)
            for (int i = 0; i < kViewLattice; ++i) {
                const Vec3 p{box.lo.x + ext.x * at(i), box.lo.y + ext.y * at(j),
                             box.lo.z + ext.z * at(k)};
                std::array<int, 3> c;
                if (g.cell(p, c) && clear(c)) out.push_back(p);
            }
    const Vec3 mid = (box.lo + box.hi) * 0.5f;
    const float reach = 1.5f * length(ext);
    for (const Vec3 d : around())
        if (!room_wall[size_t(DiscCaster::exit_face(box, mid, d))]) out.push_back(mid + d * reach);
    return out;
}

// The place the scanner stood, as far as the points tell: `at`, the refined place that sees
// the most of them, and `region`, the box of the places that see about as many.
struct View {
    Vec3 at;
    Bounds region;
    size_t seen = 0, samples = 0;  // of kViewSamples points at a fixed stride
};

// Whether each candidate sees each of the min(n, kViewSamples) points at a fixed stride
// (candidate-major): the table both the view (find_view) and the scanners by spacing
// (find_scanners) start from.
std::vector<uint8_t> sampled_views(const DiscCaster& caster, const std::vector<Vec3>& pts,
                                   const std::vector<float>& radii, float r_med, float noise,
                                   const std::vector<Vec3>& cand) {
    const size_t n = pts.size(), m = std::min(n, kViewSamples);
    std::vector<uint8_t> seen(cand.size() * m);
    parallel_for_range<size_t>(seen.size(), 256, [&](size_t chunk_begin, size_t chunk_end) {
        for (size_t k = chunk_begin; k < chunk_end; ++k) {
            const uint32_t i = uint32_t((k % m) * n / m);
            seen[k] = caster.sees(i, cand[k / m], ray_start(radii[i], r_med, noise));
        }
    });
    return seen;
}

// kHoleRays directions spread evenly over the sphere (a Fibonacci lattice).
constexpr int kHoleRays = 256;
const std::vector<Vec3>& sphere_directions() {
    static const std::vector<Vec3> dirs = [] {
        std::vector<Vec3> d;
        for (int k = 0; k < kHoleRays; ++k) {
            const float z = 1.0f - 2.0f * (float(k) + 0.5f) / float(kHoleRays);
            const float r = std::sqrt(1.0f - z * z), a = 2.39996323f * float(k);
            d.push_back({r * std::cos(a), r * std::sin(a), z});
        }
        return d;
    }();
    return dirs;
}

// Ties go to the lower candidate and the first step tried, so the view does not depend on the
// number of threads. seen: sampled_views of cand (the first cand.size() rows are used); step0:
// the lattice's spacing; h: the voxel grid's cell.
std::optional<View> find_view(const DiscCaster& caster, const std::vector<Vec3>& pts,
                              const std::vector<float>& radii, float r_med, float noise,
                              const std::vector<Vec3>& cand, const std::vector<uint8_t>& seen,
                              float step0, float h) {
    const size_t n = pts.size(), m = std::min(n, kViewSamples), c = cand.size();
    if (c == 0 || m == 0) return std::nullopt;
    auto sample = [&](size_t j) { return uint32_t(j * n / m); };
    auto sees = [&](size_t j, Vec3 x) {
        const uint32_t i = sample(j);
        return caster.sees(i, x, ray_start(radii[i], r_med, noise));
    };
    // How many samples x sees.
    auto seen_from = [&](Vec3 x) {
        std::atomic<size_t> count{0};
        parallel_for_range<size_t>(m, 64, [&](size_t chunk_begin, size_t chunk_end) {
            size_t local = 0;
            for (size_t j = chunk_begin; j < chunk_end; ++j) local += sees(j, x);
            count += local;
        });
        return count.load();
    };
    std::vector<size_t> gain(c);
    for (size_t v = 0; v < c; ++v)
        gain[v] = size_t(std::count(seen.begin() + v * m, seen.begin() + (v + 1) * m, 1));
    size_t best = 0;
    for (size_t v = 1; v < c; ++v)
        if (gain[v] > gain[best]) best = v;
    Vec3 x = cand[best];
    size_t g = gain[best];
    for (float step = 0.5f * step0; step >= h;) {
        Vec3 next = x;
        size_t next_seen = g;
        for (int a = 0; a < 6; ++a) {
            Vec3 d{0, 0, 0};
            (a / 2 == 0 ? d.x : a / 2 == 1 ? d.y : d.z) = a % 2 ? -step : step;
            const size_t s = seen_from(x + d);
            if (s > next_seen) next = x + d, next_seen = s;
        }
        if (next_seen > g) {
            x = next, g = next_seen;
        } else {
            step *= 0.5f;
        }
    }
    const size_t near = g - std::min(g, std::max<size_t>(2, size_t(kViewTolerance * double(g))));
    View view{x, {x, x}, g, m};
    // The region holds only places that see no more holes than the view itself (holes_from:
    // gaps between discs, and surface no scanner saw, a shadow): a scanner records all it sees,
    // so a place that looks onto more unscanned surface than the view is not taken for where
    // one stood. Behind a sheet scanned from one side lie its shadows; without this, places there
    // saw about as many points and the region straddled the sheet's plane, leaving it to the
    // rays, which travel farther through its unscanned back (docs/validation.md "Scans: the
    // view's region and the shadows").
    const std::vector<Vec3>& dirs = sphere_directions();
    const size_t limit = caster.holes_from(x, dirs);
    auto clear = [&](Vec3 p) { return caster.holes_from(p, dirs) <= limit; };
    for (size_t v = 0; v < c; ++v)
        if (gain[v] >= near && clear(cand[v])) grow(view.region, cand[v]);
    for (const Vec3 d : around())
        for (float s = h; s <= 2 * step0; s *= 2) {
            if (seen_from(x + d * s) < near) break;
            if (clear(x + d * s)) grow(view.region, x + d * s);
        }
    return view;
}

// The side of point i (+1 along its normal, -1 against it) that the view sees it from: 0 when
// it does not see it, sees it grazing, or the point's tangent plane cuts the view's region (the
// scanner may have stood on either side).
int view_side(const DiscCaster& caster, const std::vector<Vec3>& pts,
              const std::vector<Vec3>& normals, uint32_t i, const View& v, float tmin) {
    const Vec3 p = pts[i], n = normals[i], to = v.at - p;
    const float dist = length(to);
    if (!(dist > 0)) return 0;
    const float c = dot(n, to) / dist;
    if (!(std::fabs(c) >= kViewMinCos)) return 0;
    const float s = c > 0 ? 1.0f : -1.0f;
    for (int k = 0; k < 8; ++k) {
        const Vec3 q{k & 1 ? v.region.hi.x : v.region.lo.x, k & 2 ? v.region.hi.y : v.region.lo.y,
                     k & 4 ? v.region.hi.z : v.region.lo.z};
        if (!(s * dot(n, q - p) > 0)) return 0;
    }
    return caster.sees(i, v.at, tmin) ? int(s) : 0;
}

// Where the scanners stood, from the points' spacing (step 6 of vote_sides, before the view).
// A terrestrial scanner turns about an upright axis and steps its beam by equal angles in
// azimuth and elevation, so a point it made at range r, seen at cosine c off its normal and at
// sine s off the turning axis, lies in a patch about (a r s) by (a r / c): its splat radius is
// k r sqrt(s / c), one k per scanner. From the true place the residual
//     log(radius) - log(r) + 0.5 log(c) - 0.5 log(s)
// is the same constant for all its points (within about 0.01 on a simulated scan); a few
// centimetres off, or from a place that sees the points through an unscanned side (inside an
// object's cap), it spreads over 0.05-0.12. A scanner far from what it scans sees little change
// of s, so the axis may also be left out; else it is one of the frame's axes (room_frame turns
// the walls onto them) or of the cloud's own, whichever fits best.
//
// The search: from every candidate (the view's, and places around the box at 0.75 and 3
// diagonals too), Gauss-Newton steps on the points it sees move the place and k until their
// residuals agree, weighted by a kernel about their peak that narrows from 4 to 1 times sigma
// (kSpacingSigma, widened by the scan's noise); the best few settled places are then scored
// with visibility. Scanners only add points, so where several overlap the spacing is finer
// than any one of them makes it, never coarser. The best place is a scanner when
// - the points it explains (within 2 sigma) are at least 1 in 20 of the sampled points;
// - at most kSparserShare of the points it sees are coarser than it makes them (by 3 sigma or
//   more: the edges of a scan, where the nearest neighbours lie on one side, 6-12% of a
//   one-scanner scan of an object; a place that sees an object through its unscanned back, or
//   one among several overlapping scanners, spreads both ways: 15-44% on the scans measured);
// - at most a tenth of the earlier scanners' points (at their own spacing, so made by them
//   alone) lie where this place would have added a seventh or more to their density;
// - its points spread in spacing (log radius) by kExplainedSpread or more: a sampler's even
//   spacing is "explained" by a far place beyond a flat face, a scanner's is not even.
// Its points leave the sample and the search runs again for the next scanner. Where several
// scanners overlap almost everywhere (four or more around one object) no place explains enough
// points alone: the scan keeps the view (step 7) and the other rules. Where two overlap, no
// second place passes those tests (the points both made are finer than either makes them, and
// the best single place sits between the two), so a pair of places is also fitted to the sum
// of their densities (joint_search), then one place more at a time up to kMaxJoint, each set
// replacing the one before when it explains more.
constexpr float kSpacingSigma = 0.03f;  // the width of a scanner's residual peak (log units)
// A scan's noise scatters the radii too: by about 0.3 noise / radius in the log (0.09 at a tenth
// of a spacing per axis, measured on held-lone at the scanner's place); the peak widens so. Past
// kMaxSpacingSigma the spacing is not searched. The noise is measured on the points and set
// against their median radius, which a scan's crowding near its scanners makes finer than the
// sampler's: objects scanned without their room at a tenth of a spacing of noise read 0.105-0.109
// and, at the old limit of 0.1, went unsearched (cornell-bunny's bunny 76% of its signs right,
// held-table 30%). At 0.15 the objects' signs on the seventeen scenes' two-scanner scans of their
// objects alone rose 82.1% -> 94.3% (mean), their room scans at a quarter of a spacing 90.7% ->
// 92.9% at two scanners and 92.6% -> 94.6% at three, the scans at a tenth unchanged. It let a
// third place under held-table's top pass the tests (its objects alone at three scanners 81.7% ->
// 44.2%), which two_sided now rejects (95.3%). At 0.2, with two_sided, the scans at a quarter of
// a spacing gained again: objects alone 71.5% -> 95.1% (two scanners) and 78.0% -> 98.1% (three),
// rooms 92.9% -> 97.2% and 94.6% -> 95.0%, no scene lower; at a tenth nothing moved. Wider limits
// were not tried (docs/validation.md "Scans: noisy scans of objects").
constexpr float kNoiseSpacing = 0.3f;
constexpr float kMaxSpacingSigma = 0.2f;
constexpr size_t kMaxScanners = 8;
constexpr size_t kMinScannerPoints = 24;  // of the sampled points, explained by one place
constexpr size_t kScannerStarts = 6;      // settled places scored with visibility
constexpr size_t kLocatePoints = 256;     // the points a start's steps use, at most
constexpr double kExplainedSpread = 0.1;  // a scanner's points' spread of log radius, at least
constexpr double kSparserShare = 0.15;    // of what a scanner sees, coarser than it makes it
constexpr double kMinSpread = 0.15;       // the cloud's; below it no scanner is sought

struct Fit {
    double score = 0;  // the kernel summed over the residuals
    float centre = 0;  // log k
    size_t inliers = 0, seen = 0;
    size_t sparser = 0;  // residuals above the peak by more than 3 sigma
};

// Point i's residual from the place x (NaN where x sees it grazing or near the axis's poles);
// axis: the scanner's turning axis, unit length, or zero for none.
float spacing_residual(const std::vector<Vec3>& pts, const std::vector<Vec3>& normals,
                       const std::vector<float>& radii, uint32_t i, Vec3 x, Vec3 axis) {
    const Vec3 u = x - pts[i];
    const float dist = length(u);
    if (!(dist > 0) || !(radii[i] > 0)) return std::numeric_limits<float>::quiet_NaN();
    const float c = std::fabs(dot(normals[i], u)) / dist;
    if (!(c >= kViewMinCos)) return std::numeric_limits<float>::quiet_NaN();
    const float e = std::log(radii[i]) - std::log(dist) + 0.5f * std::log(c);
    if (axis == Vec3{0, 0, 0}) return e;
    const float along = dot(u, axis);
    const float perp = std::sqrt(std::max(0.0f, dist * dist - along * along));
    if (!(perp >= kViewMinCos * dist)) return std::numeric_limits<float>::quiet_NaN();
    return e - 0.5f * std::log(perp / dist);
}

// Two scanners at once. Where both see a point, its density is the sum of theirs, so its residual
// from either place alone lies below that place's peak: the single place that best fits a
// two-scanner scan sits between the two (on the test scenes 0.04-0.27 room widths from either),
// and the second, sought among the points the first leaves, never passes the tests. The pair's
// residual for point i is log r_i + 0.5 log(D_i), D_i = sum over the places of T_s (T_s =
// c_s / (dist_s^2 w_s), w_s = perp_s / dist_s with an axis: one place's residual is log r_i +
// 0.5 log T_s); places that see the point grazing (or near the axis's poles) add nothing, and a
// point no place sees is not counted. Its gradient in place s is (T_s / D_i) times that place's
// own (locate's).
struct Term {
    float t = 0;   // T_s; 0: this place does not count for the point
    Vec3 grad{};   // the single residual's gradient in the place
};

Term density_term(const std::vector<Vec3>& pts, const std::vector<Vec3>& normals, uint32_t i,
                  Vec3 x, Vec3 axis) {
    Term out;
    const Vec3 u = x - pts[i];
    const float uu = dot(u, u);
    if (!(uu > 0)) return out;
    const float dist = std::sqrt(uu), nu = dot(normals[i], u);
    const float c = std::fabs(nu) / dist;
    if (!(c >= kViewMinCos)) return out;
    float w = 1;
    out.grad = u * (-1.5f / uu) + normals[i] * (0.5f / nu);
    if (!(axis == Vec3{0, 0, 0})) {
        const Vec3 q = u - axis * dot(u, axis);
        const float qq = dot(q, q);
        w = std::sqrt(qq) / dist;
        if (!(w >= kViewMinCos)) return Term{};
        out.grad = out.grad + (u * (1.0f / uu) - q * (1.0f / std::max(qq, 1e-30f))) * 0.5f;
    }
    out.t = c / (uu * w);
    return out;
}

constexpr size_t kMaxJoint = 4;  // places fitted at once, at most
using Places = std::vector<Vec3>;

// Point i's residual from the places x (NaN where none counts), counting place k only where bit
// k of `sees` is set; owner: the place that makes most of its density.
float joint_residual(const std::vector<Vec3>& pts, const std::vector<Vec3>& normals,
                     const std::vector<float>& radii, uint32_t i, const Places& x, Vec3 axis,
                     uint32_t sees, int* owner = nullptr) {
    if (!(radii[i] > 0)) return std::numeric_limits<float>::quiet_NaN();
    float d = 0, top = 0;
    for (size_t k = 0; k < x.size(); ++k) {
        if (!(sees >> k & 1)) continue;
        const float t = density_term(pts, normals, i, x[k], axis).t;
        d += t;
        if (t > top) {
            top = t;
            if (owner) *owner = int(k);
        }
    }
    if (!(d > 0)) return std::numeric_limits<float>::quiet_NaN();
    return std::log(radii[i]) + 0.5f * std::log(d);
}

// The middle of the window of width 4 sigma holding the most of the residuals v (sorted here).
float residual_peak(std::vector<float>& v, float sigma) {
    std::sort(v.begin(), v.end());
    size_t best = 0, lo = 0, at = 0;
    for (size_t hi = 0; hi < v.size(); ++hi) {
        while (v[hi] - v[lo] > 4 * sigma) ++lo;
        if (hi - lo + 1 > best) best = hi - lo + 1, at = lo;
    }
    double sum = 0;
    for (size_t j = at; j < at + best; ++j) sum += v[j];
    return best ? float(sum / double(best)) : 0.0f;
}

Fit fit_residuals(std::vector<float>& e, float sigma) {
    Fit f;
    f.seen = e.size();
    if (e.empty()) return f;
    f.centre = residual_peak(e, sigma);
    for (const float v : e) {
        const double z = (v - f.centre) / sigma;
        f.score += std::exp(-0.5 * z * z);
        f.inliers += std::fabs(z) < 2;
        f.sparser += z > 3;
    }
    return f;
}

// Weighted Gauss-Newton steps for the place x and log k that make the residuals of the points
// idx agree. With u = x - p, the residual's gradient in x is -1.5 u / |u|^2 + 0.5 n / (n . u),
// plus 0.5 (u / |u|^2 - u_perp / |u_perp|^2) with an axis (u_perp: u off the axis). Steps are
// capped at a quarter of `scale` (the box's extent). Serial and arithmetic only: visibility is
// judged once the place has settled.
Vec3 locate(const std::vector<Vec3>& pts, const std::vector<Vec3>& normals,
            const std::vector<float>& radii, const std::vector<uint32_t>& idx, Vec3 x, float scale,
            Vec3 axis, float sigma0) {
    const size_t m = idx.size();
    std::vector<float> e(m), v;
    for (const float sigma : {4 * sigma0, 2 * sigma0, sigma0}) {
        for (int it = 0; it < 10; ++it) {
            v.clear();
            for (size_t j = 0; j < m; ++j) {
                e[j] = spacing_residual(pts, normals, radii, idx[j], x, axis);
                if (!std::isnan(e[j])) v.push_back(e[j]);
            }
            if (v.size() < kMinScannerPoints) return x;
            const double centre = residual_peak(v, sigma);
            double A[4][4] = {}, g[4] = {};
            for (size_t j = 0; j < m; ++j) {
                if (std::isnan(e[j])) continue;
                const double z = (e[j] - centre) / sigma;
                if (std::fabs(z) > 3) continue;
                const double w = std::exp(-0.5 * z * z);
                const Vec3 u = x - pts[idx[j]], n = normals[idx[j]];
                const double uu = double(dot(u, u)), nu = double(dot(n, u));
                double J[4] = {-1.5 * u.x / uu + 0.5 * n.x / nu, -1.5 * u.y / uu + 0.5 * n.y / nu,
                               -1.5 * u.z / uu + 0.5 * n.z / nu, -1.0};
                if (!(axis == Vec3{0, 0, 0})) {
                    const Vec3 q = u - axis * dot(u, axis);
                    const double qq = std::max(double(dot(q, q)), 1e-30);
                    J[0] += 0.5 * (u.x / uu - q.x / qq);
                    J[1] += 0.5 * (u.y / uu - q.y / qq);
                    J[2] += 0.5 * (u.z / uu - q.z / qq);
                }
                const double r = e[j] - centre;
                for (int a = 0; a < 4; ++a) {
                    g[a] -= w * J[a] * r;
                    for (int b = 0; b < 4; ++b) A[a][b] += w * J[a] * J[b];
                }
            }
            for (int a = 0; a < 4; ++a) A[a][a] = A[a][a] * (1.0 + 1e-3) + 1e-12;
            if (!solve_small(A, g)) break;
            Vec3 dx{float(g[0]), float(g[1]), float(g[2])};
            const float len = length(dx), cap = 0.25f * scale;
            if (!(len == len)) break;
            if (len > cap) dx = dx * (cap / len);
            x = x + dx;
            if (len < 1e-4f * scale) break;
        }
    }
    return x;
}

// locate for K places at once (3K + 1 unknowns: the places and log k), over the points idx,
// visibility left out.
template <size_t K>
void locate_joint(const std::vector<Vec3>& pts, const std::vector<Vec3>& normals,
                  const std::vector<float>& radii, const std::vector<uint32_t>& idx, Places& x,
                  float scale, Vec3 axis, float sigma0) {
    constexpr size_t N = 3 * K + 1;
    const size_t m = idx.size();
    const uint32_t all = (1u << K) - 1;
    std::vector<float> e(m), v;
    for (const float sigma : {4 * sigma0, 2 * sigma0, sigma0}) {
        for (int it = 0; it < 10; ++it) {
            v.clear();
            for (size_t j = 0; j < m; ++j) {
                e[j] = joint_residual(pts, normals, radii, idx[j], x, axis, all);
                if (!std::isnan(e[j])) v.push_back(e[j]);
            }
            if (v.size() < kMinScannerPoints) return;
            const double centre = residual_peak(v, sigma);
            double A[N][N] = {}, g[N] = {};
            for (size_t j = 0; j < m; ++j) {
                if (std::isnan(e[j])) continue;
                const double z = (e[j] - centre) / sigma;
                if (std::fabs(z) > 3) continue;
                const double w = std::exp(-0.5 * z * z);
                std::array<Term, K> t;
                double d = 0;
                for (size_t k = 0; k < K; ++k) {
                    t[k] = density_term(pts, normals, idx[j], x[k], axis);
                    d += double(t[k].t);
                }
                double J[N];
                for (size_t k = 0; k < K; ++k) {
                    const double f = double(t[k].t) / d;
                    J[3 * k] = f * t[k].grad.x, J[3 * k + 1] = f * t[k].grad.y,
                    J[3 * k + 2] = f * t[k].grad.z;
                }
                J[N - 1] = -1.0;
                const double r = e[j] - centre;
                for (size_t p = 0; p < N; ++p) {
                    g[p] -= w * J[p] * r;
                    for (size_t q = 0; q < N; ++q) A[p][q] += w * J[p] * J[q];
                }
            }
            for (size_t p = 0; p < N; ++p) A[p][p] = A[p][p] * (1.0 + 1e-3) + 1e-12;
            if (!solve_small(A, g)) break;
            float moved = 0;
            for (size_t k = 0; k < K; ++k) {
                Vec3 dx{float(g[3 * k]), float(g[3 * k + 1]), float(g[3 * k + 2])};
                const float len = length(dx), cap = 0.25f * scale;
                if (!(len == len)) return;
                if (len > cap) dx = dx * (cap / len);
                x[k] = x[k] + dx;
                moved = std::max(moved, len);
            }
            if (moved < 1e-4f * scale) break;
        }
    }
}

void locate_places(const std::vector<Vec3>& pts, const std::vector<Vec3>& normals,
                   const std::vector<float>& radii, const std::vector<uint32_t>& idx, Places& x,
                   float scale, Vec3 axis, float sigma) {
    switch (x.size()) {
        case 2: return locate_joint<2>(pts, normals, radii, idx, x, scale, axis, sigma);
        case 3: return locate_joint<3>(pts, normals, radii, idx, x, scale, axis, sigma);
        case 4: return locate_joint<4>(pts, normals, radii, idx, x, scale, axis, sigma);
        default: return;
    }
}

// Point i's residual from the place x where x sees it (not grazing, no disc between them); NaN
// where not. The arithmetic first, the ray only where it counts.
float seen_residual(const DiscCaster& caster, const std::vector<Vec3>& pts,
                    const std::vector<Vec3>& normals, const std::vector<float>& radii,
                    float r_med, float noise, uint32_t i, Vec3 x, Vec3 axis) {
    const float e = spacing_residual(pts, normals, radii, i, x, axis);
    if (std::isnan(e) || !caster.sees(i, x, ray_start(radii[i], r_med, noise)))
        return std::numeric_limits<float>::quiet_NaN();
    return e;
}

// From every candidate, the place that the sampled points it sees (and `use(j)` keeps) settle on
// (locate), and the candidates ranked by their fit there without visibility, best first.
struct Settled {
    std::vector<Vec3> at;
    std::vector<std::pair<double, size_t>> ranked;  // (-score, candidate)
};
template <class Use>
Settled settle_candidates(const std::vector<Vec3>& pts, const std::vector<Vec3>& normals,
                          const std::vector<float>& radii, const std::vector<Vec3>& cand,
                          const std::vector<uint8_t>& seen, size_t m, float scale, Vec3 axis,
                          float sigma, Use use) {
    const size_t n = pts.size(), c = cand.size();
    Settled out{std::vector<Vec3>(c), std::vector<std::pair<double, size_t>>(c)};
    parallel_for_range<size_t>(c, 1, [&](size_t chunk_begin, size_t chunk_end) {
        std::vector<uint32_t> idx, few;
        std::vector<float> r;
        for (size_t v = chunk_begin; v < chunk_end; ++v) {
            idx.clear(), few.clear(), r.clear();
            for (size_t j = 0; j < m; ++j)
                if (use(j) && seen[v * m + j]) idx.push_back(uint32_t(j * n / m));
            const size_t stride = std::max<size_t>(1, idx.size() / kLocatePoints);
            for (size_t j = 0; j < idx.size(); j += stride) few.push_back(idx[j]);
            out.at[v] = locate(pts, normals, radii, few, cand[v], scale, axis, sigma);
            for (const uint32_t i : idx) {
                const float x = spacing_residual(pts, normals, radii, i, out.at[v], axis);
                if (!std::isnan(x)) r.push_back(x);
            }
            out.ranked[v] = {-fit_residuals(r, sigma).score, v};
        }
    });
    std::sort(out.ranked.begin(), out.ranked.end());
    return out;
}

struct Scanners {
    std::vector<Vec3> at;
    Vec3 axis{0, 0, 0};
    double score = 0;  // the first scanner's fit, or the joint set's when one replaced it
};

// The sides of point i's tangent plane that the places `at` see it from (not grazing, no disc
// between): bit 0 along its normal, bit 1 against it. An opaque surface shows a scanner the side
// facing it, so two scanners see a point from opposite sides only where the other face is nearer
// than the rays' start (a thin part, a noisy rim). A place that stands behind a scanned surface,
// under a table's top or inside an object's unscanned back, sees all of it from behind.
int two_sided(const DiscCaster& caster, const std::vector<Vec3>& pts,
              const std::vector<Vec3>& normals, uint32_t i, const std::vector<Vec3>& at,
              float tmin) {
    int sides = 0;
    for (const Vec3 x : at) {
        const Vec3 to = x - pts[i];
        const float dist = length(to);
        if (!(dist > 0)) continue;
        const float cs = dot(normals[i], to) / dist;
        if (!(std::fabs(cs) >= kViewMinCos) || (sides & (cs > 0 ? 1 : 2)) ||
            !caster.sees(i, x, tmin))
            continue;
        sides |= cs > 0 ? 1 : 2;
    }
    return sides;
}
// Of the sampled points a set of places sees, the share it may see from both sides. Over the
// sets that passed the other tests on the seventeen scenes' two- and three-scanner scans (rooms
// and objects alone, noise 0 and 0.1): 193 of 239 under 1%, 28 at 1-20% (a hollow shell's thin
// walls 4-15%), 18 at 23-49% (places under a table's top, beside cornell-dragon's two scanners,
// around a lone object). At 10% test-open-hollow's objects alone lost their pair
// (docs/validation.md "Scans: noisy scans of objects").
constexpr double kTwoSidedShare = 0.2;

constexpr size_t kPairStarts = 8;  // settled single places, paired with each other
// How much more a pair must explain than the best single place (the fit's kernel score). Two
// places have more freedom than one: on one-scanner scans the fit splits the scanner into two a
// few centimetres apart that score 0.01-0.9% above it, while on two-scanner scans the pair
// scores 25-80% above the single place (a probe printing both, not kept; docs/validation.md
// "Scans: two scanners as a pair").
constexpr double kPairGain = 1.1;

// Several scanners at once (joint_residual). First a pair, from pairs of the best-ranked single
// places (settled by the points each candidate sees) and, where a first scanner was found, from
// that scanner with each of the best places settled on the points it does not see (those the
// other made alone); then, while that passes, one place more at a time, settled on the points
// none of the places found sees. The settled set that fits best with visibility replaces `out`
// when it passes the single scanner's tests (enough points, few sparser than it makes them,
// spread in spacing), each place makes most of the density of enough of them, it scores
// kPairGain times `out` or more, and it sees at most kTwoSidedShare of its points from both
// sides (two_sided).
void joint_search(const DiscCaster& caster, const std::vector<Vec3>& pts,
                  const std::vector<Vec3>& normals, const std::vector<float>& radii, float r_med,
                  float noise, const Settled& first, const std::vector<Vec3>& cand,
                  const std::vector<uint8_t>& seen, size_t m, float scale, Vec3 axis, float sigma,
                  Scanners& out) {
    const size_t n = pts.size();
    auto sample = [&](size_t j) { return uint32_t(j * n / m); };
    auto tmin = [&](uint32_t i) { return ray_start(radii[i], r_med, noise); };
    const float apart = 0.05f * scale;
    // The best-ranked settled places, at least `apart` from each other.
    auto distinct = [&](const Settled& s) {
        std::vector<Vec3> starts;
        for (const auto& [score, v] : s.ranked) {
            const Vec3 x = s.at[v];
            if (!std::isfinite(x.x) || !std::isfinite(x.y) || !std::isfinite(x.z)) continue;
            if (std::none_of(starts.begin(), starts.end(),
                             [&](Vec3 y) { return length(x - y) < apart; }))
                starts.push_back(x);
            if (starts.size() == kPairStarts) break;
        }
        return starts;
    };
    // The best places settled on the sampled points that none of `at` sees (not grazing).
    auto unseen_starts = [&](const Places& at) {
        std::vector<uint8_t> left(m);
        parallel_for_range<size_t>(m, 64, [&](size_t chunk_begin, size_t chunk_end) {
            for (size_t j = chunk_begin; j < chunk_end; ++j) {
                const uint32_t i = sample(j);
                left[j] = std::none_of(at.begin(), at.end(), [&](Vec3 x) {
                    return !std::isnan(
                        seen_residual(caster, pts, normals, radii, r_med, noise, i, x, axis));
                });
            }
        });
        return distinct(settle_candidates(pts, normals, radii, cand, seen, m, scale, axis, sigma,
                                          [&](size_t j) { return left[j] != 0; }));
    };
    std::vector<uint32_t> few;
    for (size_t j = 0; j < m; j += std::max<size_t>(1, m / kLocatePoints)) few.push_back(sample(j));
    // Settles each set, then scores the best few with visibility; true when the best replaced
    // `out`.
    auto try_sets = [&](std::vector<Places>& sets) {
        if (sets.empty()) return false;
        std::vector<std::pair<double, size_t>> order(sets.size());
        parallel_for_range<size_t>(sets.size(), 1, [&](size_t chunk_begin, size_t chunk_end) {
            std::vector<float> r;
            for (size_t k = chunk_begin; k < chunk_end; ++k) {
                locate_places(pts, normals, radii, few, sets[k], scale, axis, sigma);
                r.clear();
                const uint32_t all = (1u << sets[k].size()) - 1;
                for (size_t j = 0; j < m; ++j) {
                    const float x =
                        joint_residual(pts, normals, radii, sample(j), sets[k], axis, all);
                    if (!std::isnan(x)) r.push_back(x);
                }
                order[k] = {-fit_residuals(r, sigma).score, k};
            }
        });
        std::sort(order.begin(), order.end());
        Fit best;
        Places best_at;
        std::vector<float> best_e, e(m);
        std::vector<int> best_owner, owner(m);
        for (size_t t = 0; t < std::min(kScannerStarts, order.size()); ++t) {
            const Places& x = sets[order[t].second];
            bool close = false;
            for (size_t a = 0; a < x.size(); ++a)
                for (size_t b = a + 1; b < x.size(); ++b) close |= length(x[a] - x[b]) < apart;
            if (close) continue;
            parallel_for_range<size_t>(m, 64, [&](size_t chunk_begin, size_t chunk_end) {
                for (size_t j = chunk_begin; j < chunk_end; ++j) {
                    const uint32_t i = sample(j);
                    uint32_t sees = 0;
                    for (size_t k = 0; k < x.size(); ++k)
                        sees |= uint32_t(caster.sees(i, x[k], tmin(i))) << k;
                    owner[j] = 0;
                    e[j] = joint_residual(pts, normals, radii, i, x, axis, sees, &owner[j]);
                }
            });
            std::vector<float> counted;
            for (const float r : e)
                if (!std::isnan(r)) counted.push_back(r);
            const Fit f = fit_residuals(counted, sigma);
            if (f.score > best.score) best = f, best_at = x, best_e = e, best_owner = owner;
        }
        if (best_e.empty()) return false;
        // The radii of the inliers each place mostly makes.
        std::vector<std::vector<float>> owned(best_at.size());
        for (size_t j = 0; j < m; ++j)
            if (!std::isnan(best_e[j]) && std::fabs(best_e[j] - best.centre) < 2 * sigma)
                owned[size_t(best_owner[j])].push_back(radii[sample(j)]);
        const size_t need = std::max(kMinScannerPoints, m / 20);
        for (const std::vector<float>& o : owned)
            if (o.size() < need || log_spread(o) < kExplainedSpread) return false;
        if (double(best.sparser) > kSparserShare * double(best.seen) ||
            !(best.score > kPairGain * out.score))
            return false;
        // No place may stand behind what the others scanned (two_sided).
        size_t seen_by_any = 0, two = 0;
        for (size_t j = 0; j < m; ++j) {
            const uint32_t i = sample(j);
            const int sides = two_sided(caster, pts, normals, i, best_at, tmin(i));
            seen_by_any += sides != 0;
            two += sides == 3;
        }
        if (double(two) > kTwoSidedShare * double(seen_by_any)) return false;
        out.at = best_at;
        out.score = best.score;
        return true;
    };
    std::vector<Places> sets;
    const std::vector<Vec3> starts = distinct(first);
    for (size_t a = 0; a < starts.size(); ++a)
        for (size_t b = a + 1; b < starts.size(); ++b) sets.push_back({starts[a], starts[b]});
    if (out.at.size() == 1)
        for (const Vec3 x : unseen_starts(out.at)) sets.push_back({out.at[0], x});
    if (!try_sets(sets)) return;
    while (out.at.size() < kMaxJoint) {
        sets.clear();
        for (const Vec3 x : unseen_starts(out.at)) {
            sets.push_back(out.at);
            sets.back().push_back(x);
        }
        if (!try_sets(sets)) return;
    }
}

// The scanners for one axis model, given what each candidate sees of the m sampled points.
Scanners scanners_for_axis(const DiscCaster& caster, const std::vector<Vec3>& pts,
                           const std::vector<Vec3>& normals, const std::vector<float>& radii,
                           float r_med, float noise, const std::vector<Vec3>& cand,
                           const std::vector<uint8_t>& seen, size_t m, float scale, Vec3 axis,
                           float sigma) {
    const size_t n = pts.size(), c = cand.size();
    Scanners out;
    out.axis = axis;
    auto sample = [&](size_t j) { return uint32_t(j * n / m); };
    auto residual = [&](uint32_t i, Vec3 x) {
        return seen_residual(caster, pts, normals, radii, r_med, noise, i, x, axis);
    };
    std::vector<uint8_t> explained(m, 0);
    std::vector<float> e;
    Settled first;  // the first search's
    while (out.at.size() < kMaxScanners) {
        // From every candidate, the place that the points it sees (and no scanner explains yet)
        // settle on, ranked by their fit without visibility; the best few then with it.
        const Settled st = settle_candidates(pts, normals, radii, cand, seen, m, scale, axis,
                                             sigma, [&](size_t j) { return !explained[j]; });
        const std::vector<Vec3>& settled = st.at;
        const std::vector<std::pair<double, size_t>>& ranked = st.ranked;
        if (out.at.empty()) first = st;
        Vec3 best_at{};
        Fit best;
        std::vector<float> best_e;  // the best place's residual per sample (NaN: not counted)
        for (size_t t = 0; t < std::min(kScannerStarts, c); ++t) {
            const Vec3 x = settled[ranked[t].second];
            e.assign(m, std::numeric_limits<float>::quiet_NaN());
            parallel_for_range<size_t>(m, 64, [&](size_t chunk_begin, size_t chunk_end) {
                for (size_t j = chunk_begin; j < chunk_end; ++j)
                    if (!explained[j]) e[j] = residual(sample(j), x);
            });
            std::vector<float> counted;
            for (const float r : e)
                if (!std::isnan(r)) counted.push_back(r);
            const Fit f = fit_residuals(counted, sigma);
            if (f.score > best.score) best = f, best_at = x, best_e.swap(e);
        }
        if (out.at.empty()) out.score = best.score;
        // Where the earlier scanners' points bunch at their own spacing, this place would have
        // added points of its own (its density at least a seventh of theirs): conflicts.
        size_t conflicts = 0, earlier = 0;
        for (size_t j = 0; j < m; ++j) {
            if (!explained[j]) continue;
            ++earlier;
            const float r = residual(sample(j), best_at);
            conflicts += !std::isnan(r) && r < best.centre + 1.0f;
        }
        if (best.inliers < std::max(kMinScannerPoints, m / 20) ||
            double(best.sparser) > kSparserShare * double(best.seen) || 10 * conflicts > earlier)
            break;
        // Its points (best.inliers of them).
        std::vector<uint32_t> mine;
        for (size_t j = 0; j < m; ++j)
            if (!std::isnan(best_e[j]) && std::fabs(best_e[j] - best.centre) < 2 * sigma)
                mine.push_back(uint32_t(j));
        std::vector<float> theirs;
        for (const uint32_t j : mine) theirs.push_back(radii[sample(j)]);
        if (log_spread(theirs) < kExplainedSpread) break;
        for (const uint32_t j : mine) explained[j] = 1;
        out.at.push_back(best_at);
    }
    if (out.at.size() < 2)
        joint_search(caster, pts, normals, radii, r_med, noise, first, cand, seen, m, scale, axis,
                     sigma, out);
    return out;
}

// The peak's width for a scan with this noise (kNoiseSpacing); past kMaxSpacingSigma the
// spacing is not searched.
float spacing_sigma(float noise, float r_med) {
    const float t = kNoiseSpacing * noise / r_med;
    return std::sqrt(kSpacingSigma * kSpacingSigma + t * t);
}

// The scanners of the axis model whose first scanner fits best, among the models that found
// one: a model whose best place fails the tests above found no scanner, however well that place
// scored, so it does not outrank a model that found one. (On four-scanner scans of held-lone and
// test-several the turning axis's best place scored highest and was rejected as sparser than it
// would make the points, while the model without an axis had found a place that passes: the
// objects' signs 93.8% -> 98.9% and 85.2% -> 93.5%; docs/validation.md "Scans: the axis model
// that found a scanner".) seen: sampled_views of cand.
Scanners find_scanners(const DiscCaster& caster, const std::vector<Vec3>& pts,
                       const std::vector<Vec3>& normals, const std::vector<float>& radii,
                       float r_med, float noise, const std::vector<Vec3>& cand,
                       const std::vector<uint8_t>& seen, float scale, float sigma,
                       const std::array<Vec3, 3>& frame) {
    const size_t m = std::min(pts.size(), kViewSamples);
    if (cand.empty() || m == 0) return {};
    // No axis; the frame's axes (a room's walls put its upright on one); the cloud's own (a lone
    // object's frame follows its faces, the cloud's up is the file's), where not the same.
    std::vector<Vec3> axes{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    for (int k = 0; k < 3; ++k) {
        const Vec3 e{k == 0 ? 1.0f : 0.0f, k == 1 ? 1.0f : 0.0f, k == 2 ? 1.0f : 0.0f};
        const Vec3 a{dot(frame[0], e), dot(frame[1], e), dot(frame[2], e)};
        if (std::max({std::fabs(a.x), std::fabs(a.y), std::fabs(a.z)}) < 0.9998f) axes.push_back(a);
    }
    Scanners best;
    for (const Vec3 axis : axes) {
        Scanners s = scanners_for_axis(caster, pts, normals, radii, r_med, noise, cand, seen, m,
                                       scale, axis, sigma);
        const bool found = !s.at.empty(), had = !best.at.empty();
        if (found != had ? found : s.score > best.score) best = std::move(s);
    }
    return best;
}

// The turning axis in words, in the cloud's coordinates.
std::string axis_words(const std::array<Vec3, 3>& frame, Vec3 a) {
    if (a == Vec3{0, 0, 0}) return "none seen";
    const Vec3 w = frame[0] * a.x + frame[1] * a.y + frame[2] * a.z;
    for (int k = 0; k < 3; ++k)
        if (std::fabs(k == 0 ? w.x : k == 1 ? w.y : w.z) > 0.9998f) return std::string(1, "xyz"[k]);
    return fmt::format("({:.3f}, {:.3f}, {:.3f})", w.x, w.y, w.z);
}

// The side of point i that every found scanner seeing it (not grazing) sees it from; 0 when none
// sees it or they disagree.
int scanners_side(const DiscCaster& caster, const std::vector<Vec3>& pts,
                  const std::vector<Vec3>& normals, uint32_t i, const std::vector<Vec3>& at,
                  float tmin) {
    const int sides = two_sided(caster, pts, normals, i, at, tmin);
    return sides == 1 ? 1 : sides == 2 ? -1 : 0;
}

}  // namespace

SideVotes vote_sides(const std::vector<Vec3>& world_pts, const std::vector<Vec3>& world_normals,
                     const std::vector<float>& radii, float noise) {
    const std::array<Vec3, 3> frame = room_frame(world_normals);
    const std::vector<Vec3> pts = in_frame(world_pts, frame);
    const std::vector<Vec3> normals = in_frame(world_normals, frame);
    const size_t n = pts.size();
    SideVotes v;
    v.sign.assign(n, 1);
    v.cue.assign(n, SideCue::kNone);
    v.weight.assign(n, 0.0f);
    v.open.assign(n, 0);
    const float r_med = median_radius(radii);
    const Bounds b = bounds_of(pts);
    if (n < 3 || !(r_med > 0) || !(max_extent(b) > 0)) {
        v.method = "no free-space cue (no extent or no radii)";
        return v;
    }
    const Grid g = make_grid(b, std::max(kSpacing * r_med, max_extent(b) / kMaxCells), kPad);
    const FreeSpace fs = free_space(pts, normals, radii, g, r_med);
    v.method = fs.method;
    std::array<bool, 6> walled{};
    const Bounds walls = wall_box(pts, normals, b, r_med, noise, walled);
    // A point lies on the box's face when its side leaves the box within half a splat radius,
    // and on a noisy wall within the noise's reach too: the face is the wall's outermost point,
    // about 4 sigma out, and the wall's points scatter about as far in (kFaceNoiseSigmas). A ray
    // that leaves the box within two cells (and that reach) has left "at once".
    const float on_face = 0.5f * r_med + kFaceNoiseSigmas * noise;
    const std::array<bool, 6> room_wall = room_wall_faces(fs, pts, normals, walls, on_face);
    // Holes count as walls only in a room's walls (free on both sides: the room's air, and the
    // padding beyond, one region through the room's opening or the holes themselves): a lone
    // object's flat face lies on the box too, and its far side is the object's own inside.
    for (size_t f = 0; f < 6; ++f) walled[f] = walled[f] && room_wall[f];
    const DiscCaster caster(pts, normals, radii, b, walls, walled, r_med,
                            2 * g.h + kFaceNoiseSigmas * noise);
    parallel_for_range<size_t>(n, 64, [&](size_t chunk_begin, size_t chunk_end) {
        for (size_t i = chunk_begin; i < chunk_end; ++i) {
            const int plus = fs.state(fs.sides[i][0]), minus = fs.state(fs.sides[i][1]);
            const Vec3 free_n = plus == 1 ? normals[i] : -normals[i];
            const bool wall = room_wall[size_t(DiscCaster::exit_face(walls, pts[i], free_n))];
            float side =
                float(space_side(plus, minus, caster.box_exit(pts[i], free_n), wall, on_face));
            SideCue cue = SideCue::kSpace;
            // An open sheet inside the scene: free on both sides, neither of them the bounding
            // box's face (a room's walls lie on it). 2 where a surface lies within the probe's
            // reach along the normal on either side: the probe may have walked through a part
            // thinner than that reach (or the point sits at a crease).
            if (plus == 1 && minus == 1 && caster.box_exit(pts[i], normals[i]) > on_face &&
                caster.box_exit(pts[i], -normals[i]) > on_face) {
                const float reach = 0.5f * g.h * float(kProbeSteps);
                const float tmin = ray_start(radii[i], r_med, noise);
                v.open[i] = 1;
                for (const Vec3 d : {normals[i], -normals[i]}) {
                    const float t = caster.first_hit(uint32_t(i), d, tmin);
                    if (t >= 0 && t <= reach) v.open[i] = 2;
                }
            }
            if (side == 0) {
                side = ray_side(caster, uint32_t(i), normals[i], radii[i], r_med, noise);
                cue = SideCue::kRays;
            }
            if (side == 0) continue;
            v.sign[i] = int8_t(side > 0 ? 1 : -1);
            v.cue[i] = cue;
            v.weight[i] = cue == SideCue::kSpace ? 2.0f : std::fabs(side);
        }
    });
    v.stacked = stacked_verdicts(caster, pts, normals, radii, r_med, noise,
                                 0.5f * g.h * float(kProbeSteps),
                                 2 * g.h + kFaceNoiseSigmas * noise, v);
    if (v.stacked > 0)
        v.method += fmt::format(
            "; {} points behind a surface stacked on them (a hollow shell's inner wall) signed by "
            "the rays",
            v.stacked);
    // Steps 6 and 7 start from one table of what the candidate places see.
    const float sigma = spacing_sigma(noise, r_med);
    const double spread = log_spread(radii);
    const bool spaced = spread >= kMinSpread && sigma <= kMaxSpacingSigma;
    v.scanned = spaced && spread >= kScanSpread;
    const bool room_scan = scanned_room(radii, walled);
    if (!spaced && !room_scan) return v;
    std::vector<Vec3> cand = view_candidates(g, fs, walls, room_wall);
    const size_t view_cand = cand.size();
    if (spaced) {
        const Vec3 mid = (walls.lo + walls.hi) * 0.5f;
        for (const float f : {0.75f, 3.0f})
            for (const Vec3 d : around())
                if (!room_wall[size_t(DiscCaster::exit_face(walls, mid, d))])
                    cand.push_back(mid + d * (f * length(walls.hi - walls.lo)));
    }
    const std::vector<uint8_t> seen = sampled_views(caster, pts, radii, r_med, noise, cand);
    const Scanners found = spaced ? find_scanners(caster, pts, normals, radii, r_med, noise, cand,
                                                  seen, max_extent(walls), sigma, frame)
                                  : Scanners{};
    if (!found.at.empty()) {
        parallel_for_range<size_t>(n, 64, [&](size_t chunk_begin, size_t chunk_end) {
            for (size_t i = chunk_begin; i < chunk_end; ++i) {
                if (v.cue[i] == SideCue::kSpace) continue;
                const int side = scanners_side(caster, pts, normals, uint32_t(i), found.at,
                                               ray_start(radii[i], r_med, noise));
                if (side == 0) continue;
                v.sign[i] = int8_t(side);
                v.cue[i] = SideCue::kView;
                v.weight[i] = 2.0f;
            }
        });
        for (const Vec3 x : found.at)
            v.scanners.push_back(frame[0] * x.x + frame[1] * x.y + frame[2] * x.z);
        std::string places;
        for (const Vec3 x : v.scanners)
            places += fmt::format("{}({:.4g}, {:.4g}, {:.4g})", places.empty() ? "" : ", ", x.x,
                                  x.y, x.z);
        v.method +=
            fmt::format("; a scan, its scanner{} at {} by the points' spacing (turning axis: {})",
                        found.at.size() == 1 ? "" : "s", places, axis_words(frame, found.axis));
    }
    if (!room_scan) return v;
    cand.resize(view_cand);
    const std::optional<View> view = find_view(caster, pts, radii, r_med, noise, cand, seen,
                                               max_extent(walls) / float(kViewLattice), g.h);
    if (!view) return v;
    parallel_for_range<size_t>(n, 64, [&](size_t chunk_begin, size_t chunk_end) {
        for (size_t i = chunk_begin; i < chunk_end; ++i) {
            if (v.cue[i] == SideCue::kSpace || v.cue[i] == SideCue::kView) continue;
            const int side = view_side(caster, pts, normals, uint32_t(i), *view,
                                       ray_start(radii[i], r_med, noise));
            if (side == 0) continue;
            v.sign[i] = int8_t(side);
            v.cue[i] = SideCue::kView;
            v.weight[i] = 2.0f;
        }
    });
    const Vec3 at = frame[0] * view->at.x + frame[1] * view->at.y + frame[2] * view->at.z;
    v.view = at;
    v.method += fmt::format(
        "; a scan from inside a room, the place that sees the most of it at about ({:.4g}, "
        "{:.4g}, {:.4g}) (sees {} of {} points sampled)",
        at.x, at.y, at.z, view->seen, view->samples);
    return v;
}

}  // namespace vmap::detail
