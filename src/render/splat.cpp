// Point splatting on the CPU (include/vmap/render.h): tiles of the supersampled image are
// rendered in parallel, each from the list of discs whose screen bounds touch it.
#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>

#include "vmap/error.h"
#include "vmap/parallel.h"
#include "vmap/render.h"

namespace vmap {
namespace {

Vec3 normalized(Vec3 v) { return v / length(v); }

}  // namespace

void check_camera(const Camera& cam, const std::string& source) {
    if (!is_finite(cam.eye) || !is_finite(cam.target) || !is_finite(cam.up))
        throw Error(fmt::format("{}: eye, target and up must be finite", source));
    if (!(cam.fov_y_deg >= 0.1f && cam.fov_y_deg <= 179.f))
        throw Error(
            fmt::format("{}: fov {} out of range [0.1, 179] degrees", source, cam.fov_y_deg));
    const Vec3 d = cam.target - cam.eye;
    if (!(length(d) > 0)) throw Error(fmt::format("{}: eye and target coincide", source));
    const Vec3 side = cross(normalized(d), cam.up);
    if (!(length(side) > 1e-6f * length(cam.up)))
        throw Error(fmt::format("{}: up is zero or parallel to the view direction", source));
}

namespace {

// The camera's orthonormal frame and focal length for an image of width x height.
struct Frame {
    Vec3 eye, f, r, u;  // forward, right, up
    float fpx = 1;      // focal length in pixels
    float cx = 0, cy = 0;

    Frame(const Camera& cam, int width, int height) {
        check_camera(cam, "camera");
        f = normalized(cam.target - cam.eye);
        r = normalized(cross(f, cam.up));
        u = cross(r, f);
        eye = cam.eye;
        fpx = 0.5f * float(height) / std::tan(float(cam.fov_y_deg * M_PI / 360.0));
        cx = 0.5f * float(width);
        cy = 0.5f * float(height);
    }
};

void check_options(const RenderOptions& o) {
    if (o.width < 1 || o.width > 16384 || o.height < 1 || o.height > 16384)
        throw Error(fmt::format("render: image size {}x{} out of range (1..16384 each)", o.width,
                                o.height));
    if (o.supersample < 1 || o.supersample > 4)
        throw Error(fmt::format("render: supersample {} out of range (1..4)", o.supersample));
    if (!(o.splat_scale > 0 && o.splat_scale <= 100))
        throw Error(fmt::format("render: splat scale {} out of range (0, 100]", o.splat_scale));
    if (!(o.ambient >= 0 && o.ambient <= 1))
        throw Error(fmt::format("render: ambient {} out of range [0, 1]", o.ambient));
    if (!is_finite(o.background)) throw Error("render: background colour must be finite");
}

// A disc ready to rasterise: centre, plane normal, world radius squared, the colour after
// shading, and its screen bounds in supersampled pixels (inclusive).
// A sample a disc covers: sample index in the tile, the disc's index in the tile's list, depth,
// squared distance from the disc's centre.
struct Fragment {
    uint32_t p, k;
    float t, q;
};

struct Disc {
    Vec3 c, n;
    float r2 = 0;
    float band = 0;  // fragments this far behind the nearest one still blend in
    Vec3 color;
    int x0 = 0, y0 = 0, x1 = -1, y1 = -1;
};

// Random sampling leaves small gaps between discs. An output pixel missing samples with at least
// 5 of its 8 neighbours solid (every sample covered) lies in such a gap, not on a silhouette: it
// becomes solid, with the mean of its covered samples, or of those neighbours when it has none.
// Two passes close gaps two pixels wide. Elsewhere, uncovered samples show the background, which
// anti-aliases silhouettes.
void resolve(Image& img, std::vector<Vec3> mean, std::vector<uint8_t> covered, int full,
             Vec3 background) {
    const int W = img.width, H = img.height;
    for (int pass = 0; pass < 2; ++pass) {
        std::vector<Vec3> mean2 = mean;
        std::vector<uint8_t> covered2 = covered;
        parallel_for_range(H, 1, [&](int y0, int y1) {
            for (int y = y0; y != y1; ++y)
                for (int x = 0; x < W; ++x) {
                    const size_t p = size_t(y) * W + x;
                    if (covered[p] == full) continue;
                    int n = 0;
                    Vec3 sum{};
                    for (int dy = -1; dy <= 1; ++dy)
                        for (int dx = -1; dx <= 1; ++dx) {
                            const int qx = x + dx, qy = y + dy;
                            if ((dx | dy) == 0 || qx < 0 || qy < 0 || qx >= W || qy >= H) continue;
                            const size_t q = size_t(qy) * W + qx;
                            if (covered[q] != full) continue;
                            sum += mean[q];
                            ++n;
                        }
                    if (n < 5) continue;
                    if (covered[p] == 0) mean2[p] = sum / float(n);
                    covered2[p] = uint8_t(full);
                }
        });
        mean.swap(mean2);
        covered.swap(covered2);
    }
    parallel_for_range(H, 1, [&](int y0, int y1) {
        for (int y = y0; y != y1; ++y)
            for (int x = 0; x < W; ++x) {
                const size_t p = size_t(y) * W + x;
                const float f = float(covered[p]) / float(full);
                const Vec3 c = mean[p] * f + background * (1 - f);
                if (!img.linear.empty()) img.linear[p] = c;
                uint8_t* px = img.pixel(x, y);
                px[0] = linear_to_srgb8(c.x);
                px[1] = linear_to_srgb8(c.y);
                px[2] = linear_to_srgb8(c.z);
            }
    });
}

}  // namespace

Projection project(const Camera& cam, int width, int height, Vec3 p) {
    const Frame fr(cam, width, height);
    const Vec3 v = p - fr.eye;
    const float z = dot(v, fr.f);
    if (!(z > 0)) return {0, 0, z};
    return {fr.cx + fr.fpx * dot(v, fr.r) / z, fr.cy - fr.fpx * dot(v, fr.u) / z, z};
}

Camera default_camera(const PointSet& points) {
    if (points.size() == 0) throw Error("default camera: the point set is empty");
    Vec3 lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
    for (Vec3 p : points.positions) {
        lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
        hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
    }
    Camera cam;
    float half = 0.5f * std::max(hi.x - lo.x, hi.y - lo.y);
    if (!(half > 0)) half = std::max(0.5f * (hi.z - lo.z), 1e-3f);
    // The near face (z = lo.z) is the largest cross-section seen from -z, so fitting it fits the
    // box; 6% margin. For the Cornell room this puts the eye near the classic (278, 273, -800) mm.
    const float dist = 1.06f * half / std::tan(float(cam.fov_y_deg * M_PI / 360.0));
    const Vec3 mid = (lo + hi) * 0.5f;
    cam.eye = {mid.x, mid.y, lo.z - dist};
    cam.target = {mid.x, mid.y, std::max(hi.z, lo.z + 1e-3f)};
    return cam;
}

namespace {

void check_inputs(const PointSet& points, std::span<const Vec3> colors) {
    const size_t n = points.size();
    if (n == 0) throw Error("render: the point set is empty");
    if (colors.size() != n)
        throw Error(fmt::format("render: {} colours for {} points", colors.size(), n));
    if (points.has_normals() && points.normals.size() != n)
        throw Error(fmt::format("render: {} normals for {} points", points.normals.size(), n));
    if (points.has_radii() && points.radii.size() != n)
        throw Error(fmt::format("render: {} radii for {} points", points.radii.size(), n));
}

constexpr float kNear = 1e-6f;

// The supersampled image: s x s samples per output pixel, W x H in all.
struct Raster {
    Frame fr;
    int s, W, H;
};

// Point i shaded, projected and bounded on screen (x1 < x0 when it shows nowhere).
Disc make_disc(const PointSet& points, Vec3 color, size_t i, const Raster& ra,
               const RenderOptions& opt) {
    const Frame& fr = ra.fr;
    const int s = ra.s, W = ra.W, H = ra.H;
    const float near = kNear;
    Disc d;
    d.c = points.positions[i];
    const Vec3 v = d.c - fr.eye;
    const float z = dot(v, fr.f);
    const float dist = length(v);
    if (!(z > near) || !is_finite(d.c)) return d;  // behind the eye: x1 < x0 skips it
    const Vec3 view = v / dist;
    Vec3 nrm = points.has_normals() ? points.normals[i] : -view;
    if (!(length2(nrm) > 0) || !is_finite(nrm)) nrm = -view;
    d.n = nrm;
    // Radius in world units; without radii, one (output) pixel at this depth.
    float R = points.has_radii() ? points.radii[i] * opt.splat_scale
                                 : opt.splat_scale * float(s) * z / fr.fpx;
    if (!(R > 0) || !std::isfinite(R)) R = float(s) * z / fr.fpx;
    if (z - R <= near) return d;  // straddles the eye plane
    d.r2 = R * R;
    d.band = 2 * R;
    const Vec3 c = color;
    const float shade =
        opt.shade ? opt.ambient + (1 - opt.ambient) * std::fabs(dot(nrm, view)) : 1.f;
    d.color = c * shade;
    // Screen bounds: the disc lies in the sphere of radius R about c, whose silhouette
    // spans, per screen axis, the two planes through the eye tangent to it:
    // (a z -+ R sqrt(a^2 + z^2 - R^2)) / (z^2 - R^2) for view coordinate a (z > R here).
    // A sample centre (x + 0.5) inside [lo, hi] has x in [floor(lo), floor(hi)].
    const float vx = dot(v, fr.r), vy = dot(v, fr.u);
    const float den = z * z - d.r2;
    const float ex = R * std::sqrt(vx * vx + z * z - d.r2);
    const float ey = R * std::sqrt(vy * vy + z * z - d.r2);
    const float lx = fr.cx + fr.fpx * (vx * z - ex) / den;
    const float hx = fr.cx + fr.fpx * (vx * z + ex) / den;
    const float ly = fr.cy - fr.fpx * (vy * z + ey) / den;
    const float hy = fr.cy - fr.fpx * (vy * z - ey) / den;
    if (!(std::isfinite(lx) && std::isfinite(hx) && std::isfinite(ly) && std::isfinite(hy)))
        return d;
    const float fx0 = std::max(std::floor(lx), 0.f), fx1 = std::min(std::floor(hx), float(W - 1));
    const float fy0 = std::max(std::floor(ly), 0.f), fy1 = std::min(std::floor(hy), float(H - 1));
    if (fx0 > fx1 || fy0 > fy1) return d;
    d.x0 = int(fx0);
    d.x1 = int(fx1);
    d.y0 = int(fy0);
    d.y1 = int(fy1);
    return d;
}

// Discs binned into tiles of kTile x kTile output pixels: tile k lists the discs whose screen
// bounds touch it, list[start[k] .. start[k + 1]) (a counting sort, serial: cheap).
struct Tiles {
    static constexpr int kTile = 24;
    int T = 0, tw = 0, th = 0;  // tile edge in supersampled pixels, tiles across and down
    std::vector<uint64_t> start;
    std::vector<uint32_t> list;
};

Tiles bin_discs(const std::vector<Disc>& discs, const Raster& ra) {
    Tiles b;
    const int T = b.T = Tiles::kTile * ra.s;
    const int tw = b.tw = (ra.W + T - 1) / T;
    b.th = (ra.H + T - 1) / T;
    std::vector<uint64_t>& start = b.start;
    start.assign(size_t(tw) * b.th + 1, 0);
    for (const Disc& d : discs)
        if (d.x1 >= d.x0)
            for (int ty = d.y0 / T; ty <= d.y1 / T; ++ty)
                for (int tx = d.x0 / T; tx <= d.x1 / T; ++tx) start[size_t(ty) * tw + tx + 1]++;
    for (size_t k = 1; k < start.size(); ++k) start[k] += start[k - 1];
    // Each disc is listed in every tile it touches: a close camera with large splats can make
    // that far more than the discs. Refuse beyond 1e9 references (4 GB) instead of failing to
    // allocate or wrapping a count.
    if (start.back() > uint64_t(1e9))
        throw Error(
            fmt::format("render: the splats cover {} tile cells (more than 1e9): the "
                        "camera is too close or the splats too large for this size",
                        start.back()));
    b.list.resize(start.back());
    std::vector<uint64_t> fill(start.begin(), start.end() - 1);
    for (uint32_t i = 0; i < discs.size(); ++i) {
        const Disc& d = discs[i];
        if (d.x1 < d.x0) continue;
        for (int ty = d.y0 / T; ty <= d.y1 / T; ++ty)
            for (int tx = d.x0 / T; tx <= d.x1 / T; ++tx) b.list[fill[size_t(ty) * tw + tx]++] = i;
    }
    return b;
}

// One tile's buffers, reused from tile to tile by a thread's chunk.
struct TileScratch {
    std::vector<float> zbuf, wsum;
    std::vector<Vec3> acc;
    std::vector<Fragment> frags;
    explicit TileScratch(int T) : zbuf(size_t(T) * T), wsum(size_t(T) * T), acc(size_t(T) * T) {}
};

// Per output pixel of the image: the mean colour of its covered samples, and how many were.
struct PixelMeans {
    int width = 0;
    std::vector<Vec3> mean;
    std::vector<uint8_t> covered;
};

// Tile `tile`: the nearest depth per sample, then the fragments near it blended, then the
// s x s samples averaged into output pixels. Returns the fragments found.
uint64_t render_tile(int tile, const std::vector<Disc>& discs, const Tiles& tiles, const Raster& ra,
                     const RenderOptions& opt, TileScratch& sc, PixelMeans& px) {
    const Frame& fr = ra.fr;
    const int s = ra.s, W = ra.W, H = ra.H, T = tiles.T, tw = tiles.tw;
    const float near = kNear, inv_f = 1.f / fr.fpx;
    std::vector<float>& zbuf = sc.zbuf;
    std::vector<float>& wsum = sc.wsum;
    std::vector<Vec3>& acc = sc.acc;
    std::vector<Fragment>& frags = sc.frags;
    const uint32_t* const list = tiles.list.data();
    const std::vector<uint64_t>& start = tiles.start;
    const int tx0 = (tile % tw) * T, ty0 = (tile / tw) * T;
    const int tx1 = std::min(tx0 + T, W) - 1, ty1 = std::min(ty0 + T, H) - 1;
    std::fill(zbuf.begin(), zbuf.end(), std::numeric_limits<float>::infinity());
    std::fill(wsum.begin(), wsum.end(), 0.f);
    std::fill(acc.begin(), acc.end(), Vec3{});
    const uint32_t* ids = list + start[tile];
    const uint64_t count = start[tile + 1] - start[tile];
    // The ray of pixel (x, y) is eye + t dir(x, y), t = depth along the view axis;
    // a disc is hit where t = (c - eye).n / dir.n lands within its radius of c.
    auto for_fragments = [&](auto&& emit) {
        for (uint32_t k = 0; k < count; ++k) {
            const Disc& d = discs[ids[k]];
            const int x0 = std::max(d.x0, tx0), x1 = std::min(d.x1, tx1);
            const int y0 = std::max(d.y0, ty0), y1 = std::min(d.y1, ty1);
            const Vec3 ce = d.c - fr.eye;
            const float num = dot(ce, d.n);
            const float fn = dot(fr.f, d.n), rn = dot(fr.r, d.n), un = dot(fr.u, d.n);
            for (int y = y0; y <= y1; ++y) {
                const float py = (fr.cy - (float(y) + 0.5f)) * inv_f;
                for (int x = x0; x <= x1; ++x) {
                    const float px = ((float(x) + 0.5f) - fr.cx) * inv_f;
                    const float den = fn + px * rn + py * un;
                    if (std::fabs(den) < 1e-7f) continue;  // edge-on
                    const float t = num / den;
                    if (!(t > near)) continue;
                    const Vec3 dir = fr.f + fr.r * px + fr.u * py;
                    const Vec3 off = dir * t - ce;
                    const float q = length2(off);
                    if (q >= d.r2) continue;
                    emit(k, size_t(y - ty0) * T + (x - tx0), t, q);
                }
            }
        }
    };
    // Pass 1 records every fragment (so pass 2 need not intersect again) and keeps the
    // nearest depth per sample; pass 2 blends those within the band of it.
    frags.clear();
    for_fragments([&](uint32_t k, size_t p, float t, float q) {
        zbuf[p] = std::min(zbuf[p], t);
        frags.push_back({uint32_t(p), k, t, q});
    });
    const uint64_t found = frags.size();
    for (const Fragment& f : frags) {
        const Disc& d = discs[ids[f.k]];
        if (f.t > zbuf[f.p] + d.band) continue;
        const float w = 1.f - f.q / d.r2 + 1e-4f;  // falls to ~0 at the rim
        acc[f.p] += d.color * w;
        wsum[f.p] += w;
    }
    // Average s x s samples into each output pixel of the tile.
    for (int oy = ty0 / s; oy <= ty1 / s; ++oy)
        for (int ox = tx0 / s; ox <= tx1 / s; ++ox) {
            Vec3 sum{};
            int hit = 0;
            for (int sy = 0; sy < s; ++sy)
                for (int sx = 0; sx < s; ++sx) {
                    const size_t p = size_t(oy * s + sy - ty0) * T + (ox * s + sx - tx0);
                    if (wsum[p] > 0) {
                        sum += acc[p] / wsum[p];
                        ++hit;
                    }
                }
            const size_t o = size_t(oy) * px.width + ox;
            px.covered[o] = uint8_t(hit);
            px.mean[o] = hit > 0 ? sum / float(hit) : opt.background;
        }
    return found;
}

}  // namespace

Image render_points(const PointSet& points, std::span<const Vec3> colors, const Camera& cam,
                    const RenderOptions& opt, RenderStats* stats) {
    check_options(opt);
    check_inputs(points, colors);
    const int s = opt.supersample;
    const Raster ra{Frame(cam, opt.width * s, opt.height * s), s, opt.width * s, opt.height * s};

    // 1. Per point: shade, project, bound on screen.
    const size_t n = points.size();
    std::vector<Disc> discs(n);
    parallel_for_range(n, size_t(4096), [&](size_t i0, size_t i1) {
        for (size_t i = i0; i != i1; ++i) discs[i] = make_disc(points, colors[i], i, ra, opt);
    });
    // 2. Bin the discs into tiles.
    const Tiles tiles = bin_discs(discs, ra);
    // 3. Tiles in parallel, each into its output pixels.
    Image img;
    img.width = opt.width;
    img.height = opt.height;
    img.rgb.assign(size_t(img.width) * img.height * 3, 0);
    if (opt.keep_linear) img.linear.assign(size_t(img.width) * img.height, Vec3{});
    PixelMeans px{img.width, std::vector<Vec3>(size_t(img.width) * img.height),
                  std::vector<uint8_t>(size_t(img.width) * img.height, 0)};
    std::atomic<uint64_t> fragments{0};
    parallel_for_range(tiles.tw * tiles.th, 1, [&](int tile0, int tile1) {
        TileScratch sc(tiles.T);
        for (int tile = tile0; tile != tile1; ++tile)
            fragments += render_tile(tile, discs, tiles, ra, opt, sc, px);
    });
    resolve(img, std::move(px.mean), std::move(px.covered), s * s, opt.background);
    if (stats) {
        for (const Disc& d : discs) stats->discs += d.x1 >= d.x0;
        stats->tile_refs += tiles.list.size();
        stats->fragments += fragments.load();
    }
    return img;
}

}  // namespace vmap
