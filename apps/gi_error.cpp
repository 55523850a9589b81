// `vmap gi SCENE.json --reference`: the GI against a path-traced reference (include/vmap/
// gi_reference.h) at seeded sample points, split by method (the default V-map GI, the
// hierarchical solution without the final gather, the brute-force gather over the same V-map),
// by bounce count and by point set (all non-emitting points, model points).
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <set>

#include "apps/commands.h"
#include "apps/gi_cmd.h"
#include "vmap/error.h"
#include "vmap/gi.h"
#include "vmap/gi_reference.h"
#include "vmap/parallel.h"
#include "vmap/render.h"
#include "vmap/scene.h"
#include "vmap/validate.h"
#include "vmap/vmap.h"

namespace vmap::cli {
namespace {

using Clock = std::chrono::steady_clock;

uint64_t splitmix(uint64_t& s) {
    uint64_t x = (s += 0x9e3779b97f4a7c15ULL);
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    return x ^ (x >> 31);
}

// n of the candidates, seeded (partial Fisher-Yates), sorted; all of them when there are fewer.
std::vector<uint32_t> pick(std::vector<uint32_t> c, size_t n, uint64_t seed) {
    uint64_t s = seed;
    n = std::min(n, c.size());
    for (size_t k = 0; k < n; ++k) std::swap(c[k], c[k + splitmix(s) % (c.size() - k)]);
    c.resize(n);
    std::sort(c.begin(), c.end());
    return c;
}

bool is_room_surface(const std::string& name) {
    static const std::set<std::string> room{"floor", "ceiling", "back", "left", "right", "light"};
    return room.count(name) > 0;
}

struct Sets {
    std::vector<uint32_t> points;  // octree positions: the "all" set, then the model set
    size_t num_all = 0;
};

Sets choose_points(const Scene& sc, const VisibilityMap& vm, const std::vector<uint32_t>& surf,
                   size_t n, uint64_t seed) {
    std::vector<uint32_t> lit, model;
    for (uint32_t k = 0; k < vm.points().size(); ++k) {
        const SceneSurface& s = sc.surfaces[surf[vm.order()[k]]];
        if (s.emission.x > 0 || s.emission.y > 0 || s.emission.z > 0) continue;
        lit.push_back(k);
        if (!is_room_surface(s.name)) model.push_back(k);
    }
    Sets out;
    out.points = pick(lit, n, seed);
    out.num_all = out.points.size();
    const std::vector<uint32_t> m = pick(model, n, seed + 1);
    out.points.insert(out.points.end(), m.begin(), m.end());
    return out;
}

struct ErrorStats {
    double rms = 0, p95 = 0, ratio = 0;
};

// Relative RMS, 95th percentile of |h - r| / |r| and sum(h) / sum(r) (all channels) over
// entries [b, e).
ErrorStats error_stats(const std::vector<Vec3>& h, const std::vector<Vec3>& r, size_t b, size_t e) {
    double num = 0, den = 0, sh = 0, sr = 0;
    std::vector<double> rel;
    for (size_t i = b; i < e; ++i) {
        const Vec3 d = h[i] - r[i];
        const double dd = dot(d, d), rr = dot(r[i], r[i]);
        num += dd, den += rr;
        sh += double(h[i].x) + h[i].y + h[i].z, sr += double(r[i].x) + r[i].y + r[i].z;
        rel.push_back(rr > 0 ? std::sqrt(dd / rr) : (dd > 0 ? 1e9 : 0));  // 1e9: infinite
    }
    ErrorStats s;
    if (rel.empty()) return s;
    s.rms = den > 0 ? std::sqrt(num / den) : 0;
    s.ratio = sr > 0 ? sh / sr : 0;
    const size_t k = std::min(rel.size() - 1, size_t(0.95 * double(rel.size())));
    std::nth_element(rel.begin(), rel.begin() + k, rel.end());
    s.p95 = rel[k];
    return s;
}

// The reference's own noise: sqrt(sum |se|^2 / sum |r|^2) over [b, e).
double noise(const std::vector<Vec3>& se, const std::vector<Vec3>& r, size_t b, size_t e) {
    double num = 0, den = 0;
    for (size_t i = b; i < e; ++i) num += dot(se[i], se[i]), den += dot(r[i], r[i]);
    return den > 0 ? std::sqrt(num / den) : 0;
}

std::vector<Vec3> subset(const std::vector<Vec3>& B, const std::vector<uint32_t>& idx) {
    std::vector<Vec3> out(idx.size());
    for (size_t k = 0; k < idx.size(); ++k) out[k] = B[idx[k]];
    return out;
}

// One method's radiosity at the sample points: per bounce count 1..K, then converged.
struct Method {
    std::string name;
    std::vector<std::vector<Vec3>> at;
};

struct Solved {
    std::vector<Method> methods;
    std::vector<Vec3> all_points;  // the default GI at every point, converged (for -o)
    int converged_bounces = 0;
    double seconds_setup = 0, seconds_bounces = 0, seconds_gather = 0;
};

// The default V-map GI (k - 1 hierarchical bounces, then the final gather) and the hierarchical
// solution alone, at bounce counts 1..K and converged.
Solved solve_vmap(const VisibilityMap& vm, const GiOptions& o, const std::vector<uint32_t>& idx,
                  int K, bool all_points) {
    Solved s;
    RadiositySolver solver(vm, o.gi);
    s.seconds_setup = solver.stats().seconds_setup;
    Method fg{"vmap gi (default)", {}}, hier{"hierarchical only", {}};
    auto gather = [&] {
        const auto t0 = Clock::now();
        fg.at.push_back(solver.final_gather(o.gather_theta, idx));
        s.seconds_gather += seconds_since(t0);
    };
    gather();  // 1 bounce: the final gather of B = E
    double previous = 0;
    for (int b = 1; b <= o.max_bounces; ++b) {
        const auto t0 = Clock::now();
        solver.bounce();
        s.seconds_bounces += seconds_since(t0);
        const std::vector<Vec3> B = solver.radiosity();
        if (b <= K) hier.at.push_back(subset(B, idx));
        if (b < K) gather();
        const Vec3 p = total_power(vm, B);
        const double now = double(p.x) + p.y + p.z;
        s.converged_bounces = b;
        if (b >= K && now > 0 && std::abs(now - previous) <= o.tolerance * now) break;
        previous = now;
    }
    hier.at.push_back(subset(solver.radiosity(), idx));
    gather();
    if (all_points) s.all_points = solver.final_gather(o.gather_theta);
    s.methods = {fg, hier};
    return s;
}

Method solve_brute(const VisibilityMap& vm, const std::vector<uint32_t>& idx, int K, int total) {
    std::vector<std::vector<Vec3>> per;
    brute_force_radiosity(vm, std::max(K, total), &per);
    Method m{"brute-force gather", {}};
    for (int k = 0; k < K; ++k) m.at.push_back(subset(per[k], idx));
    m.at.push_back(subset(per.back(), idx));
    return m;
}

// Direct light at the sample points from the light's points, with exact visibility between
// the points (Embree over the scene's triangles, rays offset by 1e-4 of the largest extent, as
// `vmap validate`'s truth) in place of the V-map's: against the 1-bounce reference it measures
// what the points and the form factor cost; against the V-map's direct light, what the V-map's
// visibility costs.
Method direct_exact(const Scene& sc, const VisibilityMap& vm, const std::vector<uint32_t>& idx,
                    const std::string& source) {
    const ExactVisibility ex(sc.surfaces, source);
    const PointSet& ps = vm.points();
    std::vector<uint32_t> lights;
    Vec3 lo = ps.positions[0], hi = lo;
    for (uint32_t k = 0; k < ps.size(); ++k) {
        const Vec3 e = ps.emission.empty() ? Vec3{} : ps.emission[k];
        if (e.x > 0 || e.y > 0 || e.z > 0) lights.push_back(k);
        const Vec3 q = ps.positions[k];
        lo = Vec3{std::min(lo.x, q.x), std::min(lo.y, q.y), std::min(lo.z, q.z)};
        hi = Vec3{std::max(hi.x, q.x), std::max(hi.y, q.y), std::max(hi.z, q.z)};
    }
    const Vec3 ext = hi - lo;
    const float offset = 1e-4f * std::max({ext.x, ext.y, ext.z});
    auto disc = [&](uint32_t k) { return 3.14159265f * ps.radii[k] * ps.radii[k]; };
    std::vector<Vec3> out(idx.size());
    parallel_for(size_t(0), idx.size(), [&](size_t n) {
        const uint32_t i = idx[n];
        const Vec3 x = ps.positions[i], nx = ps.normals[i];
        Vec3 h{0, 0, 0};
        for (uint32_t j : lights) {
            const float k = gi_kernel(x, nx, disc(i), ps.positions[j], ps.normals[j], disc(j));
            if (k > 0 && ex.visible(x, nx, ps.positions[j], ps.normals[j], offset))
                h = h + ps.emission[j] * (k * disc(j));
        }
        const Vec3 E = ps.emission.empty() ? Vec3{} : ps.emission[i];
        const Vec3 rho = ps.has_colors() ? ps.colors[i] : Vec3{0.8f, 0.8f, 0.8f};
        out[n] = Vec3{E.x + rho.x * h.x, E.y + rho.y * h.y, E.z + rho.z * h.z};
    });
    return Method{"exact visibility (direct only)", {out}};
}

void print_direct_split(const Method& exact, const Method& vmap_gi, const ReferenceResult& ref,
                        const Sets& sets) {
    const size_t nA = sets.num_all, nT = sets.points.size();
    auto row = [&](const char* what, const std::vector<Vec3>& h, const std::vector<Vec3>& r) {
        const ErrorStats a = error_stats(h, r, 0, nA), b = error_stats(h, r, nA, nT);
        fmt::print("| {} | {:.4f} | {:.4f} | {:.4f} | {:.4f} |\n", what, a.rms, a.ratio, b.rms,
                   b.ratio);
    };
    fmt::print(
        "\nDirect light (1 bounce) split:\n| compared | all: rel. RMS | all: ratio | model: rel. "
        "RMS | model: ratio |\n|---|---|---|---|---|\n");
    row("exact visibility between the points vs reference", exact.at[0], ref.value[0]);
    row("V-map visibility vs exact visibility (same points)", vmap_gi.at[0], exact.at[0]);
    row("V-map (vmap gi) vs reference", vmap_gi.at[0], ref.value[0]);
}

// A percentile of relative errors; points the reference leaves dark but the GI lights count as
// an infinite error.
std::string p95(double v) { return v >= 1e9 ? "inf" : fmt::format("{:.4f}", v); }

void print_table(const std::vector<Method>& methods, const ReferenceResult& ref, const Sets& sets,
                 int K, int converged) {
    const size_t nA = sets.num_all, nT = sets.points.size();
    fmt::print(
        "\n| method | bounces | all: rel. RMS | all: p95 | all: mean ratio | model: rel. RMS | "
        "model: p95 | model: mean ratio |\n|---|---|---|---|---|---|---|---|\n");
    auto label = [&](int k) {
        return k < K ? fmt::format("{}", k + 1) : fmt::format("converged ({})", converged);
    };
    for (int k = 0; k <= K; ++k) {
        const std::vector<Vec3>& r = ref.value[k];
        const std::string model_noise =
            nT > nA ? fmt::format("{:.4f}", noise(ref.std_error[k], r, nA, nT)) : "-";
        fmt::print("| reference noise | {} | {:.4f} | | | {} | | |\n", label(k),
                   noise(ref.std_error[k], r, 0, nA), model_noise);
        for (const Method& m : methods) {
            const ErrorStats a = error_stats(m.at[k], r, 0, nA),
                             b = error_stats(m.at[k], r, nA, nT);
            const std::string model =
                nT > nA ? fmt::format("{:.4f} | {} | {:.4f}", b.rms, p95(b.p95), b.ratio)
                        : "- | - | -";
            fmt::print("| {} | {} | {:.4f} | {} | {:.4f} | {} |\n", m.name, label(k), a.rms,
                       p95(a.p95), a.ratio, model);
        }
    }
}

void write_csv(const std::string& path, const Scene& sc, const VisibilityMap& vm,
               const std::vector<uint32_t>& surf, const Sets& sets, const ReferenceResult& ref,
               const std::vector<Method>& methods, int K) {
    const std::string tmp = path + ".tmp";
    std::FILE* f = std::fopen(tmp.c_str(), "w");
    if (!f) throw Error(fmt::format("{}: --ref-out: cannot write", path));
    fmt::print(f, "set,input_index,surface,x,y,z");
    for (int k = 0; k <= K; ++k) {
        const std::string b = k < K ? fmt::format("b{}", k + 1) : "conv";
        fmt::print(f, ",ref_{0}_r,ref_{0}_g,ref_{0}_b,se_{0}_r,se_{0}_g,se_{0}_b", b);
        for (size_t m = 0; m < methods.size(); ++m)
            fmt::print(f, ",m{1}_{0}_r,m{1}_{0}_g,m{1}_{0}_b", b, m);
    }
    fmt::print(f, "\n");
    for (size_t i = 0; i < sets.points.size(); ++i) {
        const uint32_t k = sets.points[i], in = vm.order()[k];
        const Vec3 p = vm.points().positions[k];
        fmt::print(f, "{},{},{},{},{},{}", i < sets.num_all ? "all" : "model", in,
                   sc.surfaces[surf[in]].name, p.x, p.y, p.z);
        for (int b = 0; b <= K; ++b) {
            const Vec3 r = ref.value[b][i], e = ref.std_error[b][i];
            fmt::print(f, ",{},{},{},{},{},{}", r.x, r.y, r.z, e.x, e.y, e.z);
            for (const Method& m : methods)
                fmt::print(f, ",{},{},{}", m.at[b][i].x, m.at[b][i].y, m.at[b][i].z);
        }
        fmt::print(f, "\n");
    }
    const bool ok = std::fclose(f) == 0;
    if (!ok) throw Error(fmt::format("{}: --ref-out: write failed", path));
    std::filesystem::rename(tmp, path);
}

// The scene, its points' surfaces and the V-map: built from the scene, or a saved V-map of it
// (--scene; its points must be the scene's samples, checked point by point).
VisibilityMap reference_vmap(const GiOptions& o, Scene& sc, std::vector<uint32_t>& surf) {
    const bool saved = !has_extension(o.in.path, ".json");
    if (saved && o.cam.scene.empty())
        throw Error(
            fmt::format("{}: --reference needs the scene file (.json, or --scene for a "
                        ".vmap): the reference traces the scene's triangles",
                        o.in.path));
    sc = load_scene(saved ? o.cam.scene : o.in.path);
    if (o.in.points) sc.points = *o.in.points;
    if (o.in.seed) sc.seed = *o.in.seed;
    if (o.in.pattern) sc.pattern = *o.in.pattern;
    const auto t0 = Clock::now();
    PointSet ps = sample_scene(sc, &surf);
    if (saved) {
        if (o.K != kGiVmapK || o.eps != kGiVmapEps || o.end_window != kGiVmapEndWindow ||
            o.core != kGiVmapCore || o.in.delta_floor)
            throw Error(fmt::format(
                "{}: -K/--eps/--end-window/--core/--delta-floor apply to a V-map built from a "
                "scene file",
                o.in.path));
        VisibilityMap vm = load_vmap(o.in.path);
        bool same = vm.points().size() == ps.size();
        for (size_t k = 0; same && k < vm.points().size(); ++k)
            same = vm.points().positions[k] == ps.positions[vm.order()[k]];
        if (!same)
            throw Error(fmt::format("{}: points: not the samples of {} (points {}, seed {})",
                                    o.in.path, o.cam.scene, sc.points, sc.seed));
        fmt::print(
            "scene:      {} ({}): {} points, V-map {} (K {}, eps {}, {} links) loaded in {:.2f} "
            "s\n",
            sc.name, o.cam.scene, vm.points().size(), o.in.path, vm.visibility_params().K,
            vm.visibility_params().eps, vm.num_links(), seconds_since(t0));
        return vm;
    }
    const BuildParams bp = gi_build_params(scene_octree(sc), o);
    VisibilityMap vm = build_vmap(std::move(ps), bp, nullptr, o.in.path);
    fmt::print(
        "scene:      {} ({}): {} points, V-map (K {}, eps {}, end window {}, delta floor {}) {} "
        "links in {:.2f} s\n",
        sc.name, o.in.path, vm.points().size(), o.K, o.eps, o.end_window, bp.octree.delta_floor,
        vm.num_links(), seconds_since(t0));
    return vm;
}

// Error heat map colour for a relative error e: black (0) through red (25%) to yellow (50%
// and more).
Vec3 heat(float e) {
    const float u = std::clamp(e / 0.5f, 0.0f, 1.0f);
    return u < 0.5f ? Vec3{2 * u, 0, 0} : Vec3{1, 2 * u - 1, 0};
}

// -o with --reference: reference | vmap gi | error heat map at every point (the reference with
// --ref-picture-samples paths per point), one camera and one exposure.
void side_by_side_picture(const Scene& sc, const VisibilityMap& vm,
                          const std::vector<uint32_t>& surf, const std::vector<Vec3>& gi,
                          GiOptions& o) {
    std::vector<ReferencePoint> at(vm.points().size());
    for (size_t k = 0; k < at.size(); ++k) {
        const SceneSurface& s = sc.surfaces[surf[vm.order()[k]]];
        at[k] = {vm.points().positions[k], vm.points().normals[k], s.albedo, s.emission};
    }
    ReferenceParams rp = o.ref;
    rp.samples = o.ref_picture_samples;
    rp.bounces = 1;
    rp.progress = stderr_progress();
    const ReferenceResult ref = path_trace_radiosity(sc.surfaces, at, rp, o.in.path);
    const std::vector<Vec3>& r = ref.value.back();
    const float exposure = o.exposure > 0 ? o.exposure : [&] {
        std::vector<Vec3> unused;
        return tone_map(vm, gi, 0.0f, unused);
    }();
    const PointSet pts = points_in_input_order(vm);
    std::vector<Vec3> a(gi.size()), b(gi.size()), e(gi.size());
    for (size_t k = 0; k < gi.size(); ++k) {
        const uint32_t i = vm.order()[k];
        a[i] = r[k] * exposure, b[i] = gi[k] * exposure;
        const float rr = length(r[k]);
        e[i] = heat(rr > 0 ? length(gi[k] - r[k]) / rr : 0.0f);
    }
    Camera cam = sc.camera ? *sc.camera : default_camera(pts);
    o.render.shade = false;
    const std::vector<Image> imgs = {render_points(pts, a, cam, o.render),
                                     render_points(pts, b, cam, o.render),
                                     render_points(pts, e, cam, o.render)};
    write_png(o.image, side_by_side(imgs));
    fmt::print(
        "wrote:      {} (reference, {} paths per point | vmap gi | relative error, black 0, red "
        "25%, yellow >= 50%; exposure {}; reference in {:.1f} s)\n",
        o.image, rp.samples, exposure, ref.seconds);
}

}  // namespace

int run_gi_reference(GiOptions& o) {
    check_output(o.ref_out, "--ref-out");
    check_output(o.image, "-o");
    const auto [width, height] = parse_size(o.cam.size, "--size");
    o.render.width = width, o.render.height = height;
    Scene sc;
    std::vector<uint32_t> surf;
    const VisibilityMap vm = reference_vmap(o, sc, surf);
    const Sets sets = choose_points(sc, vm, surf, o.ref_points, o.ref.seed);
    std::vector<ReferencePoint> at;
    for (uint32_t k : sets.points) {
        const SceneSurface& s = sc.surfaces[surf[vm.order()[k]]];
        at.push_back({vm.points().positions[k], vm.points().normals[k], s.albedo, s.emission});
    }
    const int K = o.ref.bounces;
    ReferenceParams rp = o.ref;
    rp.progress = stderr_progress();
    const ReferenceResult ref = path_trace_radiosity(sc.surfaces, at, rp, o.in.path);
    fmt::print(
        "reference:  {} + {} points (all non-emitting, model), {} paths each, seed {}: {:.3g} "
        "rays in {:.1f} s\n",
        sets.num_all, sets.points.size() - sets.num_all, rp.samples, rp.seed, double(ref.rays),
        ref.seconds);
    Solved s = solve_vmap(vm, o, sets.points, K, !o.image.empty());
    fmt::print(
        "vmap gi:    theta {}, final gather theta {}: setup {:.2f} s, {} bounces {:.2f} s "
        "(converged to {}), final gathers at {} points {:.2f} s\n",
        o.gi.theta, o.gather_theta, s.seconds_setup, s.converged_bounces, s.seconds_bounces,
        o.tolerance, sets.points.size(), s.seconds_gather);
    if (o.brute) {
        const auto tb = Clock::now();
        s.methods.push_back(solve_brute(vm, sets.points, K, s.converged_bounces + 1));
        fmt::print("brute force: {} bounces in {:.1f} s\n", s.converged_bounces + 1,
                   seconds_since(tb));
    }
    print_table(s.methods, ref, sets, K, s.converged_bounces + 1);
    print_direct_split(direct_exact(sc, vm, sets.points, o.in.path), s.methods[0], ref, sets);
    if (!o.ref_out.empty()) {
        write_csv(o.ref_out, sc, vm, surf, sets, ref, s.methods, K);
        fmt::print("wrote:      {}\n", o.ref_out);
    }
    if (!o.image.empty()) side_by_side_picture(sc, vm, surf, s.all_points, o);
    return 0;
}

}  // namespace vmap::cli
