// Wavefront OBJ, the geometry part: "v", "vn" and "f" lines (polygons fan-triangulated, indices
// 1-based, negative ones counted back from the last vertex defined so far). Texture
// coordinates, lines, points, groups, materials, smoothing and free-form statements are skipped;
// an unknown statement is an error (a file that is not OBJ).
#include <array>
#include <cmath>
#include <cstdint>
#include <new>
#include <string>
#include <string_view>
#include <vector>

#include "io/line_reader.h"
#include "vmap/io.h"

namespace vmap {

using detail::fail;
using detail::InputFile;
using detail::parse_int;
using detail::parse_real;
using detail::quoted;

namespace {

bool skipped_statement(std::string_view k) {
    static constexpr std::string_view kSkipped[] = {
        "vt",     "vp",     "l",          "p",         "o",     "g",     "s",     "usemtl",
        "mtllib", "cstype", "deg",        "bmat",      "step",  "curv",  "curv2", "surf",
        "parm",   "trim",   "hole",       "scrv",      "sp",    "end",   "con",   "mg",
        "call",   "csh",    "shadow_obj", "trace_obj", "ctech", "stech", "lod",   "maplib",
        "usemap", "bevel",  "c_interp",   "d_interp",
    };
    for (std::string_view s : kSkipped)
        if (s == k) return true;
    return false;
}

struct ObjReader {
    explicit ObjReader(InputFile& file) : in(file) {}
    InputFile& in;
    ModelData out;
    std::vector<Vec3> vn;
    std::vector<Vec3> vertex_normal;  // per vertex, from the face corners that name one
    std::vector<uint8_t> has_normal;
    size_t coloured = 0;  // vertices with "v x y z r g b"
    std::vector<uint32_t> corners;

    float number(std::string_view t, const char* what) {
        float v = 0;
        if (!parse_real(t, v))
            fail(in.path(), "line ", in.line(), ": ", what, ": invalid number ", quoted(t));
        if (!std::isfinite(v))
            fail(in.path(), "line ", in.line(), ": ", what, ": non-finite ", quoted(t));
        return v;
    }

    void vertex(const std::vector<std::string_view>& w) {
        // v x y z | v x y z w | v x y z r g b (MeshLab's vertex colours, 0..1)
        if (w.size() != 4 && w.size() != 5 && w.size() != 7) {
            fail(in.path(), "line ", in.line(), ": v: expected 3, 4 or 6 numbers, found ",
                 w.size() - 1);
        }
        out.points.positions.push_back({number(w[1], "v"), number(w[2], "v"), number(w[3], "v")});
        if (w.size() == 5) number(w[4], "v (w)");
        if (w.size() == 7) {
            const Vec3 c{number(w[4], "v colour"), number(w[5], "v colour"),
                         number(w[6], "v colour")};
            if (c.x < 0 || c.y < 0 || c.z < 0 || c.x > 1 || c.y > 1 || c.z > 1) {
                fail(in.path(), "line ", in.line(), ": v: colour outside 0..1");
            }
            out.points.colors.resize(out.points.positions.size() - 1);
            out.points.colors.push_back(c);
            ++coloured;
        }
    }

    void normal(const std::vector<std::string_view>& w) {
        if (w.size() != 4) {
            fail(in.path(), "line ", in.line(), ": vn: expected 3 numbers, found ", w.size() - 1);
        }
        vn.push_back({number(w[1], "vn"), number(w[2], "vn"), number(w[3], "vn")});
    }

    // A 1-based or negative (relative) index into a list of `size` items.
    uint32_t index(std::string_view t, size_t size, const char* what) {
        int64_t i = 0;
        if (!parse_int(t, i)) {
            fail(in.path(), "line ", in.line(), ": f: invalid ", what, " index ", quoted(t));
        }
        const int64_t resolved = i < 0 ? int64_t(size) + i : i - 1;
        if (i == 0 || resolved < 0 || resolved >= int64_t(size)) {
            fail(in.path(), "line ", in.line(), ": f: ", what, " index ", i, " out of range (",
                 size, " defined so far)");
        }
        return static_cast<uint32_t>(resolved);
    }

    void corner(std::string_view t) {
        const size_t s1 = t.find('/');
        const uint32_t v = index(t.substr(0, s1), out.points.positions.size(), "vertex");
        corners.push_back(v);
        if (s1 == std::string_view::npos) return;
        const size_t s2 = t.find('/', s1 + 1);
        if (s2 == std::string_view::npos) return;  // i/t
        const uint32_t n = index(t.substr(s2 + 1), vn.size(), "normal");
        if (vertex_normal.size() <= v) {
            vertex_normal.resize(out.points.positions.size());
            has_normal.resize(out.points.positions.size());
        }
        vertex_normal[v] = vn[n];
        has_normal[v] = 1;
    }

    void face(const std::vector<std::string_view>& w) {
        if (w.size() < 4) {
            fail(in.path(), "line ", in.line(), ": f: degenerate face with ", w.size() - 1,
                 w.size() == 2 ? " vertex" : " vertices");
        }
        corners.clear();
        for (size_t k = 1; k < w.size(); ++k) corner(w[k]);
        for (size_t k = 1; k + 1 < corners.size(); ++k) {
            out.triangles.push_back({corners[0], corners[k], corners[k + 1]});
        }
    }

    void finish() {
        PointSet& p = out.points;
        const size_t n = p.size();
        if (coloured != 0 && coloured != n) {
            p.colors.clear();
            out.notes.push_back(in.path() + ": ignored vertex colours (" +
                                std::to_string(coloured) + " of " + std::to_string(n) +
                                " vertices have one)");
        }
        size_t with_normal = 0;
        for (uint8_t h : has_normal) with_normal += h;
        if (n > 0 && with_normal == n) {
            p.normals = std::move(vertex_normal);
            p.normals.resize(n);
        } else if (!vn.empty()) {
            out.notes.push_back(in.path() + ": ignored vn normals (" + std::to_string(with_normal) +
                                " of " + std::to_string(n) + " vertices have one)");
        }
    }
};

}  // namespace

ModelData read_obj(const std::string& path) try {
    InputFile in(path);
    if (in.size() == 0) fail(path, "empty file");
    ObjReader r(in);
    std::string_view line;
    std::vector<std::string_view> w;
    while (in.next_line(line)) {
        const size_t hash = line.find('#');
        if (hash != std::string_view::npos) line = line.substr(0, hash);
        w.clear();
        detail::append_words(line.data(), line.data() + line.size(), w);
        if (w.empty()) continue;
        if (w[0] == "v") {
            r.vertex(w);
        } else if (w[0] == "vn") {
            r.normal(w);
        } else if (w[0] == "f") {
            r.face(w);
        } else if (!skipped_statement(w[0])) {
            fail(path, "line ", in.line(), ": unknown statement ", quoted(w[0]));
        }
    }
    r.finish();
    return std::move(r.out);
} catch (const std::bad_alloc&) {
    fail(path, "out of memory while reading");
}

}  // namespace vmap
