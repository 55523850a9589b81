// ASCII point lists: .xyz, .xyzn, .xyzrgb (Open3D), .pts (Leica/Open3D: a count line, then
// "x y z [intensity] [r g b]"), .asc/.csv/.xyz (CloudCompare: any separator, an optional
// "//X,Y,Z,..." header line, columns in the order point, colour, scalar fields, normal).
//
// Without a header line the number of columns decides what they hold:
//   3: x y z
//   4: x y z, a scalar (intensity) that is skipped
//   6: x y z nx ny nz (.xyzn) or x y z r g b (.xyzrgb, .pts); for other extensions colours when
//      the three are integers, normals when they form a unit vector, otherwise an error
//   7: x y z intensity r g b (the PTS layout)
//   9: x y z r g b nx ny nz (CloudCompare's order)
// anything else asks for a header line.
#include <algorithm>
#include <cmath>
#include <filesystem>
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

constexpr std::string_view kSeparators = ",;";

// Column index of each value, -1 where the file has none.
struct Layout {
    size_t columns = 0;
    int xyz[3] = {-1, -1, -1};
    int normal[3] = {-1, -1, -1};
    int color[3] = {-1, -1, -1};
    int emission[3] = {-1, -1, -1};
    std::vector<std::string> ignored;  // names of the columns skipped
    size_t guessed_at = 0;             // line whose values chose colours or normals, if guessed
};

bool is_integer_token(std::string_view t) {
    int64_t v = 0;
    return parse_int(t, v);
}

bool is_number_token(std::string_view t) {
    double v = 0;
    return !t.empty() && parse_real(t, v);
}

void set_triple(int (&slot)[3], int first) {
    for (int k = 0; k < 3; ++k) slot[k] = first + k;
}

// The column named `name` ("X", "Nx", "normal_x", "R", "red", "emission_r", ...) into `layout`.
bool assign_named(std::string name, int column, Layout& layout) {
    name = detail::lower(name);
    struct Name {
        std::string_view name;
        int (Layout::*slot)[3];
        int k;
    };
    static const Name kNames[] = {
        {"x", &Layout::xyz, 0},
        {"y", &Layout::xyz, 1},
        {"z", &Layout::xyz, 2},
        {"nx", &Layout::normal, 0},
        {"ny", &Layout::normal, 1},
        {"nz", &Layout::normal, 2},
        {"normal_x", &Layout::normal, 0},
        {"normal_y", &Layout::normal, 1},
        {"normal_z", &Layout::normal, 2},
        {"r", &Layout::color, 0},
        {"g", &Layout::color, 1},
        {"b", &Layout::color, 2},
        {"red", &Layout::color, 0},
        {"green", &Layout::color, 1},
        {"blue", &Layout::color, 2},
        {"emission_r", &Layout::emission, 0},
        {"emission_g", &Layout::emission, 1},
        {"emission_b", &Layout::emission, 2},
    };
    for (const Name& n : kNames) {
        if (n.name != name) continue;
        int& slot = (layout.*n.slot)[n.k];
        if (slot >= 0) return false;
        slot = column;
        return true;
    }
    layout.ignored.push_back(name);
    return true;
}

// A header line: "//X,Y,Z,R,G,B" (CloudCompare) or a first line of names ("x,y,z,nx,ny,nz").
Layout layout_from_header(const InputFile& in, std::string_view line) {
    if (line.substr(0, 2) == "//") line.remove_prefix(2);
    std::vector<std::string_view> names;
    detail::split_fields(line, kSeparators, names);
    Layout layout;
    layout.columns = names.size();
    for (size_t c = 0; c < names.size(); ++c) {
        std::string name(names[c]);
        name.erase(std::remove(name.begin(), name.end(), '"'), name.end());
        if (!assign_named(name, static_cast<int>(c), layout)) {
            fail(in.path(), "line ", in.line(), ": column ", quoted(name), " named twice");
        }
    }
    for (int k = 0; k < 3; ++k) {
        if (layout.xyz[k] < 0) fail(in.path(), "line ", in.line(), ": no '", "xyz"[k], "' column");
    }
    auto all_or_none = [&](const int(&slot)[3], const char* what) {
        const int n = (slot[0] >= 0) + (slot[1] >= 0) + (slot[2] >= 0);
        if (n != 0 && n != 3) {
            fail(in.path(), "line ", in.line(), ": only ", n, " of the 3 ", what, " columns");
        }
    };
    all_or_none(layout.normal, "normal (nx, ny, nz)");
    all_or_none(layout.color, "colour (r, g, b)");
    all_or_none(layout.emission, "emission (emission_r, emission_g, emission_b)");
    return layout;
}

double norm3(const Vec3& n) { return std::sqrt(double(dot(n, n))); }

// Six columns in a file whose extension does not say: a unit vector is a normal, other integers
// are colours. Reader::add checks every later line against the guess.
bool six_columns_are_colours(const InputFile& in, const std::vector<std::string_view>& w) {
    float n[3];
    for (int k = 0; k < 3; ++k) {
        if (!parse_real(w[3 + k], n[k])) {
            fail(in.path(), "line ", in.line(), ": column ", 4 + k, ": invalid number ",
                 quoted(w[3 + k]));
        }
    }
    if (std::fabs(norm3({n[0], n[1], n[2]}) - 1) < 0.01) return false;
    if (is_integer_token(w[3]) && is_integer_token(w[4]) && is_integer_token(w[5])) return true;
    fail(in.path(), "line ", in.line(),
         ": columns 4-6 are neither colours (integers 0..255) nor a unit normal; name the columns "
         "with a first line such as //X,Y,Z,Nx,Ny,Nz");
}

Layout layout_from_count(const InputFile& in, const std::string& ext,
                         const std::vector<std::string_view>& w) {
    Layout layout;
    layout.columns = w.size();
    set_triple(layout.xyz, 0);
    switch (w.size()) {
        case 3:
            break;
        case 4:
            layout.ignored.push_back("column 4 (intensity)");
            break;
        case 6: {
            const bool told = ext == ".xyzrgb" || ext == ".pts" || ext == ".xyzn";
            const bool colours = told ? ext != ".xyzn" : six_columns_are_colours(in, w);
            if (!told) layout.guessed_at = in.line();
            set_triple(colours ? layout.color : layout.normal, 3);
            break;
        }
        case 7:
            layout.ignored.push_back("column 4 (intensity)");
            set_triple(layout.color, 4);
            break;
        case 9:
            set_triple(layout.color, 3);
            set_triple(layout.normal, 6);
            break;
        default:
            fail(in.path(), "line ", in.line(), ": ", w.size(),
                 " columns: cannot tell what they hold; name them with a first line such as "
                 "//X,Y,Z,R,G,B,Nx,Ny,Nz");
    }
    return layout;
}

struct Reader {
    explicit Reader(InputFile& file) : in(file) {}
    InputFile& in;
    Layout layout;
    ModelData out;
    bool colours_all_integers = true;
    float max_colour = 0;
    bool shift = false;  // out.points.origin is not zero

    template <class T = float>
    T value(const std::vector<std::string_view>& w, int column, const char* what) {
        T v = 0;
        if (!parse_real(w[column], v)) {
            fail(in.path(), "line ", in.line(), ": ", what, ": invalid number ", quoted(w[column]));
        }
        if (!std::isfinite(v)) {
            fail(in.path(), "line ", in.line(), ": ", what, ": non-finite value ",
                 quoted(w[column]));
        }
        return v;
    }

    Vec3 triple(const std::vector<std::string_view>& w, const int (&slot)[3], const char* what) {
        return {value(w, slot[0], what), value(w, slot[1], what), value(w, slot[2], what)};
    }

    void add(const std::vector<std::string_view>& w) {
        if (w.size() != layout.columns) {
            fail(in.path(), "line ", in.line(), ": expected ", layout.columns, " values, found ",
                 w.size());
        }
        PointSet& p = out.points;
        if (shift) {  // in double, relative to read_xyz's origin (a survey's millions of units)
            const int(&xyz)[3] = layout.xyz;
            const std::array<double, 3>& o = p.origin;
            const Vec3 pos{float(value<double>(w, xyz[0], "coordinate") - o[0]),
                           float(value<double>(w, xyz[1], "coordinate") - o[1]),
                           float(value<double>(w, xyz[2], "coordinate") - o[2])};
            if (!is_finite(pos)) fail(in.path(), "line ", in.line(), ": coordinate: out of range");
            p.positions.push_back(pos);
        } else {
            p.positions.push_back(triple(w, layout.xyz, "coordinate"));
        }
        if (layout.normal[0] >= 0) {
            p.normals.push_back(triple(w, layout.normal, "normal"));
            if (layout.guessed_at != 0 && std::fabs(norm3(p.normals.back()) - 1) >= 0.01) {
                fail(in.path(), "line ", in.line(),
                     ": columns 4-6 are not a unit normal as on line ", layout.guessed_at,
                     "; name the columns with a first line such as //X,Y,Z,R,G,B");
            }
        }
        if (layout.color[0] >= 0) {
            const Vec3 c = triple(w, layout.color, "colour");
            if (c.x < 0 || c.y < 0 || c.z < 0) {
                fail(in.path(), "line ", in.line(), ": colour: negative value");
            }
            for (int k = 0; k < 3; ++k) {
                const bool integer = is_integer_token(w[layout.color[k]]);
                if (layout.guessed_at != 0 && !integer) {
                    fail(in.path(), "line ", in.line(),
                         ": columns 4-6 are not integer colours as on line ", layout.guessed_at,
                         "; name the columns with a first line such as //X,Y,Z,Nx,Ny,Nz");
                }
                colours_all_integers &= integer;
            }
            max_colour = std::max({max_colour, c.x, c.y, c.z});
            p.colors.push_back(c);
        }
        if (layout.emission[0] >= 0) {
            const Vec3 e = triple(w, layout.emission, "emission");
            if (e.x < 0 || e.y < 0 || e.z < 0) {
                fail(in.path(), "line ", in.line(), ": emission: negative value");
            }
            p.emission.push_back(e);
        }
    }

    // Integers, or any value above 1, mean 0..255 (CloudCompare); floats up to 1 are 0..1
    // (Open3D).
    void finish_colours() {
        if (out.points.colors.empty()) return;
        if (!colours_all_integers && max_colour <= 1) return;
        if (max_colour > 255) {
            fail(in.path(), "colour value ", max_colour, " above 255");
        }
        for (Vec3& c : out.points.colors) c = c / 255.0f;
    }
};

}  // namespace

ModelData read_xyz(const std::string& path, const std::array<double, 3>& origin) try {
    InputFile in(path);
    if (in.size() == 0) fail(path, "empty file");
    const std::string ext = detail::lower(std::filesystem::path(path).extension().string());
    Reader r(in);
    r.out.points.origin = origin;
    r.shift = origin != std::array<double, 3>{0, 0, 0};
    std::string_view line;
    std::vector<std::string_view> words;
    bool have_layout = false, first = true;
    int64_t promised = -1;
    size_t promised_line = 0;
    while (in.next_line(line)) {
        const size_t start = line.find_first_not_of(" \t");
        if (start == std::string_view::npos || line[start] == '#') continue;
        line.remove_prefix(start);
        detail::split_fields(line, kSeparators, words);
        if (words.empty()) continue;
        const bool is_first = first;
        first = false;
        if (line.substr(0, 2) == "//" || (is_first && !is_number_token(words[0]))) {
            if (have_layout) continue;  // a comment
            r.layout = layout_from_header(in, line);
            have_layout = true;
            continue;
        }
        if (is_first && words.size() == 1 && is_integer_token(words[0])) {
            // A PTS point count: checked against the file's size and, at the end, the points.
            parse_int(words[0], promised);
            promised_line = in.line();
            if (promised < 0) fail(path, "line ", in.line(), ": negative point count ", promised);
            if (static_cast<uint64_t>(promised) > in.size() / 6) {
                fail(path, "line ", in.line(), ": ", promised, " points cannot fit in the ",
                     in.size(), " bytes of the file");
            }
            continue;
        }
        if (!have_layout) {
            r.layout = layout_from_count(in, ext, words);
            have_layout = true;
        }
        r.add(words);
    }
    if (promised >= 0 && static_cast<uint64_t>(promised) != r.out.points.size()) {
        fail(path, "line ", promised_line, ": the count says ", promised, " points, the file has ",
             r.out.points.size());
    }
    r.finish_colours();
    if (!r.layout.ignored.empty()) {
        std::string names;
        for (const std::string& n : r.layout.ignored) names += (names.empty() ? "" : ", ") + n;
        r.out.notes.push_back(path + ": ignored " + names);
    }
    return std::move(r.out);
} catch (const std::bad_alloc&) {
    fail(path, "out of memory while reading");
}

}  // namespace vmap
