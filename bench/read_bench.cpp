// Reader throughput: one mesh written in every format vmap reads, each file read `runs` times
// after a warm-up; prints per format the file size, the median time and its spread (min..max),
// MB/s and vertices/s, as a Markdown table (docs/formats.md has the figures).
//   build-cpu/read_bench [MESH (default models/dragon.ply)] [--runs N (default 5)] [--dir D]
// vec.h calls isfinite unqualified; <math.h> must come first.
// clang-format off
#include <math.h>
// clang-format on

#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <charconv>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "vmap/error.h"
#include "vmap/io.h"
#include "vmap/version.h"

namespace {

namespace fs = std::filesystem;
using vmap::ModelData;
using vmap::Vec3;

std::string num(float v) {
    char b[32];
    return std::string(b, std::to_chars(b, b + sizeof b, v).ptr);
}

template <class T>
void put(std::string& out, T v) {
    char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    out.append(b, sizeof(T));
}

std::string xyz3(Vec3 p, const char* sep = " ") {
    return num(p.x) + sep + num(p.y) + sep + num(p.z);
}

// Each format's text of the mesh (point formats: the vertices with their mean face normals).
std::string as_off(const ModelData& m) {
    std::string s = fmt::format("OFF\n{} {} 0\n", m.points.size(), m.triangles.size());
    for (Vec3 p : m.points.positions) s += xyz3(p) + "\n";
    for (const auto& t : m.triangles) s += fmt::format("3 {} {} {}\n", t[0], t[1], t[2]);
    return s;
}

std::string as_obj(const ModelData& m) {
    std::string s;
    for (Vec3 p : m.points.positions) s += "v " + xyz3(p) + "\n";
    for (const auto& t : m.triangles)
        s += fmt::format("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    return s;
}

std::string as_stl(const ModelData& m, bool binary) {
    std::string s = binary ? std::string(80, ' ') : "solid bench\n";
    if (binary) put(s, uint32_t(m.triangles.size()));
    for (const auto& t : m.triangles) {
        const Vec3 a = m.points.positions[t[0]], b = m.points.positions[t[1]],
                   c = m.points.positions[t[2]];
        const Vec3 n = vmap::cross(b - a, c - a);
        if (binary) {
            for (Vec3 v : {n, a, b, c}) put(s, v.x), put(s, v.y), put(s, v.z);
            put(s, uint16_t(0));
            continue;
        }
        s += "facet normal " + xyz3(n) + "\nouter loop\n";
        for (Vec3 v : {a, b, c}) s += "vertex " + xyz3(v) + "\n";
        s += "endloop\nendfacet\n";
    }
    return binary ? s : s + "endsolid bench\n";
}

std::string as_xyzn(const ModelData& m) {
    std::string s;
    for (size_t i = 0; i < m.points.size(); ++i) {
        s += xyz3(m.points.positions[i]) + " " + xyz3(m.points.normals[i]) + "\n";
    }
    return s;
}

std::string as_pcd(const ModelData& m, const std::string& data) {
    const size_t n = m.points.size();
    std::string s = fmt::format(
        "VERSION 0.7\nFIELDS x y z normal_x normal_y normal_z\nSIZE 4 4 4 4 4 4\n"
        "TYPE F F F F F F\nCOUNT 1 1 1 1 1 1\nWIDTH {}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n"
        "POINTS {}\nDATA {}\n",
        n, n, data);
    if (data == "ascii") return s + as_xyzn(m);
    std::string body;
    if (data == "binary") {
        for (size_t i = 0; i < n; ++i)
            for (Vec3 v : {m.points.positions[i], m.points.normals[i]})
                put(body, v.x), put(body, v.y), put(body, v.z);
        return s + body;
    }
    for (int f = 0; f < 6; ++f)
        for (size_t i = 0; i < n; ++i) {
            const Vec3 v = f < 3 ? m.points.positions[i] : m.points.normals[i];
            put(body, f % 3 == 0 ? v.x : f % 3 == 1 ? v.y : v.z);
        }
    std::string z;  // LZF literal runs only: valid, and the decoder's slowest case per byte
    for (size_t k = 0; k < body.size(); k += 32) {
        const size_t len = std::min<size_t>(32, body.size() - k);
        z += char(len - 1);
        z.append(body, k, len);
    }
    put(s, uint32_t(z.size()));
    put(s, uint32_t(body.size()));
    return s + z;
}

void with_vertex_normals(ModelData& m) {
    m.points.normals.assign(m.points.size(), Vec3{});
    for (const auto& t : m.triangles) {
        const Vec3 a = m.points.positions[t[0]], b = m.points.positions[t[1]],
                   c = m.points.positions[t[2]];
        for (uint32_t k : t) m.points.normals[k] = m.points.normals[k] + vmap::cross(b - a, c - a);
    }
    for (Vec3& n : m.points.normals) {
        const float l = vmap::length(n);
        n = l > 0 ? n / l : Vec3{0, 0, 1};
    }
}

double seconds(const std::function<void()>& f) {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

int run(const std::string& mesh, int runs, const fs::path& dir) {
    ModelData m = vmap::read_model(mesh);
    with_vertex_normals(m);
    vmap::PointSet cloud = m.points;
    fs::create_directories(dir);
    struct Case {
        std::string name, file;
    };
    std::vector<Case> cases;
    auto write = [&](const std::string& name, const std::string& file, const std::string& text) {
        std::ofstream(dir / file, std::ios::binary) << text;
        cases.push_back({name, (dir / file).string()});
    };
    vmap::write_ply((dir / "cloud_bin.ply").string(), cloud, true);
    cases.push_back({"ply binary (points)", (dir / "cloud_bin.ply").string()});
    vmap::write_ply((dir / "cloud_ascii.ply").string(), cloud, false);
    cases.push_back({"ply ascii (points)", (dir / "cloud_ascii.ply").string()});
    write("off (mesh)", "mesh.off", as_off(m));
    write("obj (mesh)", "mesh.obj", as_obj(m));
    write("stl ascii (mesh)", "mesh_a.stl", as_stl(m, false));
    write("stl binary (mesh)", "mesh_b.stl", as_stl(m, true));
    write("xyzn (points)", "cloud.xyzn", as_xyzn(m));
    for (const char* d : {"ascii", "binary", "binary_compressed"}) {
        write(fmt::format("pcd {} (points)", d), fmt::format("cloud_{}.pcd", d), as_pcd(m, d));
    }
    fmt::print("mesh: {} ({} vertices, {} triangles); {} runs after a warm-up\n\n", mesh,
               m.points.size(), m.triangles.size(), runs);
    fmt::print("| format | file MB | median s | min..max s | MB/s | Mvertices/s |\n");
    fmt::print("|---|---:|---:|---:|---:|---:|\n");
    for (const Case& c : cases) {
        size_t vertices = 0;
        (void)vmap::read_model(c.file);
        std::vector<double> t;
        for (int r = 0; r < runs; ++r)
            t.push_back(seconds([&] { vertices = vmap::read_model(c.file).points.size(); }));
        std::sort(t.begin(), t.end());
        const double mb = double(fs::file_size(c.file)) / 1e6, med = t[t.size() / 2];
        fmt::print("| {} | {:.1f} | {:.3f} | {:.3f}..{:.3f} | {:.0f} | {:.2f} |\n", c.name, mb, med,
                   t.front(), t.back(), mb / med, vertices / med / 1e6);
    }
    fs::remove_all(dir);
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    std::string mesh = vmap::data_dir() + "/models/dragon.ply";
    int runs = 5;
    fs::path dir = fs::temp_directory_path() / "vmap_read_bench";
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--runs" && i + 1 < argc) {
            runs = std::max(1, std::atoi(argv[++i]));
        } else if (a == "--dir" && i + 1 < argc) {
            dir = argv[++i];
        } else if (!a.empty() && a[0] != '-') {
            mesh = a;
        } else {
            fmt::print(stderr, "usage: read_bench [MESH] [--runs N] [--dir D]\n");
            return 2;
        }
    }
    try {
        return run(mesh, runs, dir);
    } catch (const vmap::Error& e) {
        fmt::print(stderr, "read_bench: error: {}\n", e.what());
        return 1;
    }
}
