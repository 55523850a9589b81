// Choosing a reader by file extension, and telling meshes from point clouds.
// vec.h calls isfinite unqualified, which <cmath> alone does not declare globally (libstdc++);
// <math.h> does, so it must come first. Remove once vec.h includes what it uses.
// clang-format off
#include <math.h>
// clang-format on

#include <algorithm>
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

ModelData read_model(const std::string& path) {
    io::check_input_path(path);  // a FIFO would block the reader, a folder fail obscurely
    switch (kind_of(path)) {
        case Kind::kPly:
            return read_ply(path);
        case Kind::kOff:
            return read_off(path);
        case Kind::kXyz:
            return read_xyz(path);
        case Kind::kPcd:
            return read_pcd(path);
        case Kind::kObj:
            return read_obj(path);
        case Kind::kStl:
            return read_stl(path);
    }
    return {};
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
