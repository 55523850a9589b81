// normals_accuracy: how well raw-cloud normals and splat radii are recovered.
//
//   normals_accuracy [--objects-only] [--per-surface] [--points N] [--noise F] [--scan N]
//                    [--scan-seed S]
//                    [--orientation auto|outward|inward] [--write-ply DIR] SCENE.json...
//   normals_accuracy --angles [--noise F] [--floor] [--objects-only] [--points N]
//                    [--fit-neighbours N] [--refits N] [--write-ply DIR] SCENE.json...
//
// Samples each scene (true normals and radii), strips both, re-estimates them as `vmap build`
// does for a raw cloud, and prints one table row per scene: the share of the area (points are
// area-uniform samples) whose estimated normal has the true one's sign, over all points, on the
// objects (not the room), both also without hidden points (inside a solid or covered: below), and
// on thin parts (points with a surface of the opposite normal within three splat radii), and the
// median ratio of estimated to true splat radius on the same sets, beside the old estimate (d_8 /
// sqrt 8 over all neighbours). --objects-only drops the room (a lone object or several).
// --write-ply writes the stripped cloud, for `vmap build`. --per-surface adds on stderr, per
// surface: its points, the share signed right, and where the wrong ones lie (hidden, thin, near
// another surface, elsewhere). --scan N scores a simulated scan from N scanners (scan_scene, as
// `vmap validate --scan`) instead of the scene's samples.
//
// --angles prints instead the unsigned angle between each estimated normal's axis and the true
// one (so orientation is left out: it orients outward unless --orientation is given, which is
// quick), median and 90th percentile in degrees, over all points, the room, the objects and the
// thin parts. --noise F (both modes: the signs of a noisy scan too) moves every point by
// Gaussian noise of F sample spacings per axis (the
// spacing sqrt(area / points) = sqrt(pi) * splat radius), scored against the noise-free true
// normals. --floor adds what a fit cannot beat on faceted meshes: the angle between each point's
// true (face) normal and the plane fit of its 12 nearest in a sample 16 times denser, i.e. the
// smooth surface's normal, where the mesh's faces are smaller than the spacing. With
// --write-ply DIR it writes DIR/SCENE-estimated.ply (and -smooth.ply with --floor): positions
// and those normals, each signed like the true one, to score directions alone with `vmap
// validate SCENE.json --cloud FILE`.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "vmap/error.h"
#include "vmap/io.h"
#include "vmap/normals.h"
#include "vmap/parallel.h"
#include "vmap/scene.h"
#include "vmap/validate.h"

namespace {

using namespace vmap;

struct Options {
    bool objects_only = false;
    bool angles = false, floor = false;
    bool orientation_given = false;
    uint32_t scan = 0;           // --scan N: a simulated scan from N scanners, not the samples
    uint64_t scan_seed = 1;      // --scan-seed S: where they stand
    bool per_surface = false;    // --per-surface: a sign count per mesh on stderr
    double noise = 0;            // Gaussian, in sample spacings
    NormalEstimationParams fit;  // --fit-neighbours, --refits
    uint64_t points = 0;
    Orientation orientation = Orientation::kAuto;
    std::string write_dir;
    std::string mix_dir;   // --mix DIR: clouds that mix estimated and true normals (below)
    bool uniform = false;  // --uniform: uniform samples (a scanner or an area sampler's)
    std::vector<std::string> scenes;
};

bool is_room(const std::string& name) {
    static const std::set<std::string> kRoom{"floor", "back", "ceiling", "left", "right", "light"};
    return kRoom.count(name) > 0;
}

// Which surface each sample came from: the same sampling with the surface index as albedo.
std::vector<uint32_t> surface_of(Scene sc) {
    for (uint32_t s = 0; s < sc.surfaces.size(); ++s) sc.surfaces[s].albedo = {float(s), 0, 0};
    const PointSet ps = sample_scene(sc);
    std::vector<uint32_t> out(ps.size());
    for (size_t i = 0; i < ps.size(); ++i) out[i] = uint32_t(ps.colors[i].x);
    return out;
}

// Points with a sample j within three splat radii (among the 48 nearest) for which
// `match(i, j)` holds.
template <class Match>
std::vector<uint8_t> with_sample_near(const PointSet& truth, Match match) {
    const NearestPoints tree(truth.positions);
    std::vector<uint8_t> out(truth.size(), 0);
    parallel_for(size_t(0), truth.size(), [&](size_t i) {
        const Vec3 p = truth.positions[i];
        const float r = 3 * truth.radii[i];
        uint32_t idx[48];
        float d2[48];
        const size_t got = tree.find(p, 48, idx, d2);
        for (size_t j = 0; j < got; ++j) out[i] |= d2[j] <= r * r && match(i, size_t(idx[j]));
    });
    return out;
}

// Points with a sample of the same surface with (nearly) opposite true normal within three
// splat radii: both faces of a plate or shell thinner than that.
std::vector<uint8_t> thin_parts(const PointSet& truth, const std::vector<uint32_t>& surf) {
    return with_sample_near(truth, [&](size_t i, size_t j) {
        return surf[j] == surf[i] && dot(truth.normals[j], truth.normals[i]) < -0.5f;
    });
}

// Points with a sample of another surface within three splat radii: near a wall, the floor
// or another object.
std::vector<uint8_t> near_other(const PointSet& truth, const std::vector<uint32_t>& surf) {
    return with_sample_near(truth, [&](size_t i, size_t j) { return surf[j] != surf[i]; });
}

// Points hidden in any case: inside a solid (the first sample disc along the true normal, among
// the 64 nearest, shows its back) or covered (that disc lies closer than the point's splat
// radius, as an object's flat base covers the floor it stands on). Their sign is arbitrary, so
// the table also scores the area without them.
std::vector<uint8_t> buried(const PointSet& truth) {
    const NearestPoints tree(truth.positions);
    std::vector<uint8_t> out(truth.size(), 0);
    parallel_for(size_t(0), truth.size(), [&](size_t i) {
        const Vec3 p = truth.positions[i], d = truth.normals[i];
        uint32_t idx[64];
        float d2[64];
        const size_t got = tree.find(p, 64, idx, d2);
        float best = 1e30f;
        bool back = false;
        for (size_t j = 0; j < got; ++j) {
            const uint32_t o = idx[j];
            const Vec3 n = truth.normals[o];
            const float den = dot(n, d);
            if (o == i || std::fabs(den) < 1e-6f) continue;
            const float t = dot(n, truth.positions[o] - p) / den;
            if (!(t > 1e-5f && t < best)) continue;
            const Vec3 h = p + d * t - truth.positions[o];
            if (length2(h) > truth.radii[o] * truth.radii[o]) continue;
            best = t;
            back = den > 0;
        }
        out[i] = back || best < truth.radii[i];
    });
    return out;
}

// d_8 / sqrt(8) over all neighbours: the radii raw clouds got before estimate_radii.
std::vector<float> old_radii(const std::vector<Vec3>& pts) {
    const NearestPoints tree(pts);
    std::vector<float> r(pts.size());
    parallel_for(size_t(0), pts.size(), [&](size_t i) {
        uint32_t idx[9];
        float d2[9];
        const size_t got = tree.find(pts[i], 9, idx, d2);
        r[i] = got > 1 ? std::sqrt(d2[got - 1]) / std::sqrt(float(got - 1)) : 0.f;
    });
    return r;
}

struct Tally {
    uint64_t n = 0, right = 0;
    std::vector<float> ratio, old_ratio;

    void add(bool ok, float r, float old) {
        ++n;
        right += ok;
        ratio.push_back(r);
        old_ratio.push_back(old);
    }
    std::string signs() const {
        return n ? fmt::format("{:.2f}%", 100.0 * double(right) / double(n)) : "-";
    }
    static std::string median(std::vector<float> v) {
        if (v.empty()) return "-";
        std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
        return fmt::format("{:.3f}", v[v.size() / 2]);
    }
};

// Degrees between the axes of a and b (unit vectors; signs ignored).
float axis_angle(Vec3 a, Vec3 b) {
    return float(std::acos(std::min(1.0, double(std::fabs(dot(a, b))))) * 180.0 / M_PI);
}

// "p50 / p90" of v in degrees, or "-".
std::string percentiles(std::vector<float> v) {
    if (v.empty()) return "-";
    auto at = [&](double q) {
        const size_t k = std::min(v.size() - 1, size_t(q * double(v.size())));
        std::nth_element(v.begin(), v.begin() + k, v.end());
        return v[k];
    };
    const float p50 = at(0.5), p90 = at(0.9);
    return fmt::format("{:.1f} / {:.1f}", p50, p90);
}

// Per point, the estimated normal (12 neighbours) of the nearest sample of a 16 times denser
// sample of the scene: the smooth surface's normal at the point, for --floor.
std::vector<Vec3> dense_fit_normals(Scene sc, const PointSet& truth) {
    sc.points = 16 * truth.size();
    sc.seed += 1000;
    sc.pattern = SamplePattern::kUniform;
    PointSet dense;
    dense.positions = sample_scene(sc).positions;
    NormalEstimationParams np;
    np.orientation = Orientation::kOutward;
    estimate_normals(dense, np, "dense sample");
    const NearestPoints tree(dense.positions);
    std::vector<Vec3> out(truth.size());
    parallel_for(size_t(0), truth.size(), [&](size_t i) {
        const Vec3 p = truth.positions[i];
        uint32_t idx = 0;
        float d2 = 0;
        tree.find(p, 1, &idx, &d2);
        out[i] = dense.normals[idx];
    });
    return out;
}

// Gaussian noise of `f` sample spacings (sqrt(pi) * the true splat radius) per axis, seeded.
void add_noise(PointSet& ps, const PointSet& truth, double f) {
    add_surface_noise(ps.positions, truth.radii, f, 12345);
}

// For `vmap validate --cloud`: the estimated normals (and with --floor the smooth surface's),
// each signed to agree with the true normal, so that the fit's directions are scored alone.
void write_signed(const std::string& stem, const PointSet& est, const std::vector<Vec3>& smooth,
                  const PointSet& truth) {
    PointSet out;
    out.positions = est.positions;
    auto signed_like_truth = [&](const std::vector<Vec3>& n) {
        out.normals.resize(n.size());
        for (size_t i = 0; i < n.size(); ++i)
            out.normals[i] = dot(n[i], truth.normals[i]) < 0 ? -n[i] : n[i];
    };
    signed_like_truth(est.normals);
    write_ply(stem + "-estimated.ply", out);
    if (smooth.empty()) return;
    signed_like_truth(smooth);
    write_ply(stem + "-smooth.ply", out);
}

// For `vmap validate --cloud`, to tell where a bare cloud's misses come from: the estimated
// normals as `vmap build` orients them (-est), the same signed like the truth (-estsign), the
// true normals on the objects and the estimated ones on the room (-objtrue), the reverse
// (-roomtrue), the true normals everywhere (-true), and the signed estimates with the truth
// wherever they are more than 30 degrees off (-fixbad). Positions only: radii estimated.
void write_mixed(const std::string& stem, const Scene& sc, const PointSet& truth,
                 const PointSet& est, const std::vector<uint32_t>& surf) {
    auto write = [&](const char* tag, auto pick) {
        PointSet out;
        out.positions = truth.positions;
        out.normals.resize(truth.size());
        for (size_t i = 0; i < truth.size(); ++i) {
            const bool model = !is_room(sc.surfaces[surf[i]].name);
            out.normals[i] = pick(i, model);
        }
        write_ply(stem + tag, out);
    };
    const auto& t = truth.normals;
    const auto& e = est.normals;
    auto signed_est = [&](size_t i) { return dot(e[i], t[i]) < 0 ? -e[i] : e[i]; };
    write("-est.ply", [&](size_t i, bool) { return e[i]; });
    write("-estsign.ply", [&](size_t i, bool) { return signed_est(i); });
    write("-objtrue.ply", [&](size_t i, bool m) { return m ? t[i] : e[i]; });
    write("-roomtrue.ply", [&](size_t i, bool m) { return m ? e[i] : t[i]; });
    write("-true.ply", [&](size_t i, bool) { return t[i]; });
    // Signed like the truth, and the truth where the estimate's axis is more than 30 degrees
    // off (what fixing the worst directions alone could gain).
    write("-fixbad.ply", [&](size_t i, bool) {
        const Vec3 v = signed_est(i);
        return dot(v, t[i]) < 0.866f * length(v) * length(t[i]) ? t[i] : v;
    });
}

// Per surface (mesh or wall): points, signs right, and where the wrong ones lie: hidden in any
// case (buried), on a thin part, near another surface (not thin), or elsewhere.
void print_per_surface(const Scene& sc, const PointSet& truth, const PointSet& est,
                       const std::vector<uint32_t>& surf, const std::vector<uint8_t>& inside,
                       const std::vector<uint8_t>& thin) {
    const std::vector<uint8_t> near = near_other(truth, surf);
    const size_t m = sc.surfaces.size();
    std::vector<Tally> all(m);
    std::vector<std::array<uint64_t, 4>> wrong(m, {0, 0, 0, 0});
    for (size_t i = 0; i < truth.size(); ++i) {
        const bool ok = dot(est.normals[i], truth.normals[i]) > 0;
        all[surf[i]].add(ok, 0, 0);
        if (!ok) ++wrong[surf[i]][inside[i] ? 0 : thin[i] ? 1 : near[i] ? 2 : 3];
    }
    for (size_t s = 0; s < m; ++s)
        fmt::print(stderr,
                   "  {} / {}: {} points, {} right; wrong: {} hidden, {} thin, {} near another "
                   "surface, {} elsewhere\n",
                   sc.name, sc.surfaces[s].name, all[s].n, all[s].signs(), wrong[s][0], wrong[s][1],
                   wrong[s][2], wrong[s][3]);
}

void run_angles(const std::string& path, Scene sc, const PointSet& truth,
                const std::vector<uint32_t>& surf, const Options& o) {
    const std::vector<uint8_t> thin = thin_parts(truth, surf);
    PointSet raw;
    raw.positions = truth.positions;
    if (o.noise > 0) add_noise(raw, truth, o.noise);
    NormalEstimationParams np = o.fit;
    np.orientation = o.orientation_given ? o.orientation : Orientation::kOutward;
    const auto t0 = std::chrono::steady_clock::now();
    estimate_normals(raw, np, path.c_str());
    const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::vector<float> all, room, obj, thn, floor_obj;
    const std::vector<Vec3> smooth = o.floor ? dense_fit_normals(sc, truth) : std::vector<Vec3>{};
    for (size_t i = 0; i < truth.size(); ++i) {
        const float a = axis_angle(raw.normals[i], truth.normals[i]);
        const bool model = !is_room(sc.surfaces[surf[i]].name);
        all.push_back(a);
        (model ? obj : room).push_back(a);
        if (thin[i]) thn.push_back(a);
        if (o.floor && model) floor_obj.push_back(axis_angle(smooth[i], truth.normals[i]));
    }
    if (!o.write_dir.empty()) write_signed(o.write_dir + "/" + sc.name, raw, smooth, truth);
    fmt::print("| {} | {} | {:.2f} | {} | {} | {} | {} | {} | {:.2f} s |\n",
               sc.name + (o.objects_only ? " (objects only)" : ""), truth.size(), o.noise,
               percentiles(all), percentiles(room), percentiles(obj),
               percentiles(thn) + fmt::format(" ({})", thn.size()), percentiles(floor_obj), sec);
}

void run_scene(const std::string& path, const Options& o) {
    Scene sc = load_scene(path);
    if (o.objects_only)
        std::erase_if(sc.surfaces, [](const SceneSurface& s) { return is_room(s.name); });
    if (o.points) sc.points = o.points;
    if (o.uniform) sc.pattern = SamplePattern::kUniform;
    PointSet truth;
    std::vector<uint32_t> surf;
    if (o.scan) {  // a simulated scan (vmap validate --scan): its points and true sides
        const ExactVisibility exact(sc.surfaces, path);
        ScanPoints scan = scan_scene(sc, exact, o.scan, sc.points, o.scan_seed, path);
        for (const Vec3& s : scan.scanners)
            fmt::print(stderr, "{}: scanner at ({:.3f}, {:.3f}, {:.3f})\n", sc.name, s.x, s.y, s.z);
        truth = std::move(scan.points);
        surf = std::move(scan.surface);
    } else {
        truth = sample_scene(sc);
        surf = surface_of(sc);
    }
    if (o.angles) return run_angles(path, sc, truth, surf, o);
    const std::vector<uint8_t> thin = thin_parts(truth, surf);
    const std::vector<uint8_t> inside = buried(truth);

    PointSet raw;
    raw.positions = truth.positions;
    if (o.noise > 0) add_noise(raw, truth, o.noise);  // a scan's noise (signs still scored)
    if (!o.write_dir.empty())
        write_ply(o.write_dir + "/" + sc.name + (o.objects_only ? "-objects" : "") + ".ply", raw);
    const auto t0 = std::chrono::steady_clock::now();
    NormalEstimationParams np;
    np.orientation = o.orientation;
    OrientationReport rep;
    estimate_normals(raw, np, path.c_str(), &rep);
    const auto t1 = std::chrono::steady_clock::now();
    fmt::print(
        stderr,
        "{}: close-neighbour share {:.4f} (true normals), {:.4f} (estimated); floor {:.3f}\n",
        sc.name, close_neighbour_share(truth), close_neighbour_share(raw), cloud_delta_floor(raw));
    if (!o.mix_dir.empty()) write_mixed(o.mix_dir + "/" + sc.name, sc, truth, raw, surf);
    estimate_radii(raw);
    const auto t2 = std::chrono::steady_clock::now();
    const std::vector<float> old = old_radii(raw.positions);

    Tally all, obj, thn, exposed, exposed_obj;
    for (size_t i = 0; i < truth.size(); ++i) {
        const bool ok = dot(raw.normals[i], truth.normals[i]) > 0;
        const float r = raw.radii[i] / truth.radii[i], ro = old[i] / truth.radii[i];
        all.add(ok, r, ro);
        if (!is_room(sc.surfaces[surf[i]].name)) obj.add(ok, r, ro);
        if (thin[i]) thn.add(ok, r, ro);
        if (!inside[i]) exposed.add(ok, r, ro);
        if (!inside[i] && !is_room(sc.surfaces[surf[i]].name)) exposed_obj.add(ok, r, ro);
    }
    const double sn = std::chrono::duration<double>(t1 - t0).count();
    const double sr = std::chrono::duration<double>(t2 - t1).count();
    fmt::print(
        "| {} | {} | {} | {} | {} | {} | {} | {} / {} | {} / {} | {} / {} | {:.2f} s + {:.2f} s "
        "|\n",
        sc.name + (o.objects_only ? " (objects only)" : ""), truth.size(), all.signs(),
        exposed.signs(), obj.signs(), exposed_obj.signs(),
        thn.signs() + fmt::format(" ({})", thn.n), Tally::median(all.ratio),
        Tally::median(all.old_ratio), Tally::median(obj.ratio), Tally::median(obj.old_ratio),
        Tally::median(thn.ratio), Tally::median(thn.old_ratio), sn, sr);
    fmt::print(stderr,
               "{}: {}; {} by space, {} by view, {} by rays, {} by shape, {} by neighbours\n",
               sc.name, rep.method, rep.by_space, rep.by_view, rep.by_rays, rep.by_shape,
               rep.by_neighbours);
    if (o.per_surface) print_per_surface(sc, truth, raw, surf, inside, thin);
}

int usage() {
    fmt::print(stderr,
               "usage: normals_accuracy [--objects-only] [--per-surface] [--points N] [--scan N] "
               "[--orientation auto|outward|inward] [--write-ply DIR] SCENE.json...\n"
               "       normals_accuracy --angles [--noise F] [--floor] [--objects-only] "
               "[--points N] [--fit-neighbours N] [--refits N] [--write-ply DIR] SCENE.json...\n");
    return 2;
}

}  // namespace

int main(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        const bool more = i + 1 < argc;
        if (a == "--objects-only") {
            o.objects_only = true;
        } else if (a == "--per-surface") {
            o.per_surface = true;
        } else if (a == "--angles") {
            o.angles = true;
        } else if (a == "--floor") {
            o.floor = true;
        } else if (a == "--fit-neighbours" && more) {
            o.fit.fit_neighbours = std::stoull(argv[++i]);
        } else if (a == "--refits" && more) {
            o.fit.refits = std::stoi(argv[++i]);
        } else if (a == "--noise" && more) {
            o.noise = std::stod(argv[++i]);
        } else if (a == "--points" && more) {
            o.points = std::stoull(argv[++i]);
        } else if (a == "--mix" && more) {
            o.mix_dir = argv[++i];
        } else if (a == "--scan" && more) {
            o.scan = uint32_t(std::stoul(argv[++i]));
        } else if (a == "--scan-seed" && more) {
            o.scan_seed = std::stoull(argv[++i]);
        } else if (a == "--uniform") {
            o.uniform = true;
        } else if (a == "--write-ply" && more) {
            o.write_dir = argv[++i];
        } else if (a == "--orientation" && more) {
            const std::string v = argv[++i];
            o.orientation_given = true;
            if (v == "auto")
                o.orientation = Orientation::kAuto;
            else if (v == "outward")
                o.orientation = Orientation::kOutward;
            else if (v == "inward")
                o.orientation = Orientation::kInward;
            else
                return usage();
        } else if (!a.empty() && a[0] == '-') {
            return usage();
        } else {
            o.scenes.push_back(a);
        }
    }
    if (o.scenes.empty()) return usage();
    if (o.angles)
        fmt::print(
            "| cloud | points | noise (spacings) | angle to the true normal, p50 / p90 (deg): all "
            "| room | objects | thin parts (points) | floor on objects | time: normals |\n"
            "|---|---|---|---|---|---|---|---|---|\n");
    else
        fmt::print(
            "| cloud | points | signs right (area) | not hidden | on objects | objects, not hidden "
            "| on thin parts (points) | radius ratio, new / old | on objects | on thin parts | "
            "time: normals + radii |\n"
            "|---|---|---|---|---|---|---|---|---|---|---|\n");
    try {
        for (const std::string& s : o.scenes) run_scene(s, o);
    } catch (const vmap::Error& e) {
        fmt::print(stderr, "normals_accuracy: error: {}\n", e.what());
        return 1;
    }
    return 0;
}
