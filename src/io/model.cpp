// Choosing a reader by file extension, and telling meshes from point clouds.
// vec.h calls isfinite unqualified, which <cmath> alone does not declare globally (libstdc++);
// <math.h> does, so it must come first. Remove once vec.h includes what it uses.
// clang-format off
#include <math.h>
// clang-format on

#include <algorithm>
#include <cmath>
#include <cctype>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "io/line_reader.h"
#include "vmap/error.h"
#include "vmap/files.h"
#include "vmap/io.h"

namespace vmap {
namespace {

using detail::InputFile;

enum class Kind { kPly, kOff, kXyz, kPcd, kObj, kStl };

constexpr const char* kKnown =
    ".ply, .off, .xyz, .xyzn, .xyzrgb, .pts, .asc, .csv, .pcd, .obj or .stl";

Kind kind_of(const std::string& path) {
    const std::string ext = detail::lower(std::filesystem::path(path).extension().string());
    if (ext == ".ply") return Kind::kPly;
    if (ext == ".off") return Kind::kOff;
    if (ext == ".pcd") return Kind::kPcd;
    if (ext == ".obj") return Kind::kObj;
    if (ext == ".stl") return Kind::kStl;
    for (const char* e : {".xyz", ".xyzn", ".xyzrgb", ".pts", ".asc", ".csv"}) {
        if (ext == e) return Kind::kXyz;
    }
    if (ext.empty()) {
        throw Error(path + ": unknown model format (no extension; expected " + kKnown + ")");
    }
    throw Error(path + ": unknown model format '" + ext + "' (expected " + kKnown + ")");
}

// The next line's words, '#' comments cut off; false at the end.
bool next_words(InputFile& in, std::vector<std::string_view>& w) {
    std::string_view line;
    w.clear();
    while (w.empty()) {
        if (!in.next_line(line)) return false;
        line = line.substr(0, line.find('#'));
        detail::append_words(line.data(), line.data() + line.size(), w);
    }
    return true;
}

bool ply_has_faces(InputFile& in) {
    std::vector<std::string_view> w;
    while (next_words(in, w) && w[0] != "end_header") {
        if (w[0] == "element" && w.size() == 3 && w[1] == "face" && w[2] != "0") return true;
    }
    return false;
}

bool off_has_faces(InputFile& in) {
    std::vector<std::string_view> w;
    if (!next_words(in, w)) return false;
    std::vector<std::string_view> counts(w.begin() + 1, w.end());
    if (counts.empty() && next_words(in, w)) counts = w;
    return counts.size() >= 2 && counts[1] != "0";
}

bool obj_has_faces(InputFile& in) {
    std::vector<std::string_view> w;
    while (next_words(in, w)) {
        if (w[0] == "f") return true;
    }
    return false;
}

}  // namespace

namespace {

// OFF, OBJ and STL hold floats (or are read as such): their positions move to `origin` after
// reading, in double.
ModelData shifted(ModelData md, const std::array<double, 3>& origin) {
    if (origin == std::array<double, 3>{0, 0, 0}) return md;
    for (Vec3& p : md.points.positions) {
        p = {float(double(p.x) - origin[0]), float(double(p.y) - origin[1]),
             float(double(p.z) - origin[2])};
    }
    md.points.origin = origin;
    return md;
}

}  // namespace

ModelData read_model(const std::string& path, const std::array<double, 3>& origin) {
    io::check_input_path(path);  // a FIFO would block the reader, a folder fail obscurely
    switch (kind_of(path)) {
        case Kind::kPly:
            return read_ply(path, origin);
        case Kind::kOff:
            return shifted(read_off(path), origin);
        case Kind::kXyz:
            return read_xyz(path, origin);
        case Kind::kPcd:
            return read_pcd(path, origin);
        case Kind::kObj:
            return shifted(read_obj(path), origin);
        case Kind::kStl:
            return shifted(read_stl(path), origin);
    }
    return {};
}

void to_file_frame(PointSet& points) {
    const std::array<double, 3> o = points.origin;
    if (o == std::array<double, 3>{0, 0, 0}) return;
    for (Vec3& p : points.positions) p = {float(p.x + o[0]), float(p.y + o[1]), float(p.z + o[2])};
    points.origin = {0, 0, 0};
}

std::optional<std::array<double, 3>> far_origin(const std::vector<Vec3>& positions) {
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (const Vec3& p : positions) {
        const double c[3] = {p.x, p.y, p.z};
        for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], c[a]), hi[a] = std::max(hi[a], c[a]);
    }
    double extent = 0, far = 0;
    for (int a = 0; a < 3; ++a) {
        extent = std::max(extent, hi[a] - lo[a]);
        far = std::max({far, std::fabs(lo[a]), std::fabs(hi[a])});
    }
    // All at one float: the file's points may differ by less than a float step out there.
    if (extent == 0) extent = far * 0x1p-23;
    if (!(extent > 0) || !std::isfinite(far) || far <= 256 * extent) return std::nullopt;
    // A round number: the centre to a multiple of 2^k >= extent (exact in double; the cloud then
    // lies within 1.5 extents of it).
    const double step = std::ldexp(1.0, std::ilogb(extent) + 1);
    std::array<double, 3> o;
    for (int a = 0; a < 3; ++a) o[a] = std::round(0.5 * (lo[a] + hi[a]) / step) * step;
    return o;
}

// A malformed header is the reader's to report: here it only decides which path to take.
bool model_has_faces(const std::string& path) {
    io::check_input_path(path);  // never open a FIFO (it would block) or a folder
    const Kind kind = kind_of(path);
    if (kind == Kind::kXyz || kind == Kind::kPcd) return false;
    if (kind == Kind::kStl) return true;
    InputFile in(path);
    if (kind == Kind::kPly) return ply_has_faces(in);
    if (kind == Kind::kOff) return off_has_faces(in);
    return obj_has_faces(in);
}

bool has_extension(std::string_view path, std::string_view suffix) {
    if (path.size() < suffix.size()) return false;
    const std::string_view tail = path.substr(path.size() - suffix.size());
    return std::equal(tail.begin(), tail.end(), suffix.begin(), [](char a, char b) {
        return std::tolower(static_cast<unsigned char>(a)) ==
               std::tolower(static_cast<unsigned char>(b));
    });
}

}  // namespace vmap
