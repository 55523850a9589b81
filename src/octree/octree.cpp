// Adaptive octree construction (DESIGN.md "Octree", paper §3 and §5.2).
#include "vmap/octree.h"

#include <fmt/format.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <numeric>

#include "geom/morton.h"
#include "octree/delta_rule.h"
#include "vmap/error.h"

namespace vmap {
namespace {

constexpr int kMortonBits = 21;  // per axis: 63-bit codes, so max_height <= 21

struct Builder {
    const PointSet& pts;
    const std::vector<uint64_t>& codes;  // sorted, aligned with pts
    const OctreeParams& params;
    Octree& t;

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
        t.leaf_begin.push_back(t.num_leaves());
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
            t.node_leaf[n] = t.num_leaves();
            t.leaf_node.push_back(n);
        }
        t.skip[n] = static_cast<int32_t>(t.skip.size());
        t.leaf_end[n] = t.num_leaves();
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
    t.scale = std::ldexp(1.0, k);
    return t;
}

Octree Octree::build(PointSet& points, const OctreeParams& params, std::vector<uint32_t>& order,
                     const std::string& source) {
    if (params.max_height < 1 || params.max_height > kMortonBits)
        throw Error(fmt::format("{}: max_height {} out of range (1..{})", source, params.max_height,
                                kMortonBits));
    if (params.leaf_points < 1 || params.leaf_points > 1000000)
        throw Error(fmt::format("{}: leaf_points {} out of range (1..1000000)", source,
                                params.leaf_points));
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

    double maxabs = 0;
    Vec3 lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = 0; i < n; ++i) {
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
        lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
        hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
        maxabs = std::max(
            {maxabs, (double)std::fabs(p.x), (double)std::fabs(p.y), (double)std::fabs(p.z)});
    }

    Octree t;
    t.params = params;
    // The root is the bounding cube, padded by 0.1% so no point lies on its far faces.
    // The extent in double: float coordinates near +-3e38 can span more than a float holds.
    const double dext = std::max({double(hi.x) - lo.x, double(hi.y) - lo.y, double(hi.z) - lo.z});
    if (!(dext * 1.001 < 3.0e38))
        throw Error(
            fmt::format("{}: the points span {:.3g} units, more than a float can hold; "
                        "rescale the coordinates",
                        source, dext));
    float extent = float(dext);
    if (!(extent > 0)) extent = std::max(1e-3f, static_cast<float>(maxabs) * 1e-3f);
    const float size = extent * 1.001f;
    const Vec3 mid = (lo + hi) * 0.5f;
    t.root_min = mid - Vec3{size * 0.5f, size * 0.5f, size * 0.5f};
    t.root_size = size;

    // Morton order: sort by 63-bit code, ties by input index (deterministic).
    std::vector<uint64_t> code(n);
    const double scale = static_cast<double>(1u << kMortonBits) / size;
    tbb::parallel_for(size_t(0), n, [&](size_t i) {
        auto q = [&](float v, float m) {
            const double c = std::floor((static_cast<double>(v) - m) * scale);
            return static_cast<uint64_t>(std::clamp(c, 0.0, double((1u << kMortonBits) - 1)));
        };
        const Vec3 p = points.positions[i];
        code[i] = detail::spread_bits(q(p.x, t.root_min.x)) |
                  detail::spread_bits(q(p.y, t.root_min.y)) << 1 |
                  detail::spread_bits(q(p.z, t.root_min.z)) << 2;
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
    permute(points.emission);  // emission belongs to its point like the colour (was left behind)
    permute(code);

    Builder{points, code, params, t}.build(0, 0, static_cast<uint32_t>(n), t.root_min, size, -1);

    // Leaf statistics (DESIGN.md: centroid, normal, Delta, splat radius, bounding sphere).
    // Conservative slack on every sphere: the float segment-sphere test errs by a few ulps of
    // the coordinates' magnitude, so spheres grow by 8 ulps of (|coordinates| + root size).
    const float slack = static_cast<float>((maxabs + size) * 1e-6);
    const int32_t L = t.num_leaves();
    t.leaves.resize(L);
    t.boxes.resize(t.num_nodes());
    t.leaf_splat.resize(L);
    tbb::parallel_for(int32_t(0), L, [&](int32_t l) {
        const int32_t nd = t.leaf_node[l];
        const uint32_t b = t.point_begin[nd], e = t.point_end[nd];
        double cx = 0, cy = 0, cz = 0, nx = 0, ny = 0, nz = 0;
        float splat = 0;
        for (uint32_t k = b; k < e; ++k) {
            const Vec3 p = points.positions[k], q = points.normals[k];
            cx += p.x, cy += p.y, cz += p.z;
            nx += q.x, ny += q.y, nz += q.z;
            if (!points.radii.empty()) splat = std::max(splat, points.radii[k]);
        }
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
        float far2 = 0, rad2 = 0;
        const Vec3 c = t.spheres[nd].center;
        for (uint32_t k = b; k < e; ++k) {
            far2 = std::max(far2, length2(points.positions[k] - d.centroid));
            rad2 = std::max(rad2, length2(points.positions[k] - c));
        }
        // Delta never below the splat radius (times a floor, octree/delta_rule.h), so a
        // one-point leaf still occludes.
        d.delta = std::max(std::sqrt(far2), detail::kDeltaSplatFloor * splat);
        t.leaves[l] = d;
        t.leaf_splat[l] = splat;
        // The box encloses the points and the disc: along axis i a disc of radius Delta and
        // normal n reaches Delta sqrt(1 - n_i^2) from its centre (the full Delta when flagged).
        Box bx{d.centroid, d.centroid};
        for (uint32_t k = b; k < e; ++k) {
            const Vec3 q = points.positions[k];
            bx.lo = {std::min(bx.lo.x, q.x), std::min(bx.lo.y, q.y), std::min(bx.lo.z, q.z)};
            bx.hi = {std::max(bx.hi.x, q.x), std::max(bx.hi.y, q.y), std::max(bx.hi.z, q.z)};
        }
        bx = grow_by_disc(bx, d);
        t.boxes[nd] = {bx.lo - Vec3{slack, slack, slack}, bx.hi + Vec3{slack, slack, slack}};
        // The sphere encloses the points and the occluder disc (centroid, normal, Delta).
        t.spheres[nd].radius =
            std::max(std::sqrt(rad2), length(d.centroid - c) + d.delta) * 1.00001f + slack;
    });
    // Internal nodes, children first (they follow their parent in preorder): the sphere about
    // the cell centre that encloses every child sphere. DEVIATION from paper §5.2, which takes
    // the plain maximum of the children's radii and so does not bound them.
    for (int32_t nd = t.num_nodes() - 1; nd >= 0; --nd) {
        if (t.is_leaf(nd)) continue;
        float r = 0;
        Box bx{{INFINITY, INFINITY, INFINITY}, {-INFINITY, -INFINITY, -INFINITY}};
        t.for_each_child(nd, [&](int32_t c) {
            bx = merge(bx, t.boxes[c]);
            r = std::max(r,
                         length(t.spheres[c].center - t.spheres[nd].center) + t.spheres[c].radius);
        });
        t.spheres[nd].radius = r * 1.00001f + slack;
        t.boxes[nd] = bx;
    }
    t.pack_walk();
    return t;
}

void Octree::pack_walk() {
    walk.resize(skip.size());
    for (size_t n = 0; n < skip.size(); ++n)
        walk[n] = WalkNode{boxes[n].lo, skip[n], boxes[n].hi, node_leaf[n]};
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

OctreeView Octree::view() const {
    return OctreeView{walk.data(), leaves.data(), num_nodes(), num_leaves()};
}

int Octree::height() const {
    int h = 0;
    for (int32_t l : leaf_node) h = std::max(h, int(level[l]));
    return h;
}

int32_t Octree::leaf_of_point(uint32_t k) const {
    // Leaves are in point order: the last leaf whose first point is <= k.
    int32_t lo = 0, hi = num_leaves();
    while (hi - lo > 1) {
        const int32_t mid = (lo + hi) / 2;
        if (point_begin[leaf_node[mid]] <= k)
            lo = mid;
        else
            hi = mid;
    }
    return lo;
}

}  // namespace vmap
