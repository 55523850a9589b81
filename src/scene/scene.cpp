// Scene files: parsing, the Cornell room, placing meshes (DESIGN.md "Scenes").
#include "vmap/scene.h"

#include <fmt/format.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "io/atomic_file.h"
#include "io/json_file.h"
#include "vmap/error.h"
#include "vmap/io.h"

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

}  // namespace

std::string default_scene_path() {
    return std::string(VMAP_SOURCE_DIR) + "/scenes/cornell-bunny.json";
}

Scene load_scene(const std::string& path) {
    Ctx cx{path};
    const json j = io::parse_json_file(path);
    cx.known(j, "",
             {"name", "description", "room", "light", "meshes", "sampling", "octree", "camera"});
    Scene sc;
    sc.path = path;
    sc.name = cx.text(j, "name", "name", fs::path(path).stem().string());

    // The Cornell room: published dimensions (552.8 x 548.8 x 559.2 mm) and wall colours.
    const json room = j.value("room", json::object());
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

    // The area light, just below the ceiling, facing down (Cornell: 130 x 105 mm, centred).
    const json light = j.value("light", json::object());
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
        SceneSurface s;
        s.name = "ceiling";
        s.albedo = albedo("ceiling", white);
        auto strip = [&](float xa, float xb, float za, float zb) {
            if (xb > xa && zb > za) add_quad(s, {xa, H, za}, {xb, H, za}, {xb, H, zb}, {xa, H, zb});
        };
        strip(0, W, 0, z0);
        strip(0, W, z1, D);
        strip(0, x0, z0, z1);
        strip(x1, W, z0, z1);
        sc.surfaces.insert(sc.surfaces.begin() + 1, std::move(s));
    }
    {
        SceneSurface s;
        s.name = "light";
        s.albedo = {0.78f, 0.78f, 0.78f};
        s.emission = light.contains("emission")
                         ? cx.vec3(light["emission"], "light.emission", 0, 1e6)
                         : Vec3{17.f, 12.f, 4.f};
        const float y = H * 0.999f;  // a hair below the ceiling, so the two never coincide
        add_quad(s, {x0, y, z0}, {x1, y, z0}, {x1, y, z1}, {x0, y, z1});
        sc.surfaces.push_back(std::move(s));
    }

    // Meshes placed in the room.
    const json meshes = j.value("meshes", json::array());
    if (!meshes.is_array()) cx.fail("meshes", "expected an array");
    const fs::path dir = fs::path(path).parent_path();
    for (size_t i = 0; i < meshes.size(); ++i) {
        const std::string f = fmt::format("meshes[{}]", i);
        const json& m = meshes[i];
        cx.known(m, f,
                 {"file", "name", "size", "scale", "rotate", "position", "albedo", "flip_normals"});
        if (!m.contains("file")) cx.fail(f + ".file", "missing");
        if (!m["file"].is_string()) cx.fail(f + ".file", "expected a string");
        const std::string rel = m["file"].get<std::string>();
        const fs::path file = fs::path(rel).is_absolute() ? fs::path(rel) : dir / rel;
        if (!fs::exists(file))
            cx.fail(f + ".file", fmt::format("{}: no such file (scripts/fetch-models.sh fetches "
                                             "the models)",
                                             file.string()));
        ModelData md;
        try {
            md = read_model(file.string());
        } catch (const Error& e) {
            cx.fail(f + ".file", e.what());
        }
        if (md.triangles.empty()) cx.fail(f + ".file", file.string() + ": has no faces");
        SceneSurface s;
        s.name = cx.text(m, "name", f + ".name", fs::path(rel).stem().string());
        s.albedo = m.contains("albedo") ? cx.vec3(m["albedo"], f + ".albedo", 0, 1)
                                        : Vec3{0.75f, 0.75f, 0.8f};
        s.mesh = md.mesh();
        // Centre the box at the origin, scale, rotate, then stand its bottom centre on position.
        Vec3 lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
        for (Vec3 v : s.mesh.vertices) {
            lo = {std::min(lo.x, v.x), std::min(lo.y, v.y), std::min(lo.z, v.z)};
            hi = {std::max(hi.x, v.x), std::max(hi.y, v.y), std::max(hi.z, v.z)};
        }
        const Vec3 mid = (lo + hi) * 0.5f;
        const float ext = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
        if (!(ext > 0) || !std::isfinite(ext))
            cx.fail(f + ".file",
                    file.string() + ": the mesh has zero extent (all vertices coincide)");
        float scale = 1;
        if (m.contains("size") && m.contains("scale")) cx.fail(f, "give size or scale, not both");
        if (m.contains("size")) scale = float(cx.number(m["size"], f + ".size", 1e-6, 1e6)) / ext;
        if (m.contains("scale")) scale = float(cx.number(m["scale"], f + ".scale", 1e-9, 1e9));
        const Vec3 rot =
            m.contains("rotate") ? cx.vec3(m["rotate"], f + ".rotate", -3600, 3600) : Vec3{};
        const Vec3 pos = m.contains("position") ? cx.vec3(m["position"], f + ".position", -1e6, 1e6)
                                                : Vec3{W / 2, 0, D / 2};
        for (Vec3& v : s.mesh.vertices) v = rotate((v - mid) * scale, rot);
        float ylo = INFINITY, xlo = INFINITY, xhi = -INFINITY, zlo = INFINITY, zhi = -INFINITY;
        for (Vec3 v : s.mesh.vertices) {
            ylo = std::min(ylo, v.y);
            xlo = std::min(xlo, v.x), xhi = std::max(xhi, v.x);
            zlo = std::min(zlo, v.z), zhi = std::max(zhi, v.z);
        }
        const Vec3 shift = pos - Vec3{(xlo + xhi) / 2, ylo, (zlo + zhi) / 2};
        for (Vec3& v : s.mesh.vertices) v = v + shift;
        // Outward normals: a closed mesh wound inside-out has negative signed volume.
        bool flip = signed_volume(s.mesh) < 0;
        if (cx.boolean(m, "flip_normals", f + ".flip_normals", false)) flip = !flip;
        if (flip)
            for (auto& t : s.mesh.triangles) std::swap(t[1], t[2]);
        sc.surfaces.push_back(std::move(s));
    }

    const json sampling = j.value("sampling", json::object());
    cx.known(sampling, "sampling", {"points", "density", "seed"});
    if (sampling.contains("points") && sampling.contains("density"))
        cx.fail("sampling", "give points or density, not both");
    if (sampling.contains("points"))
        sc.points = uint64_t(cx.number(sampling["points"], "sampling.points", 1, 5e7));
    if (sampling.contains("density")) {
        double area = 0;
        for (const auto& s : sc.surfaces)
            for (const auto& t : s.mesh.triangles) {
                const Vec3 a = s.mesh.vertices[t[0]], b = s.mesh.vertices[t[1]],
                           c = s.mesh.vertices[t[2]];
                area += 0.5 * length(cross(b - a, c - a));
            }
        const double dens = cx.number(sampling["density"], "sampling.density", 1e-6, 1e12);
        const double n = std::ceil(dens * area);
        if (n > 5e7) cx.fail("sampling.density", fmt::format("gives {} points (at most 5e7)", n));
        sc.points = uint64_t(std::max(1.0, n));
    }
    if (sampling.contains("seed"))
        sc.seed = uint64_t(cx.number(sampling["seed"], "sampling.seed", 0, 1e15));

    if (j.contains("octree")) {
        const json& o = j["octree"];
        cx.known(o, "octree", {"max_height", "leaf_points"});
        OctreeParams op;
        if (o.contains("max_height"))
            op.max_height = int(cx.number(o["max_height"], "octree.max_height", 1, 21));
        if (o.contains("leaf_points"))
            op.leaf_points = int(cx.number(o["leaf_points"], "octree.leaf_points", 1, 1e6));
        sc.octree = op;
    }

    if (j.contains("camera")) {
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
    return sc;
}

}  // namespace vmap
