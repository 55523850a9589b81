// The Python module `vmap` (pybind11): build, load and save V-maps, and query, render and light
// them, with numpy arrays in and out. Ids are input point ids everywhere, as in the CLI.
// vmap::Error becomes vmap.Error (a RuntimeError) with the library's message; a progress
// callback that returns False, raises, or a Ctrl-C cancels a build (vmap.Cancelled).
#include <fmt/format.h>
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <tbb/parallel_for.h>

#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <optional>

#include "vmap/error.h"
#include "vmap/gi.h"
#include "vmap/io.h"
#include "vmap/normals.h"
#include "vmap/query.h"
#include "vmap/render.h"
#include "vmap/scene.h"
#include "vmap/version.h"
#include "vmap/vmap.h"

namespace py = pybind11;
using namespace vmap;

namespace {

template <class T>
using Array = py::array_t<T, py::array::c_style | py::array::forcecast>;

// An N x 3 array (float32 after numpy's conversion) as Vec3s; `name` for the message.
std::vector<Vec3> vec3s(const Array<float>& a, const char* name, py::ssize_t rows = -1) {
    if (a.ndim() != 2 || a.shape(1) != 3) {
        std::string shape;
        for (py::ssize_t d = 0; d < a.ndim(); ++d)
            shape += (d ? " x " : "") + std::to_string(a.shape(d));
        throw Error(fmt::format("{}: expected an N x 3 array, got {}", name,
                                a.ndim() ? shape : std::string("a scalar")));
    }
    if (rows >= 0 && a.shape(0) != rows)
        throw Error(
            fmt::format("{}: {} rows, expected {} (one per point)", name, a.shape(0), rows));
    std::vector<Vec3> v(size_t(a.shape(0)));
    const float* f = a.data();
    for (size_t k = 0; k < v.size(); ++k) v[k] = {f[3 * k], f[3 * k + 1], f[3 * k + 2]};
    return v;
}

PointSet point_set(const Array<float>& points, const std::optional<Array<float>>& normals,
                   const std::optional<Array<float>>& radii,
                   const std::optional<Array<float>>& colors,
                   const std::optional<Array<float>>& emission) {
    PointSet ps;
    ps.positions = vec3s(points, "points");
    const auto n = py::ssize_t(ps.size());
    if (normals) ps.normals = vec3s(*normals, "normals", n);
    if (colors) ps.colors = vec3s(*colors, "colors", n);
    if (emission) ps.emission = vec3s(*emission, "emission", n);
    if (radii) {
        if (radii->ndim() != 1 || radii->shape(0) != n)
            throw Error(fmt::format("radii: expected {} values (one per point)", n));
        ps.radii.assign(radii->data(), radii->data() + n);
    }
    if (ps.size() == 0) throw Error("points: the point set is empty");
    if (!ps.has_normals()) estimate_normals(ps, {}, "points");
    if (!ps.has_colors()) ps.colors.assign(ps.size(), Vec3{0.8f, 0.8f, 0.8f});
    return ps;
}

// The build options, named as BuildParams' fields (and the CLI's options).
struct BuildArgs {
    std::optional<int> max_height, leaf_points;
    std::optional<float> delta_floor;
    int K = VisibilityParams{}.K;
    float eps = VisibilityParams{}.eps, facing_tol = VisibilityParams{}.facing_tol,
          parallel_tol = VisibilityParams{}.parallel_tol,
          end_window = VisibilityParams{}.end_window, core = VisibilityParams{}.core;
    std::optional<float> roughness;  // None: a cloud's measured noise (0 for a scene file)
    std::string backend = "auto", occluders = "spheres";
    int threads = 0;
    uint64_t batch_pairs = BuildParams{}.max_batch_pairs;
    py::object progress = py::none();

    BuildParams params(std::optional<OctreeParams> file_octree) const {
        BuildParams bp;
        if (file_octree) bp.octree = *file_octree;
        if (max_height) bp.octree.max_height = *max_height;
        if (leaf_points) bp.octree.leaf_points = *leaf_points;
        if (delta_floor) bp.octree.delta_floor = *delta_floor;
        bp.visibility = {K,          eps, facing_tol, parallel_tol, end_window, roughness.value_or(0.f),
                         core};
        bp.backend = parse<Backend>(backend, "backend");
        bp.occluders = parse<OccluderSearch>(occluders, "occluders");
        bp.threads = threads;
        bp.max_batch_pairs = batch_pairs;
        return bp;
    }
};

// Calls a Python progress function from whichever thread reports; False, an exception or a
// pending Ctrl-C cancels.
ProgressCallback python_progress(py::object fn) {
    return [fn](const ProgressInfo& p) {
        py::gil_scoped_acquire gil;
        if (PyErr_CheckSignals() != 0) {
            PyErr_Clear();
            return false;
        }
        if (fn.is_none()) return true;
        try {
            py::dict d;
            d["stage"] = p.stage, d["done"] = p.done, d["total"] = p.total;
            d["seconds"] = p.seconds, d["eta_seconds"] = p.eta_seconds;
            d["estimate_seconds"] = p.estimate_seconds, d["backend"] = p.backend;
            d["note"] = p.note;
            const py::object r = fn(d);
            return r.is_none() || r.cast<bool>();
        } catch (const py::error_already_set&) {
            return false;
        }
    };
}

// `cloud`: the points are a scan's (not samples of a scene): without a roughness given, the
// predicate's is the cloud's measured noise, as `vmap build` takes it (vmap/input.h).
VisibilityMap build_points(PointSet ps, const BuildArgs& a, const std::string& source,
                           std::optional<OctreeParams> file_octree, bool cloud) {
    BuildParams bp = a.params(file_octree);
    if (cloud && !a.roughness) bp.visibility.roughness = roughness_of(estimate_surface_noise(ps));
    bp.progress = python_progress(a.progress);
    py::gil_scoped_release nogil;
    return build_vmap(std::move(ps), bp, nullptr, source);
}

VisibilityMap build_file(const std::string& path, std::optional<uint64_t> points,
                         std::optional<uint64_t> seed, std::optional<std::string> sampling,
                         const BuildArgs& a) {
    const bool scene = path.size() >= 5 && path.compare(path.size() - 5, 5, ".json") == 0;
    if (!scene) {
        if (points || seed || sampling)
            throw Error(path + ": points/seed/sampling apply to scene files, not clouds");
        PointSet ps = load_point_cloud(path);
        OctreeParams op = BuildParams{}.octree;
        op.delta_floor = cloud_delta_floor(ps);  // as `vmap build` chooses it for a cloud
        return build_points(std::move(ps), a, path, op, true);
    }
    Scene sc = load_scene(path);
    if (points) sc.points = *points;
    if (seed) sc.seed = *seed;
    if (sampling) sc.pattern = parse<SamplePattern>(*sampling, "sampling");
    return build_points(sample_scene(sc), a, path, scene_octree(sc), false);
}

uint32_t id_of(const VisibilityMap& vm, int64_t i, const char* what) {
    if (i < 0 || uint64_t(i) >= vm.order().size())
        throw Error(fmt::format("{}: point id {} out of range (the V-map has {} points)", what, i,
                                vm.order().size()));
    return uint32_t(i);
}

std::vector<uint32_t> pair_ids(const Array<int64_t>& pairs, const VisibilityMap& vm) {
    if (pairs.ndim() != 2 || pairs.shape(1) != 2)
        throw Error("pairs: expected an M x 2 array of point ids");
    std::vector<uint32_t> ids(size_t(pairs.size()));
    const int64_t* p = pairs.data();
    for (size_t k = 0; k < ids.size(); ++k) ids[k] = id_of(vm, p[k], "pairs");
    return ids;
}

py::array_t<uint8_t> query_codes(const VisibilityMap& vm, const Array<int64_t>& pairs) {
    const std::vector<uint32_t> ids = pair_ids(pairs, vm);
    py::array_t<uint8_t> out(py::ssize_t(ids.size() / 2));
    {
        py::gil_scoped_release nogil;
        query_pairs(vm, ids, std::span<uint8_t>(out.mutable_data(), ids.size() / 2));
    }
    return out;
}

py::tuple visible_from(const VisibilityMap& vm, const Array<int64_t>& ids) {
    std::vector<uint32_t> v(size_t(ids.size()));
    for (size_t k = 0; k < v.size(); ++k) v[k] = id_of(vm, ids.data()[k], "ids");
    VisibleSets s;
    {
        py::gil_scoped_release nogil;
        s = visible_sets(vm, v);
    }
    auto* off = new std::vector<uint64_t>(std::move(s.offsets));
    auto* tgt = new std::vector<uint32_t>(std::move(s.targets));
    // The arrays own the vectors (no copy): the capsules free them.
    py::capsule co(off, [](void* p) { delete static_cast<std::vector<uint64_t>*>(p); });
    py::capsule ct(tgt, [](void* p) { delete static_cast<std::vector<uint32_t>*>(p); });
    return py::make_tuple(py::array_t<uint64_t>(py::ssize_t(off->size()), off->data(), co),
                          py::array_t<uint32_t>(py::ssize_t(tgt->size()), tgt->data(), ct));
}

py::tuple shoot_rays(const VisibilityMap& vm, const Array<int64_t>& origins,
                     const Array<float>& dirs, float splat_scale) {
    const std::vector<Vec3> d = vec3s(dirs, "dirs", origins.size());
    if (origins.ndim() != 1) throw Error("origins: expected a 1-D array of point ids");
    std::vector<uint32_t> from(d.size());
    for (size_t k = 0; k < d.size(); ++k) from[k] = id_of(vm, origins.data()[k], "origins");
    py::array_t<int64_t> hit(py::ssize_t(d.size()));
    py::array_t<float> dist(py::ssize_t(d.size()));
    int64_t* h = hit.mutable_data();
    float* t = dist.mutable_data();
    {
        py::gil_scoped_release nogil;
        tbb::parallel_for(size_t(0), d.size(), [&](size_t k) {
            const RayHit r = shoot_ray(vm, from[k], d[k], nullptr, splat_scale);
            h[k] = r.hit ? int64_t(r.id) : -1;
            t[k] = r.hit ? r.distance : std::numeric_limits<float>::infinity();
        });
    }
    return py::make_tuple(hit, dist);
}

Camera camera_of(const VisibilityMap& vm, const std::optional<std::array<float, 3>>& eye,
                 const std::optional<std::array<float, 3>>& target, float fov) {
    Camera cam = default_camera(vm.points());
    if (eye) cam.eye = {(*eye)[0], (*eye)[1], (*eye)[2]};
    if (target) cam.target = {(*target)[0], (*target)[1], (*target)[2]};
    if (fov > 0) cam.fov_y_deg = fov;
    check_camera(cam, "camera (eye/target/fov)");
    return cam;
}

py::array_t<uint8_t> image_array(Image img) {
    auto* v = new std::vector<uint8_t>(std::move(img.rgb));
    py::capsule c(v, [](void* p) { delete static_cast<std::vector<uint8_t>*>(p); });
    return py::array_t<uint8_t>({py::ssize_t(img.height), py::ssize_t(img.width), py::ssize_t(3)},
                                v->data(), c);
}

// Per point in input order, N x 3 float32, from per-point values in octree order.
py::array_t<float> input_order(const VisibilityMap& vm, const std::vector<Vec3>& octree_order) {
    py::array_t<float> out({py::ssize_t(octree_order.size()), py::ssize_t(3)});
    float* o = out.mutable_data();
    for (size_t k = 0; k < octree_order.size(); ++k) {
        const Vec3 v = octree_order[k];
        float* row = o + 3 * size_t(vm.order()[k]);
        row[0] = v.x, row[1] = v.y, row[2] = v.z;
    }
    return out;
}

void save_vmap_of(const VisibilityMap& vm, const std::string& path) { save_vmap(path, vm); }

py::array_t<uint8_t> render(const VisibilityMap& vm, int64_t eye_id, int width, int height,
                            std::optional<std::array<float, 3>> eye,
                            std::optional<std::array<float, 3>> target, float fov,
                            std::optional<Array<float>> colors) {
    const Camera cam = camera_of(vm, eye, target, fov);
    RenderOptions opt;
    opt.width = width, opt.height = height;
    const uint32_t eye_pt = eye_id >= 0 ? id_of(vm, eye_id, "eye_id") : 0;
    const PointSet ps = eye_id >= 0 ? PointSet{} : points_in_input_order(vm);
    const std::vector<Vec3> c = eye_id >= 0 ? std::vector<Vec3>{}
                                : colors    ? vec3s(*colors, "colors", py::ssize_t(ps.size()))
                                            : ps.colors;
    Image img;
    {
        py::gil_scoped_release nogil;
        img = eye_id >= 0 ? render_visible(vm, eye_pt, cam, opt) : render_points(ps, c, cam, opt);
    }
    return image_array(std::move(img));
}

py::array_t<float> gi(const VisibilityMap& vm, int bounces, float theta, const std::string& refine,
                      const std::string& backend) {
    GiParams p;
    p.bounces = bounces, p.theta = theta;
    p.refine = parse<GiRefine>(refine, "refine"), p.backend = parse<Backend>(backend, "backend");
    std::vector<Vec3> b;
    {
        py::gil_scoped_release nogil;
        b = solve_radiosity(vm, p);
    }
    return input_order(vm, b);
}

// The keyword options of build() and build_file(), by BuildParams' names.
BuildArgs build_args(const py::kwargs& kw) {
    using Set = void (*)(BuildArgs&, py::handle);
    static const std::map<std::string, Set> setters = {
        {"max_height", [](BuildArgs& a, py::handle v) { a.max_height = v.cast<int>(); }},
        {"leaf_points", [](BuildArgs& a, py::handle v) { a.leaf_points = v.cast<int>(); }},
        {"delta_floor", [](BuildArgs& a, py::handle v) { a.delta_floor = v.cast<float>(); }},
        {"K", [](BuildArgs& a, py::handle v) { a.K = v.cast<int>(); }},
        {"eps", [](BuildArgs& a, py::handle v) { a.eps = v.cast<float>(); }},
        {"facing_tol", [](BuildArgs& a, py::handle v) { a.facing_tol = v.cast<float>(); }},
        {"parallel_tol", [](BuildArgs& a, py::handle v) { a.parallel_tol = v.cast<float>(); }},
        {"end_window", [](BuildArgs& a, py::handle v) { a.end_window = v.cast<float>(); }},
        {"roughness", [](BuildArgs& a, py::handle v) { a.roughness = v.cast<float>(); }},
        {"core", [](BuildArgs& a, py::handle v) { a.core = v.cast<float>(); }},
        {"backend", [](BuildArgs& a, py::handle v) { a.backend = v.cast<std::string>(); }},
        {"occluders", [](BuildArgs& a, py::handle v) { a.occluders = v.cast<std::string>(); }},
        {"threads", [](BuildArgs& a, py::handle v) { a.threads = v.cast<int>(); }},
        {"batch_pairs", [](BuildArgs& a, py::handle v) { a.batch_pairs = v.cast<uint64_t>(); }},
        {"progress",
         [](BuildArgs& a, py::handle v) { a.progress = py::reinterpret_borrow<py::object>(v); }},
    };
    BuildArgs a;
    for (auto [k, v] : kw) {
        const std::string key = py::str(k);
        const auto it = setters.find(key);
        if (it == setters.end()) {
            std::string known;
            for (const auto& [name, set] : setters) known += (known.empty() ? "" : ", ") + name;
            throw py::type_error(fmt::format("unknown build option '{}' ({})", key, known));
        }
        it->second(a, v);
    }
    return a;
}

void def_build(py::module_& m) {
    auto args = [](const py::kwargs& kw) { return build_args(kw); };
    m.def(
        "build",
        [args](const Array<float>& points, std::optional<Array<float>> normals,
               std::optional<Array<float>> radii, std::optional<Array<float>> colors,
               std::optional<Array<float>> emission, py::kwargs kw) {
            return build_points(point_set(points, normals, radii, colors, emission), args(kw),
                                "points", std::nullopt, true);
        },
        py::arg("points"), py::arg("normals") = py::none(), py::arg("radii") = py::none(),
        py::arg("colors") = py::none(), py::arg("emission") = py::none(),
        "V-map of a point set: points N x 3; normals N x 3 (estimated when None), radii N "
        "(splat radii), colors N x 3 (albedo, 0.8 grey when None), emission N x 3. Options as "
        "the CLI's build: max_height, leaf_points, delta_floor, K, eps, facing_tol, parallel_tol, "
        "end_window, roughness (None: the points' measured noise, vmap.surface_noise), core, "
        "backend ('auto', "
        "'cpu', 'cuda'), occluders, threads (0: all cores), batch_pairs, progress "
        "(a function of a dict; returning False cancels).");
    m.def(
        "build_file",
        [args](const std::string& path, std::optional<uint64_t> points,
               std::optional<uint64_t> seed, std::optional<std::string> sampling,
               py::kwargs kw) { return build_file(path, points, seed, sampling, args(kw)); },
        py::arg("path"), py::arg("points") = py::none(), py::arg("seed") = py::none(),
        py::arg("sampling") = py::none(),
        "V-map of a scene file (.json: sampled with `points`, `seed` and `sampling` ('blue-noise' "
        "or 'uniform') when given, its octree defaults, the disc floor by the sampling) or a "
        "point cloud (.ply/.off); options as build().");
    m.def(
        "estimate_normals",
        [](const Array<float>& points, std::optional<Array<float>> radii,
           std::optional<Array<float>> viewpoint, std::optional<Array<float>> sensors) {
            PointSet ps;
            ps.positions = vec3s(points, "points");
            const auto n = py::ssize_t(ps.size());
            if (n == 0) throw Error("points: the point set is empty");
            if (radii) {
                if (radii->ndim() != 1 || radii->shape(0) != n)
                    throw Error(fmt::format("radii: expected {} values (one per point)", n));
                ps.radii.assign(radii->data(), radii->data() + n);
            }
            NormalEstimationParams params;
            if (viewpoint) {
                if (viewpoint->size() != 3) throw Error("viewpoint: expected 3 values (x, y, z)");
                const float* v = viewpoint->data();
                params.orientation = Orientation::kViewpoint;
                params.viewpoint = {v[0], v[1], v[2]};
            }
            std::vector<Vec3> sensed;
            if (sensors) {
                if (viewpoint) throw Error("sensors: give a viewpoint or sensors, not both");
                sensed = vec3s(*sensors, "sensors", n);
                params.orientation = Orientation::kOutward;  // replaced by the sensors below
            }
            OrientationReport rep;
            {
                py::gil_scoped_release nogil;
                estimate_normals(ps, params, "points", &rep);
                if (!sensed.empty()) orient_toward(ps, sensed, "points");
            }
            py::array_t<float> normals({n, py::ssize_t(3)});
            float* o = normals.mutable_data();
            for (size_t k = 0; k < ps.size(); ++k) {
                o[3 * k] = ps.normals[k].x;
                o[3 * k + 1] = ps.normals[k].y;
                o[3 * k + 2] = ps.normals[k].z;
            }
            py::dict d;
            d["normals"] = normals;
            d["method"] = sensed.empty() ? rep.method : std::string("toward each point's sensor");
            d["scanner"] =
                rep.scanner
                    ? py::object(py::make_tuple(rep.scanner->x, rep.scanner->y, rep.scanner->z))
                    : py::object(py::none());
            py::list scanners;
            for (const Vec3& x : rep.scanners) scanners.append(py::make_tuple(x.x, x.y, x.z));
            d["scanners"] = scanners;
            d["by_space"] = rep.by_space, d["by_view"] = rep.by_view, d["by_rays"] = rep.by_rays,
            d["by_shape"] = rep.by_shape, d["by_neighbours"] = rep.by_neighbours;
            d["at_creases"] = rep.at_creases;
            return d;
        },
        py::arg("points"), py::arg("radii") = py::none(), py::arg("viewpoint") = py::none(),
        py::arg("sensors") = py::none(),
        "Normals of a raw cloud, points N x 3, as build() estimates them: {'normals': N x 3, "
        "'method': how they were signed, in words, 'scanner': where a bare scan from inside a "
        "room was taken from, as far as its points tell (None otherwise), 'scanners': the places "
        "a bare scan's spacing shows its scanners stood at (a list of (x, y, z), empty when it "
        "does not tell), and the points signed "
        "by each cue: 'by_space', 'by_view', 'by_rays', 'by_shape', 'by_neighbours', and "
        "'at_creases': the points at a crease whose normal is the plane through them that holds "
        "the most of their neighbours}. "
        "viewpoint (x, y, z) signs every normal toward it; sensors N x 3 each toward its own "
        "scanner position; radii N (splat radii) are estimated when None.");
    m.def(
        "surface_noise",
        [](const Array<float>& points) {
            PointSet ps;
            ps.positions = vec3s(points, "points");
            py::gil_scoped_release nogil;
            const SurfaceNoise n = estimate_surface_noise(ps);
            py::gil_scoped_acquire gil;
            py::dict d;
            d["sigma"] = n.sigma, d["spacing"] = n.spacing, d["roughness"] = roughness_of(n);
            return d;
        },
        py::arg("points"),
        "A scan's surface noise, points N x 3: {'sigma': the points' scatter off their surface "
        "(median jet-fit residual), 'spacing': the sample spacing, 'roughness': what build() "
        "takes for these points when given none}.");
    m.def("load", &load_vmap, py::arg("path"), py::call_guard<py::gil_scoped_release>(),
          "Reads a .vmap file.");
}

void def_map(py::module_& m) {
    py::class_<VisibilityMap>(m, "VisibilityMap")
        .def_property_readonly("num_points",
                               [](const VisibilityMap& v) { return v.order().size(); })
        .def_property_readonly("num_links", &VisibilityMap::num_links)
        .def_property_readonly("num_nodes",
                               [](const VisibilityMap& v) { return v.octree().num_nodes(); })
        .def_property_readonly("num_leaves",
                               [](const VisibilityMap& v) { return v.octree().num_leaves(); })
        .def_property_readonly("height", [](const VisibilityMap& v) { return v.octree().height(); })
        .def_property_readonly("delta_floor",
                               [](const VisibilityMap& v) { return v.octree_params().delta_floor; })
        .def_property_readonly(
            "end_window", [](const VisibilityMap& v) { return v.visibility_params().end_window; })
        .def_property_readonly(
            "roughness", [](const VisibilityMap& v) { return v.visibility_params().roughness; },
            "The predicate's roughness (the input's units): steps below it between a point and "
            "its own sheet did not occlude; 0 for samples of a scene.")
        .def_property_readonly(
            "core", [](const VisibilityMap& v) { return v.visibility_params().core; },
            "The predicate's core: a crossing within this share of an occluder's disc radius "
            "from its centre counted as K occluders (not where the roughness is above 0).")
        .def_property_readonly(
            "points", [](const VisibilityMap& v) { return input_order(v, v.points().positions); },
            "Positions, N x 3 float32, in input order, relative to origin.")
        .def_property_readonly(
            "origin",
            [](const VisibilityMap& v) {
                const std::array<double, 3>& o = v.points().origin;
                return py::make_tuple(o[0], o[1], o[2]);
            },
            "(x, y, z): where the input file's coordinates have the points' zero (points + origin "
            "are the file's); (0, 0, 0) unless the cloud lay far from its file's zero.")
        .def_property_readonly(
            "normals", [](const VisibilityMap& v) { return input_order(v, v.points().normals); },
            "Normals, N x 3 float32, in input order.")
        .def_property_readonly(
            "colors", [](const VisibilityMap& v) { return input_order(v, v.points().colors); },
            "Albedo, N x 3 float32 (linear RGB), in input order (empty when none).")
        .def_property_readonly(
            "emission", [](const VisibilityMap& v) { return input_order(v, v.points().emission); },
            "Emission, N x 3 float32, in input order (empty when none).")
        .def_property_readonly(
            "radii",
            [](const VisibilityMap& v) {
                py::array_t<float> out(py::ssize_t(v.points().radii.size()));
                for (size_t k = 0; k < v.points().radii.size(); ++k)
                    out.mutable_data()[v.order()[k]] = v.points().radii[k];
                return out;
            },
            "Splat radii, N float32, in input order (empty when none).")
        .def("save", &save_vmap_of, py::arg("path"), py::call_guard<py::gil_scoped_release>())
        .def(
            "query",
            [](const VisibilityMap& v, const Array<int64_t>& pairs) {
                py::array_t<uint8_t> c = query_codes(v, pairs);
                return py::array(c.attr("__eq__")(uint8_t(PairVisibility::kVisible)));
            },
            py::arg("pairs"), "Visibility of point pairs (M x 2 ids) -> bool[M].")
        .def("query_codes", &query_codes, py::arg("pairs"),
             "The same as uint8[M]: 0 hidden, 1 visible, 2 same leaf (the V-map does not say).")
        .def(
            "visible_set",
            [](const VisibilityMap& v, int64_t i) {
                return py::array(py::cast(v.visible_set(id_of(v, i, "visible_set"))));
            },
            py::arg("id"), "Sorted ids visible from point `id`.")
        .def("visible_from", &visible_from, py::arg("ids"),
             "Visible sets of many points as CSR: (offsets uint64[len(ids)+1], ids uint32); the "
             "set of ids[k] is targets[offsets[k]:offsets[k+1]].")
        .def("shoot_rays", &shoot_rays, py::arg("origins"), py::arg("dirs"),
             py::arg("splat_scale") = 2.f,
             "First splat hit from each origin id along dirs (M x 3): (hit ids int64, -1 for "
             "none; distances float32, inf for none).")
        .def("render", &render, py::arg("eye_id") = -1, py::arg("width") = 800,
             py::arg("height") = 800, py::arg("eye") = py::none(), py::arg("target") = py::none(),
             py::arg("fov") = 0.f, py::arg("colors") = py::none(),
             "Picture as H x W x 3 uint8 (sRGB): with eye_id, Fig. 9's visible set from that "
             "point; else the points in `colors` (N x 3 linear RGB, input order) or their "
             "albedo, shaded. Camera from eye/target/fov (default: through the room's open "
             "side).")
        .def("gi", &gi, py::arg("bounces") = 3, py::arg("theta") = GiParams{}.theta,
             py::arg("refine") = "blocks", py::arg("backend") = "auto",
             "Diffuse radiosity per point (N x 3 float32, input order) with the V-map as the "
             "visibility (paper §6.3).");
}

}  // namespace

PYBIND11_MODULE(_vmap, m) {
    m.doc() = "vmap: view-independent mutual visibility for point models";
    static py::exception<Error> error(m, "Error", PyExc_RuntimeError);
    static py::exception<Cancelled> cancelled(m, "Cancelled", error.ptr());
    py::register_exception_translator([](std::exception_ptr p) {
        try {
            if (p) std::rethrow_exception(p);
        } catch (const Cancelled& e) {
            cancelled(e.what());
        } catch (const Error& e) {
            error(e.what());
        }
    });
    m.attr("__version__") = vmap::version();
    m.attr("commit") = vmap::commit();
    m.attr("built_with_cuda") = vmap::built_with_cuda();
    m.def("data_dir", &data_dir, "The folder holding vmap's scenes/ and models/.");
    m.def(
        "write_png",
        [](const std::string& path, const py::array_t<uint8_t, py::array::c_style>& rgb) {
            if (rgb.ndim() != 3 || rgb.shape(2) != 3)
                throw Error(path + ": write_png: expected an H x W x 3 uint8 array");
            Image img;
            img.height = int(rgb.shape(0)), img.width = int(rgb.shape(1));
            img.rgb.assign(rgb.data(), rgb.data() + rgb.size());
            write_png(path, img);
        },
        py::arg("path"), py::arg("image"), "Writes an H x W x 3 uint8 array as a PNG.");
    def_build(m);
    def_map(m);
}
