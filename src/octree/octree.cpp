// Adaptive octree construction (paper §3 and §5.2; docs/design.md).
#include "vmap/octree.h"

#include <fmt/format.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <tuple>
#include <vector>

#include "geom/morton.h"
#include "octree/delta_rule.h"
#include "octree/records.h"
#include "vmap/error.h"
#include "vmap/parallel.h"

namespace vmap {
namespace {

constexpr int kMortonBits = 21;  // per axis: 63-bit codes, so max_height <= 21

struct Builder {
    const PointSet& pts;
    const std::vector<uint64_t>& codes;  // sorted, aligned with pts
    const OctreeParams& params;
    detail::OctreeData& t;

    int32_t num_leaves() const { return static_cast<int32_t>(t.leaf_node.size()); }

    int32_t build(int level, uint32_t b, uint32_t e, Vec3 cell_min, float size, int32_t par) {
        const int32_t n = static_cast<int32_t>(t.skip.size());
        const float half = size * 0.5f;
        t.spheres.push_back({cell_min + Vec3{half, half, half}, 0.f});
        t.half_size.push_back(half);
        t.skip.push_back(0);
        t.parent.push_back(par);
        t.level.push_back(static_cast<uint8_t>(level));
        t.node_leaf.push_back(-1);
        t.point_begin.push_back(b);
        t.point_end.push_back(e);
        t.leaf_begin.push_back(num_leaves());
        t.leaf_end.push_back(0);

        if (e - b > static_cast<uint32_t>(params.leaf_points) && level < params.max_height) {
            const int shift = 3 * (kMortonBits - 1 - level);
            uint32_t lo = b;
            for (uint64_t oct = 0; oct < 8; ++oct) {
                // Codes in [b, e) share the bits above `shift`; the octant is the next 3 bits.
                uint32_t hi = lo;
                while (hi < e && ((codes[hi] >> shift) & 7) == oct) ++hi;
                if (hi > lo) {
                    const Vec3 cmin{cell_min.x + ((oct & 1) ? half : 0.f),
                                    cell_min.y + ((oct & 2) ? half : 0.f),
                                    cell_min.z + ((oct & 4) ? half : 0.f)};
                    build(level + 1, lo, hi, cmin, half, n);
                }
                lo = hi;
            }
        } else {
            t.node_leaf[n] = num_leaves();
            t.leaf_node.push_back(n);
        }
        t.skip[n] = static_cast<int32_t>(t.skip.size());
        t.leaf_end[n] = num_leaves();
        return n;
    }
};

}  // namespace

Octree Octree::build_in_unit_frame(PointSet& points, const OctreeParams& params,
                                   std::vector<uint32_t>& order, const std::string& source) {
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    double maxabs = 0;
    for (const Vec3& p : points.positions) {
        if (!is_finite(p)) continue;  // build() names it
        const double c[3] = {p.x, p.y, p.z};
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], c[a]), hi[a] = std::max(hi[a], c[a]);
            maxabs = std::max(maxabs, std::fabs(c[a]));
        }
    }
    const double extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 0.0});
    const double size = extent > 0 ? extent : maxabs;  // one point (or all at one place)
    const int k = size > 0 && std::isfinite(size) ? std::ilogb(size) + 1 : 0;
    auto down = [k](float v) { return float(std::ldexp(double(v), -k)); };
    for (Vec3& p : points.positions) p = {down(p.x), down(p.y), down(p.z)};
    for (float& r : points.radii) r = down(r);
    Octree t = build(points, params, order, source);
    detail::OctreeAccess::data(t).scale = std::ldexp(1.0, k);
    return t;
}

namespace {

// Throws for parameters out of range or points the octree cannot hold.
void check_input(const PointSet& points, const OctreeParams& params, const std::string& source) {
    static_assert(kMortonBits == 21);  // OctreeParams::check's bound on max_height
    params.check(source);
    const size_t n = points.size();
    if (n == 0) throw Error(fmt::format("{}: the point cloud is empty", source));
    if (n >= (1ull << 31)) throw Error(fmt::format("{}: too many points ({})", source, n));
    if (points.normals.size() != n)
        throw Error(fmt::format("{}: points have no normals (estimate them first)", source));
    if (!points.radii.empty() && points.radii.size() != n)
        throw Error(fmt::format("{}: {} radii for {} points", source, points.radii.size(), n));
    if (!points.colors.empty() && points.colors.size() != n)
        throw Error(fmt::format("{}: {} colours for {} points", source, points.colors.size(), n));
    if (!points.emission.empty() && points.emission.size() != n)
        throw Error(
            fmt::format("{}: {} emission values for {} points", source, points.emission.size(), n));
}

struct Extent {
    Vec3 lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
    double maxabs = 0;  // largest |coordinate|
};

// The bounds of the points; normalises the normals. Throws for non-finite coordinates and
// zero or non-finite normals or radii.
Extent check_points(PointSet& points, const std::string& source) {
    Extent x;
    for (size_t i = 0; i < points.size(); ++i) {
        const Vec3 p = points.positions[i];
        if (!is_finite(p))
            throw Error(fmt::format("{}: point {}: non-finite coordinate ({}, {}, {})", source, i,
                                    p.x, p.y, p.z));
        Vec3& nr = points.normals[i];
        const float len = length(nr);
        if (!is_finite(nr) || !(len > 1e-12f))
            throw Error(fmt::format("{}: point {}: normal ({}, {}, {}) is zero or not finite",
                                    source, i, nr.x, nr.y, nr.z));
        nr = nr / len;
        if (!points.radii.empty() && !(points.radii[i] >= 0 && std::isfinite(points.radii[i])))
            throw Error(fmt::format("{}: point {}: splat radius {} is negative or not finite",
                                    source, i, points.radii[i]));
        x.lo = {std::min(x.lo.x, p.x), std::min(x.lo.y, p.y), std::min(x.lo.z, p.z)};
        x.hi = {std::max(x.hi.x, p.x), std::max(x.hi.y, p.y), std::max(x.hi.z, p.z)};
        x.maxabs = std::max(
            {x.maxabs, (double)std::fabs(p.x), (double)std::fabs(p.y), (double)std::fabs(p.z)});
    }
    return x;
}

// The root cell: the bounding cube, padded by 0.1% so no point lies on its far faces. Sets
// root_min and root_size.
void place_root(detail::OctreeData& t, const Extent& x, const std::string& source) {
    // The extent in double: float coordinates near +-3e38 can span more than a float holds.
    const Vec3 lo = x.lo, hi = x.hi;
    const double dext = std::max({double(hi.x) - lo.x, double(hi.y) - lo.y, double(hi.z) - lo.z});
    if (!(dext * 1.001 < 3.0e38))
        throw Error(
            fmt::format("{}: the points span {:.3g} units, more than a float can hold; "
                        "rescale the coordinates",
                        source, dext));
    float extent = float(dext);
    if (!(extent > 0)) extent = std::max(1e-3f, static_cast<float>(x.maxabs) * 1e-3f);
    const float size = extent * 1.001f;
    const Vec3 mid = (lo + hi) * 0.5f;
    t.root_min = mid - Vec3{size * 0.5f, size * 0.5f, size * 0.5f};
    t.root_size = size;
}

// Sorts the points into Morton order (63-bit codes, ties by input index: deterministic);
// returns the sorted codes and sets order[k] to the input index of the k-th point.
std::vector<uint64_t> morton_sort(PointSet& points, Vec3 root_min, float size,
                                  std::vector<uint32_t>& order) {
    const size_t n = points.size();
    std::vector<uint64_t> code(n);
    const double scale = static_cast<double>(1u << kMortonBits) / size;
    parallel_for(n, [&](size_t i) {
        auto q = [&](float v, float m) {
            const double c = std::floor((static_cast<double>(v) - m) * scale);
            return static_cast<uint64_t>(std::clamp(c, 0.0, double((1u << kMortonBits) - 1)));
        };
        const Vec3 p = points.positions[i];
        code[i] = detail::spread_bits(q(p.x, root_min.x)) |
                  detail::spread_bits(q(p.y, root_min.y)) << 1 |
                  detail::spread_bits(q(p.z, root_min.z)) << 2;
    });
    order.resize(n);
    std::iota(order.begin(), order.end(), 0u);
    tbb::parallel_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
        return code[a] != code[b] ? code[a] < code[b] : a < b;
    });
    auto permute = [&](auto& v) {
        if (v.empty()) return;
        std::remove_reference_t<decltype(v)> out(n);
        for (size_t k = 0; k < n; ++k) out[k] = v[order[k]];
        v.swap(out);
    };
    permute(points.positions);
    permute(points.normals);
    permute(points.colors);
    permute(points.radii);
    permute(points.emission);
    permute(code);
    return code;
}

// The largest splat radius of points k in [b, e), where points at one position (exact copies:
// a cloud exported twice, two copies of a scan station) count as one disc of their summed area.
// Copies halve the spacing, so each gets a radius 1/sqrt(2) smaller (the right share of the
// area), but their discs coincide and cover only what one smaller disc does: the leaf's disc
// from the largest radius alone left holes the copies never filled. Without copies, the
// largest radius, bit for bit (sqrt of a float's square in double is the float).
float largest_splat(const PointSet& points, uint32_t b, uint32_t e) {
    if (points.radii.empty()) return 0;
    if (e - b == 1) return points.radii[b];
    std::vector<uint32_t> at(e - b);
    for (uint32_t k = b; k < e; ++k) at[k - b] = k;
    const auto key = [&](uint32_t k) {
        const Vec3 p = points.positions[k];
        return std::tuple(p.x, p.y, p.z);
    };
    std::sort(at.begin(), at.end(), [&](uint32_t i, uint32_t j) { return key(i) < key(j); });
    float splat = 0;
    for (size_t i = 0; i < at.size();) {
        double area = 0;  // of the copies at one position, in r^2
        size_t j = i;
        for (; j < at.size() && key(at[j]) == key(at[i]); ++j)
            area += double(points.radii[at[j]]) * double(points.radii[at[j]]);
        splat = std::max(splat, float(std::sqrt(area)));
        i = j;
    }
    return splat;
}

// Per leaf: the centroid and mean normal of its points (flagged when they cancel out) and the
// largest splat radius (largest_splat). Delta is left to apply_delta_rule.
void leaf_means(detail::OctreeData& t, const PointSet& points) {
    const int32_t L = static_cast<int32_t>(t.leaf_node.size());
    t.leaves.resize(L);
    t.leaf_splat.resize(L);
    parallel_for(L, [&](int32_t l) {
        const int32_t nd = t.leaf_node[l];
        const uint32_t b = t.point_begin[nd], e = t.point_end[nd];
        double cx = 0, cy = 0, cz = 0, nx = 0, ny = 0, nz = 0;
        for (uint32_t k = b; k < e; ++k) {
            const Vec3 p = points.positions[k], q = points.normals[k];
            cx += p.x, cy += p.y, cz += p.z;
            nx += q.x, ny += q.y, nz += q.z;
        }
        const float splat = largest_splat(points, b, e);
        const double cnt = e - b;
        LeafDisc d;
        d.centroid = {float(cx / cnt), float(cy / cnt), float(cz / cnt)};
        const double nlen = std::sqrt(nx * nx + ny * ny + nz * nz) / cnt;
        // Mean normal shorter than 0.1: the normals spread over more than a hemisphere (a
        // thin two-sided sheet, a sharp crease): no tangent plane stands for this leaf.
        if (nlen < 0.1) {
            d.flags |= kLeafNormalDegenerate;
            d.normal = {0, 0, 0};
        } else {
            const double s = 1.0 / (nlen * cnt);
            d.normal = {float(nx * s), float(ny * s), float(nz * s)};
        }
        t.leaves[l] = d;
        t.leaf_splat[l] = splat;
    });
}

// The bounding spheres about the cell centres: a leaf's encloses its points and its occluder
// disc, an internal node's every child sphere. DEVIATION from paper §5.2, which takes the plain
// maximum of the children's radii and so does not bound them.
void bounding_spheres(Octree& tree, const PointSet& points, float slack) {
    detail::OctreeData& t = detail::OctreeAccess::data(tree);
    parallel_for(tree.num_leaves(), [&](int32_t l) {
        const int32_t nd = t.leaf_node[l];
        const LeafDisc& d = t.leaves[l];
        const Vec3 c = t.spheres[nd].center;
        float rad2 = 0;
        for (uint32_t k = t.point_begin[nd]; k < t.point_end[nd]; ++k)
            rad2 = std::max(rad2, length2(points.positions[k] - c));
        t.spheres[nd].radius =
            std::max(std::sqrt(rad2), length(d.centroid - c) + d.delta) * 1.00001f + slack;
    });
    for (int32_t nd = tree.num_nodes() - 1; nd >= 0; --nd) {
        if (tree.is_leaf(nd)) continue;
        float r = 0;
        tree.for_each_child(nd, [&](int32_t c) {
            r = std::max(r,
                         length(t.spheres[c].center - t.spheres[nd].center) + t.spheres[c].radius);
        });
        t.spheres[nd].radius = r * 1.00001f + slack;
    }
}

}  // namespace

Octree Octree::build(PointSet& points, const OctreeParams& params, std::vector<uint32_t>& order,
                     const std::string& source) {
    check_input(points, params, source);
    const Extent extent = check_points(points, source);
    Octree tree;
    Data& t = tree.d_;
    t.params = params;
    place_root(t, extent, source);
    const std::vector<uint64_t> code = morton_sort(points, t.root_min, t.root_size, order);
    Builder{points, code, params, t}.build(0, 0, static_cast<uint32_t>(points.size()),
                                           t.root_min, t.root_size, -1);
    leaf_means(t, points);
    const float slack = detail::content_slack(extent.maxabs, t.root_size);
    detail::apply_delta_rule(tree, points, 1.f, params.delta_floor, slack);
    bounding_spheres(tree, points, slack);
    return tree;
}

float detail::content_slack(double maxabs, float root_size) {
    return static_cast<float>((maxabs + root_size) * 1e-6);
}

void detail::apply_delta_rule(Octree& tree, const PointSet& pts, float scale, float floor,
                              float slack) {
    OctreeData& t = OctreeAccess::data(tree);
    t.boxes.resize(t.skip.size());
    parallel_for(tree.num_leaves(), [&](int32_t l) {
        const int32_t nd = t.leaf_node[l];
        LeafDisc& d = t.leaves[l];
        float far2 = 0;
        Box bx{d.centroid, d.centroid};
        for (uint32_t k = t.point_begin[nd]; k < t.point_end[nd]; ++k) {
            const Vec3 q = pts.positions[k];
            far2 = std::max(far2, length2(q - d.centroid));
            bx.lo = {std::min(bx.lo.x, q.x), std::min(bx.lo.y, q.y), std::min(bx.lo.z, q.z)};
            bx.hi = {std::max(bx.hi.x, q.x), std::max(bx.hi.y, q.y), std::max(bx.hi.z, q.z)};
        }
        d.delta = scale * std::max(std::sqrt(far2), floor * t.leaf_splat[l]);
        bx = grow_by_disc(bx, d);
        t.boxes[nd] = {bx.lo - Vec3{slack, slack, slack}, bx.hi + Vec3{slack, slack, slack}};
    });
    for (int32_t nd = tree.num_nodes() - 1; nd >= 0; --nd) {
        if (tree.is_leaf(nd)) continue;
        Box bx{{INFINITY, INFINITY, INFINITY}, {-INFINITY, -INFINITY, -INFINITY}};
        tree.for_each_child(nd, [&](int32_t c) { bx = merge(bx, t.boxes[c]); });
        t.boxes[nd] = bx;
    }
    OctreeAccess::pack_walk(tree);
}

void detail::OctreeAccess::pack_walk(Octree& tree) {
    OctreeData& t = tree.d_;
    t.walk.resize(t.skip.size());
    for (size_t n = 0; n < t.skip.size(); ++n)
        t.walk[n] = WalkNode{t.boxes[n].lo, t.skip[n], t.boxes[n].hi, t.node_leaf[n]};
    t.point_leaf.resize(t.skip.empty() ? 0 : t.point_end[0]);
    for (size_t l = 0; l < t.leaf_node.size(); ++l)
        for (uint32_t k = t.point_begin[t.leaf_node[l]]; k < t.point_end[t.leaf_node[l]]; ++k)
            t.point_leaf[k] = int32_t(l);
}

Box grow_by_disc(Box bx, const LeafDisc& d) {
    auto reach = [&](float ni) {
        return d.delta * std::sqrt(std::max(0.f, 1.f - ni * ni)) * 1.00001f;
    };
    const Vec3 ext{reach(d.normal.x), reach(d.normal.y), reach(d.normal.z)};
    const Vec3 dlo = d.centroid - ext, dhi = d.centroid + ext;
    bx.lo = {std::min(bx.lo.x, dlo.x), std::min(bx.lo.y, dlo.y), std::min(bx.lo.z, dlo.z)};
    bx.hi = {std::max(bx.hi.x, dhi.x), std::max(bx.hi.y, dhi.y), std::max(bx.hi.z, dhi.z)};
    return bx;
}

Octree::Octree() = default;
Octree::~Octree() = default;
Octree::Octree(const Octree&) = default;
Octree::Octree(Octree&&) noexcept = default;
Octree& Octree::operator=(const Octree&) = default;
Octree& Octree::operator=(Octree&&) noexcept = default;

int Octree::height() const {
    int h = 0;
    for (int32_t l : d_.leaf_node) h = std::max(h, int(d_.level[l]));
    return h;
}

}  // namespace vmap
