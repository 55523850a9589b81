// Scene files: parsing, the Cornell room, placing meshes (docs/design.md "Scenes and sampling").
#include "vmap/scene.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "io/json_file.h"
#include "vmap/error.h"
#include "vmap/files.h"
#include "vmap/io.h"
#include "vmap/version.h"

namespace vmap {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct Ctx {
    std::string file;
    [[noreturn]] void fail(const std::string& field, const std::string& what) const {
        if (field.empty()) throw Error(fmt::format("{}: {}", file, what));
        throw Error(fmt::format("{}: {}: {}", file, field, what));
    }
    std::string text(const json& obj, const char* key, const std::string& field,
                     const std::string& def) const {
        if (!obj.contains(key)) return def;
        if (!obj[key].is_string()) fail(field, "expected a string");
        return obj[key].get<std::string>();
    }
    bool boolean(const json& obj, const char* key, const std::string& field, bool def) const {
        if (!obj.contains(key)) return def;
        if (!obj[key].is_boolean()) fail(field, "expected true or false");
        return obj[key].get<bool>();
    }
    double number(const json& j, const std::string& field, double lo, double hi) const {
        if (!j.is_number()) fail(field, "expected a number");
        const double v = j.get<double>();
        if (!std::isfinite(v) || v < lo || v > hi)
            fail(field, fmt::format("{} out of range [{}, {}]", v, lo, hi));
        return v;
    }
    Vec3 vec3(const json& j, const std::string& field, double lo, double hi) const {
        if (!j.is_array() || j.size() != 3) fail(field, "expected an array of 3 numbers");
        return {float(number(j[0], field + "[0]", lo, hi)),
                float(number(j[1], field + "[1]", lo, hi)),
                float(number(j[2], field + "[2]", lo, hi))};
    }
    void known(const json& obj, const std::string& field,
               std::initializer_list<const char*> keys) const {
        if (!obj.is_object()) fail(field, "expected an object");
        for (auto it = obj.begin(); it != obj.end(); ++it) {
            bool ok = false;
            for (const char* k : keys) ok = ok || it.key() == k;
            if (!ok) fail(field.empty() ? it.key() : field + "." + it.key(), "unknown key");
        }
    }
};

void add_quad(SceneSurface& s, Vec3 a, Vec3 b, Vec3 c, Vec3 d) {
    // a b c d counter-clockwise seen from the side the normal points to.
    const uint32_t o = static_cast<uint32_t>(s.mesh.vertices.size());
    s.mesh.vertices.insert(s.mesh.vertices.end(), {a, b, c, d});
    s.mesh.triangles.push_back({o, o + 1, o + 2});
    s.mesh.triangles.push_back({o, o + 2, o + 3});
}

Vec3 rotate(Vec3 p, Vec3 deg) {
    const double k = M_PI / 180.0;
    auto rot = [](Vec3 v, int axis, double a) {
        const float c = float(std::cos(a)), s = float(std::sin(a));
        if (axis == 0) return Vec3{v.x, c * v.y - s * v.z, s * v.y + c * v.z};
        if (axis == 1) return Vec3{c * v.x + s * v.z, v.y, -s * v.x + c * v.z};
        return Vec3{c * v.x - s * v.y, s * v.x + c * v.y, v.z};
    };
    p = rot(p, 0, deg.x * k);
    p = rot(p, 1, deg.y * k);
    return rot(p, 2, deg.z * k);
}

double signed_volume(const Mesh& m) {
    double v = 0;
    for (const auto& t : m.triangles) {
        const Vec3 a = m.vertices[t[0]], b = m.vertices[t[1]], c = m.vertices[t[2]];
        v += dot(a, cross(b, c));
    }
    return v / 6.0;
}

// ---- the room --------------------------------------------------------------------------------

// The Cornell room: published dimensions (552.8 x 548.8 x 559.2 mm) and wall colours.
void add_walls(const Ctx& cx, const json& room, Scene& sc) {
    cx.known(room, "room", {"size", "floor", "ceiling", "back", "left", "right"});
    if (room.contains("size")) sc.room_size = cx.vec3(room["size"], "room.size", 1e-3, 1e4);
    auto albedo = [&](const char* key, Vec3 def) {
        return room.contains(key) ? cx.vec3(room[key], std::string("room.") + key, 0, 1) : def;
    };
    const float W = sc.room_size.x, H = sc.room_size.y, D = sc.room_size.z;
    const Vec3 white{0.73f, 0.73f, 0.73f};
    struct Wall {
        const char* name;
        Vec3 a, b, c, d, albedo;
    };
    const Wall walls[] = {
        {"floor", {0, 0, 0}, {0, 0, D}, {W, 0, D}, {W, 0, 0}, albedo("floor", white)},
        {"back", {0, 0, D}, {0, H, D}, {W, H, D}, {W, 0, D}, albedo("back", white)},
        {"left",
         {W, 0, 0},
         {W, 0, D},
         {W, H, D},
         {W, H, 0},
         albedo("left", {0.63f, 0.065f, 0.05f})},
        {"right",
         {0, 0, 0},
         {0, H, 0},
         {0, H, D},
         {0, 0, D},
         albedo("right", {0.14f, 0.45f, 0.091f})},
    };
    for (const Wall& w : walls) {
        SceneSurface s;
        s.name = w.name;
        s.albedo = w.albedo;
        add_quad(s, w.a, w.b, w.c, w.d);
        sc.surfaces.push_back(std::move(s));
    }
    // The ceiling, with a hole for the light: add_light fills it in.
    SceneSurface ceiling;
    ceiling.name = "ceiling";
    ceiling.albedo = albedo("ceiling", white);
    sc.surfaces.insert(sc.surfaces.begin() + 1, std::move(ceiling));
}

// The area light, just below the ceiling, facing down (Cornell: 130 x 105 mm, centred).
void add_light(const Ctx& cx, const json& light, Scene& sc) {
    const float W = sc.room_size.x, H = sc.room_size.y, D = sc.room_size.z;
    cx.known(light, "light", {"center", "size", "emission"});
    float lx = W * 0.5f, lz = D * 0.5f, sx = 0.13f * W / 0.5528f, sz = 0.105f * D / 0.5592f;
    if (light.contains("center")) {
        if (!light["center"].is_array() || light["center"].size() != 2)
            cx.fail("light.center", "expected [x, z]");
        lx = float(cx.number(light["center"][0], "light.center[0]", 0, W));
        lz = float(cx.number(light["center"][1], "light.center[1]", 0, D));
    }
    if (light.contains("size")) {
        if (!light["size"].is_array() || light["size"].size() != 2)
            cx.fail("light.size", "expected [sx, sz]");
        sx = float(cx.number(light["size"][0], "light.size[0]", 1e-4, W));
        sz = float(cx.number(light["size"][1], "light.size[1]", 1e-4, D));
    }
    const float x0 = std::max(0.f, lx - sx / 2), x1 = std::min(W, lx + sx / 2);
    const float z0 = std::max(0.f, lz - sz / 2), z1 = std::min(D, lz + sz / 2);
    {
        // The ceiling around the light: the part the light covers is not sampled (its points
        // would be hidden from everything, by a light 0.5 mm below them, closer than any
        // leaf-level occluder test can resolve; docs/validation.md, "buried points").
        SceneSurface& s = sc.surfaces[1];
        auto strip = [&](float xa, float xb, float za, float zb) {
            if (xb > xa && zb > za) add_quad(s, {xa, H, za}, {xb, H, za}, {xb, H, zb}, {xa, H, zb});
        };
        strip(0, W, 0, z0);
        strip(0, W, z1, D);
        strip(0, x0, z0, z1);
        strip(x1, W, z0, z1);
    }
    SceneSurface s;
    s.name = "light";
    s.albedo = {0.78f, 0.78f, 0.78f};
    s.emission = light.contains("emission") ? cx.vec3(light["emission"], "light.emission", 0, 1e6)
                                            : Vec3{17.f, 12.f, 4.f};
    const float y = H * 0.999f;  // a hair below the ceiling, so the two never coincide
    add_quad(s, {x0, y, z0}, {x1, y, z0}, {x1, y, z1}, {x0, y, z1});
    sc.surfaces.push_back(std::move(s));
}

// ---- meshes and clouds ------------------------------------------------------------------------

// Scale, rotation and placement of a mesh or cloud entry: centre the box at the origin, scale,
// rotate, then stand its bottom centre on position.
struct Placement {
    bool identity = true;
    Vec3 mid;
    float scale = 1;
    Vec3 axes{1, 1, 1};  // a per-axis scale (meshes only: "scale": [sx, sy, sz])
    Vec3 rot;
    Vec3 shift;
    Vec3 scaled(Vec3 v) const {
        const Vec3 c = (v - mid) * scale;
        return {c.x * axes.x, c.y * axes.y, c.z * axes.z};
    }
    Vec3 point(Vec3 v) const { return identity ? v : rotate(scaled(v), rot) + shift; }
    Vec3 direction(Vec3 n) const { return identity ? n : rotate(n, rot); }
};

Placement placement(const Ctx& cx, const json& m, const std::string& f, const std::string& file,
                    const std::vector<Vec3>& pts, const Scene& sc) {
    Vec3 lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
    for (Vec3 v : pts) {
        lo = {std::min(lo.x, v.x), std::min(lo.y, v.y), std::min(lo.z, v.z)};
        hi = {std::max(hi.x, v.x), std::max(hi.y, v.y), std::max(hi.z, v.z)};
    }
    Placement pl;
    pl.mid = (lo + hi) * 0.5f;
    const float ext = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
    if (!(ext > 0) || !std::isfinite(ext))
        cx.fail(f + ".file", file + ": zero extent (all points coincide)");
    if (m.contains("size") && m.contains("scale")) cx.fail(f, "give size or scale, not both");
    if (m.contains("size")) pl.scale = float(cx.number(m["size"], f + ".size", 1e-6, 1e6)) / ext;
    if (m.contains("scale") && m["scale"].is_array())
        pl.axes = cx.vec3(m["scale"], f + ".scale", 1e-9, 1e9);
    else if (m.contains("scale"))
        pl.scale = float(cx.number(m["scale"], f + ".scale", 1e-9, 1e9));
    pl.rot = m.contains("rotate") ? cx.vec3(m["rotate"], f + ".rotate", -3600, 3600) : Vec3{};
    const bool moved =
        m.contains("size") || m.contains("scale") || m.contains("rotate") || m.contains("position");
    if (!sc.has_room && !moved) return pl;  // the file's own coordinates, exactly
    pl.identity = false;
    const Vec3 own_base{pl.mid.x, lo.y, pl.mid.z};
    const Vec3 base = sc.has_room ? Vec3{sc.room_size.x / 2, 0, sc.room_size.z / 2} : own_base;
    const Vec3 pos =
        m.contains("position") ? cx.vec3(m["position"], f + ".position", -1e6, 1e6) : base;
    float ylo = INFINITY, xlo = INFINITY, xhi = -INFINITY, zlo = INFINITY, zhi = -INFINITY;
    for (Vec3 v : pts) {
        v = rotate(pl.scaled(v), pl.rot);
        ylo = std::min(ylo, v.y);
        xlo = std::min(xlo, v.x), xhi = std::max(xhi, v.x);
        zlo = std::min(zlo, v.z), zhi = std::max(zhi, v.z);
    }
    pl.shift = pos - Vec3{(xlo + xhi) / 2, ylo, (zlo + zhi) / 2};
    return pl;
}

fs::path entry_file(const Ctx& cx, const json& m, const std::string& f, const fs::path& dir) {
    if (!m.contains("file")) cx.fail(f + ".file", "missing");
    if (!m["file"].is_string()) cx.fail(f + ".file", "expected a string");
    const std::string rel = m["file"].get<std::string>();
    const fs::path file = fs::path(rel).is_absolute() ? fs::path(rel) : dir / rel;
    if (!fs::exists(file))
        cx.fail(f + ".file", fmt::format("{}: no such file (scripts/fetch-models.sh fetches "
                                         "the models)",
                                         file.string()));
    return file;
}

// Outward normals: a closed mesh wound inside-out has negative signed volume.
void orient_outward(Mesh& mesh, bool flip_requested) {
    bool flip = signed_volume(mesh) < 0;
    if (flip_requested) flip = !flip;
    if (flip)
        for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
}

void add_mesh(const Ctx& cx, const json& m, const std::string& f, const fs::path& dir, Scene& sc) {
    cx.known(m, f,
             {"file", "name", "size", "scale", "rotate", "position", "albedo", "emission",
              "flip_normals"});
    const fs::path file = entry_file(cx, m, f, dir);
    ModelData md;
    try {
        md = read_model(file.string());
    } catch (const Error& e) {
        cx.fail(f + ".file", e.what());
    }
    if (md.triangles.empty()) cx.fail(f + ".file", file.string() + ": has no faces");
    SceneSurface s;
    s.is_model = true;
    s.name = cx.text(m, "name", f + ".name", file.stem().string());
    if (m.contains("albedo")) {
        s.albedo = cx.vec3(m["albedo"], f + ".albedo", 0, 1);
    } else {
        s.albedo = Vec3{0.75f, 0.75f, 0.8f};
        s.vertex_colors = std::move(md.points.colors);
    }
    if (m.contains("emission")) {
        s.emission = cx.vec3(m["emission"], f + ".emission", 0, 1e6);
    } else {
        s.vertex_emission = std::move(md.points.emission);
    }
    s.mesh = md.mesh();
    const Placement pl = placement(cx, m, f, file.string(), s.mesh.vertices, sc);
    for (Vec3& v : s.mesh.vertices) v = pl.point(v);
    orient_outward(s.mesh, cx.boolean(m, "flip_normals", f + ".flip_normals", false));
    sc.notes.insert(sc.notes.end(), md.notes.begin(), md.notes.end());
    sc.surfaces.push_back(std::move(s));
}

void add_cloud(const Ctx& cx, const json& c, const std::string& f, const fs::path& dir, Scene& sc) {
    cx.known(c, f, {"file", "name", "size", "scale", "rotate", "position", "albedo", "emission"});
    const fs::path file = entry_file(cx, c, f, dir);
    PointSet ps;
    try {
        ps = load_point_cloud(file.string());
    } catch (const Error& e) {
        cx.fail(f + ".file", e.what());
    }
    // The scene's frame is the file's: a cloud read around a far origin goes back to it (its
    // placement below may move it, and other clouds and meshes share the frame).
    to_file_frame(ps);
    if (c.contains("scale") && c["scale"].is_array())
        cx.fail(f + ".scale", "a per-axis scale applies to meshes, not clouds (give one factor)");
    const Placement pl = placement(cx, c, f, file.string(), ps.positions, sc);
    for (Vec3& p : ps.positions) p = pl.point(p);
    for (Vec3& n : ps.normals) n = pl.direction(n);
    for (float& r : ps.radii) r *= pl.scale;
    if (c.contains("albedo"))
        ps.colors.assign(ps.size(), cx.vec3(c["albedo"], f + ".albedo", 0, 1));
    if (c.contains("emission")) {
        ps.emission.assign(ps.size(), cx.vec3(c["emission"], f + ".emission", 0, 1e6));
    } else if (ps.emission.empty()) {
        ps.emission.assign(ps.size(), Vec3{});
    }
    sc.clouds.push_back(std::move(ps));
}

// ---- the rest of the file ---------------------------------------------------------------------

void read_sampling(const Ctx& cx, const json& j, Scene& sc) {
    const json sampling = j.value("sampling", json::object());
    cx.known(sampling, "sampling", {"points", "density", "seed", "pattern"});
    if (sampling.contains("points") && sampling.contains("density"))
        cx.fail("sampling", "give points or density, not both");
    if (sampling.contains("points"))
        sc.points = uint64_t(cx.number(sampling["points"], "sampling.points", 1, 5e7));
    if (sampling.contains("density")) {
        const double area = scene_area(sc);
        const double dens = cx.number(sampling["density"], "sampling.density", 1e-6, 1e12);
        const double n = std::ceil(dens * area);
        if (n > 5e7) cx.fail("sampling.density", fmt::format("gives {} points (at most 5e7)", n));
        sc.points = uint64_t(std::max(1.0, n));
    }
    if (sampling.contains("seed"))
        sc.seed = uint64_t(cx.number(sampling["seed"], "sampling.seed", 0, 1e15));
    if (sampling.contains("pattern")) {
        const std::string p = cx.text(sampling, "pattern", "sampling.pattern", "");
        try {
            sc.pattern = parse<SamplePattern>(p, "sampling.pattern");
        } catch (const Error&) {
            cx.fail("sampling.pattern", fmt::format("unknown value '{}' (expected uniform or "
                                                    "blue-noise)",
                                                    p));
        }
    }
}

void read_octree(const Ctx& cx, const json& j, Scene& sc) {
    if (!j.contains("octree")) return;
    const json& o = j["octree"];
    cx.known(o, "octree", {"max_height", "leaf_points", "delta_floor"});
    OctreeParams op;
    if (o.contains("max_height"))
        op.max_height = int(cx.number(o["max_height"], "octree.max_height", 1, 21));
    if (o.contains("leaf_points"))
        op.leaf_points = int(cx.number(o["leaf_points"], "octree.leaf_points", 1, 1e6));
    if (o.contains("delta_floor"))
        sc.delta_floor = float(
            cx.number(o["delta_floor"], "octree.delta_floor", 0, OctreeParams::kDeltaFloorLimit));
    sc.octree = op;
}

void read_camera(const Ctx& cx, const json& j, Scene& sc) {
    if (!j.contains("camera")) return;
    const json& c = j["camera"];
    cx.known(c, "camera", {"eye", "target", "fov", "up"});
    if (!c.contains("eye")) cx.fail("camera.eye", "missing");
    if (!c.contains("target")) cx.fail("camera.target", "missing");
    Camera cam;
    cam.eye = cx.vec3(c["eye"], "camera.eye", -1e6, 1e6);
    cam.target = cx.vec3(c["target"], "camera.target", -1e6, 1e6);
    if (c.contains("up")) cam.up = cx.vec3(c["up"], "camera.up", -1e6, 1e6);
    if (c.contains("fov")) cam.fov_y_deg = float(cx.number(c["fov"], "camera.fov", 0.1, 179));
    if (!(length(cam.target - cam.eye) > 0)) cx.fail("camera.target", "equals camera.eye");
    if (!(length(cross(cam.target - cam.eye, cam.up)) > 0))
        cx.fail("camera.up", "zero or parallel to the view direction");
    sc.camera = cam;
}

// Without a room, the scene's size is its contents' bounding box.
void set_extent(const std::string& path, Scene& sc) {
    Vec3 lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
    auto grow = [&](Vec3 v) {
        lo = {std::min(lo.x, v.x), std::min(lo.y, v.y), std::min(lo.z, v.z)};
        hi = {std::max(hi.x, v.x), std::max(hi.y, v.y), std::max(hi.z, v.z)};
    };
    for (const auto& s : sc.surfaces)
        for (Vec3 v : s.mesh.vertices) grow(v);
    for (const auto& c : sc.clouds)
        for (Vec3 v : c.positions) grow(v);
    if (!(hi.x >= lo.x))
        throw Error(fmt::format("{}: no room (\"room\": null) and no meshes or clouds", path));
    sc.room_size = hi - lo;
}

// A mesh file on its own: one surface in the file's coordinates, no room.
Scene mesh_file_scene(const std::string& path) {
    ModelData md = read_model(path);
    if (md.triangles.empty())
        throw Error(fmt::format("{}: has no faces (a point cloud; a scene needs a mesh)", path));
    Scene sc;
    sc.path = path;
    sc.name = fs::path(path).stem().string();
    sc.has_room = false;
    SceneSurface s;
    s.is_model = true;
    s.name = sc.name;
    s.vertex_colors = std::move(md.points.colors);
    s.vertex_emission = std::move(md.points.emission);
    s.mesh = md.mesh();
    orient_outward(s.mesh, false);
    sc.notes = std::move(md.notes);
    if (md.points.has_normals())
        sc.notes.push_back(path + ": vertex normals not used (samples take their triangle's)");
    sc.surfaces.push_back(std::move(s));
    set_extent(path, sc);
    return sc;
}

}  // namespace

std::string default_scene_path() { return data_dir() + "/scenes/cornell-bunny.json"; }

OctreeParams scene_octree(const Scene& scene) {
    OctreeParams op = scene.octree.value_or(OctreeParams{});
    op.delta_floor = scene.delta_floor.value_or(scene.pattern == SamplePattern::kBlueNoise
                                                    ? OctreeParams::kEvenDeltaFloor
                                                    : OctreeParams::kDefaultDeltaFloor);
    return op;
}

bool is_scene_input(const std::string& path, bool as_points) {
    if (has_extension(path, ".json")) return true;
    return !as_points && model_has_faces(path);
}

Scene load_scene(const std::string& path) {
    if (!has_extension(path, ".json")) return mesh_file_scene(path);
    Ctx cx{path};
    const json j = io::parse_json_file(path);
    cx.known(j, "",
             {"name", "description", "room", "light", "meshes", "clouds", "sampling", "octree",
              "camera"});
    Scene sc;
    sc.path = path;
    sc.name = cx.text(j, "name", "name", fs::path(path).stem().string());
    sc.has_room = !(j.contains("room") && j["room"].is_null());
    if (sc.has_room) {
        add_walls(cx, j.value("room", json::object()), sc);
        add_light(cx, j.value("light", json::object()), sc);
    } else if (j.contains("light")) {
        cx.fail("light",
                "a light needs the room (\"room\": null); give a mesh or cloud "
                "\"emission\" instead");
    }
    const fs::path dir = fs::path(path).parent_path();
    for (const char* key : {"meshes", "clouds"}) {
        const json list = j.value(key, json::array());
        if (!list.is_array()) cx.fail(key, "expected an array");
        for (size_t i = 0; i < list.size(); ++i) {
            const std::string f = fmt::format("{}[{}]", key, i);
            if (key[0] == 'm') {
                add_mesh(cx, list[i], f, dir, sc);
            } else {
                add_cloud(cx, list[i], f, dir, sc);
            }
        }
    }
    read_sampling(cx, j, sc);
    read_octree(cx, j, sc);
    read_camera(cx, j, sc);
    if (!sc.has_room) set_extent(path, sc);
    return sc;
}

double scene_area(const Scene& sc) {
    double area = 0;
    for (const SceneSurface& s : sc.surfaces)
        for (const auto& t : s.mesh.triangles) {
            const Vec3 a = s.mesh.vertices[t[0]], b = s.mesh.vertices[t[1]],
                       c = s.mesh.vertices[t[2]];
            area += 0.5 * length(cross(b - a, c - a));
        }
    return area;
}

}  // namespace vmap
