// OFF reading (OFF, COFF, NOFF and CNOFF headers; ascii only).
//
// Like the PLY reader, the file is read whole and split into lines in place, one vertex or face
// per line, so that a short line is reported with the line it is on.

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstring>
#include <new>
#include <string>
#include <string_view>
#include <vector>

#include "io/text_util.h"
#include "vmap/io.h"

namespace vmap {

using detail::append_words;
using detail::fail;
using detail::FileBuffer;
using detail::load_file;
using detail::parse_int;
using detail::parse_real;
using detail::quoted;

namespace {

// ---- header --------------------------------------------------------------------------------

// Significant lines of an OFF file: '#' starts a comment, blank lines are skipped.
class LineReader {
  public:
    LineReader(const char* begin, const char* end) : p_(begin), end_(end) {}

    bool next(std::vector<std::string_view>& tokens) {
        tokens.clear();
        while (p_ != end_ && tokens.empty()) {
            const char* eol = static_cast<const char*>(std::memchr(p_, '\n', end_ - p_));
            if (eol == nullptr) eol = end_;
            ++line_;
            const char* hash = static_cast<const char*>(std::memchr(p_, '#', eol - p_));
            const char* stop = hash == nullptr ? eol : hash;
            append_words(p_, stop, tokens);
            p_ = eol == end_ ? end_ : eol + 1;
        }
        return !tokens.empty();
    }

    size_t line() const { return line_; }
    size_t remaining() const { return static_cast<size_t>(end_ - p_); }

  private:
    const char* p_;
    const char* end_;
    size_t line_ = 0;
};

int64_t parse_count(const std::string& path, std::string_view token, const char* what) {
    int64_t n = 0;
    if (!parse_int(token, n)) fail(path, "header: invalid ", what, " count ", quoted(token));
    if (n < 0) fail(path, "header: negative ", what, " count ", n);
    return n;
}

struct OffHeader {
    bool has_colors = false, has_normals = false;
    int64_t vertices = 0, faces = 0;
};

// The keyword and the counts, checked against the bytes left: a corrupt count must not become
// a huge allocation.
OffHeader read_header(const std::string& path, LineReader& lines) {
    std::vector<std::string_view> tokens;
    if (!lines.next(tokens)) fail(path, "header: bad magic (no 'OFF' line, only comments)");
    OffHeader h;
    const std::string_view keyword = tokens[0];
    h.has_colors = keyword == "COFF" || keyword == "CNOFF";
    h.has_normals = keyword == "NOFF" || keyword == "CNOFF";
    if (!h.has_colors && !h.has_normals && keyword != "OFF") {
        fail(path, "header: bad magic ", quoted(keyword), " (expected OFF, COFF, NOFF or CNOFF)");
    }
    // The counts may follow the keyword on the same line or have a line of their own.
    std::vector<std::string_view> counts(tokens.begin() + 1, tokens.end());
    if (!counts.empty() && counts[0] == "BINARY") fail(path, "header: binary OFF is not supported");
    if (counts.empty()) {
        if (!lines.next(tokens)) fail(path, "header: missing vertex, face and edge counts");
        counts = tokens;
    }
    // The edge count is informative only and some writers leave it out.
    if (counts.size() < 2) {
        fail(path, "header: expected vertex, face and edge counts, found ", counts.size(), " value",
             counts.size() == 1 ? "" : "s");
    }
    h.vertices = parse_count(path, counts[0], "vertex");
    h.faces = parse_count(path, counts[1], "face");
    if (counts.size() > 2) parse_count(path, counts[2], "edge");
    // A vertex line is at least "0 0 0\n" and a face line at least "3 0 0 0\n" (the last line
    // may lack its newline).
    const uint64_t room = lines.remaining() + 1;
    if (static_cast<uint64_t>(h.vertices) > room / 6 ||
        static_cast<uint64_t>(h.faces) > (room - 6 * static_cast<uint64_t>(h.vertices)) / 8) {
        fail(path, "truncated: ", h.vertices, h.vertices == 1 ? " vertex and " : " vertices and ",
             h.faces, h.faces == 1 ? " face" : " faces", " cannot fit in the ", lines.remaining(),
             " bytes after the header");
    }
    return h;
}

// Three values of a vertex line (v[0..2]) as a finite vector, else the error naming `what`.
Vec3 finite_triple(const std::string& path, const float* v, int64_t i, size_t line,
                   const char* what) {
    const Vec3 x{v[0], v[1], v[2]};
    if (!is_finite(x))
        fail(path, "vertex ", i, " (line ", line, "): non-finite ", what, " (", x.x, ", ", x.y,
             ", ", x.z, ")");
    return x;
}

// The vertices (positions, and normals and colours when the keyword says so); true when a
// line carried values beyond those (alpha, texture coordinates: ignored).
bool read_vertices(const std::string& path, const OffHeader& h, LineReader& lines,
                   PointSet& points) {
    std::vector<std::string_view> tokens;
    points.positions.reserve(h.vertices);
    if (h.has_normals) points.normals.reserve(h.vertices);
    if (h.has_colors) points.colors.reserve(h.vertices);
    const size_t needed_values = 3 + (h.has_normals ? 3 : 0) + (h.has_colors ? 3 : 0);
    float max_channel = 0;
    bool extra = false;
    for (int64_t i = 0; i < h.vertices; ++i) {
        if (!lines.next(tokens)) {
            fail(path, "truncated: expected ", h.vertices, " vertices, found ", i);
        }
        extra |= tokens.size() > needed_values;
        if (tokens.size() < needed_values) {
            fail(path, "vertex ", i, " (line ", lines.line(), "): expected ", needed_values,
                 " values, found ", tokens.size());
        }
        float v[9];
        for (size_t k = 0; k < needed_values; ++k) {
            if (!parse_real(tokens[k], v[k])) {
                fail(path, "vertex ", i, " (line ", lines.line(), "): invalid number ",
                     quoted(tokens[k]));
            }
        }
        points.positions.push_back(finite_triple(path, v, i, lines.line(), "coordinate"));
        const size_t next = h.has_normals ? 6 : 3;
        if (h.has_normals)
            points.normals.push_back(finite_triple(path, v + 3, i, lines.line(), "normal"));
        if (h.has_colors) {
            const Vec3 c = finite_triple(path, v + next, i, lines.line(), "colour");
            max_channel = std::max({max_channel, c.x, c.y, c.z});
            points.colors.push_back(c);
        }
    }
    // OFF does not say whether colours are 0..1 floats or 0..255 integers; writers use both.
    // Any channel above 1 can only mean the latter.
    if (max_channel > 1.0f) {
        for (Vec3& c : points.colors) c = c / 255.0f;
    }
    return extra;
}

// The faces as a fan of triangles each; true when a line carried values after its indices (a
// face colour: ignored).
bool read_faces(const std::string& path, const OffHeader& h, LineReader& lines,
                std::vector<std::array<uint32_t, 3>>& triangles) {
    std::vector<std::string_view> tokens;
    triangles.reserve(h.faces);
    bool extra = false;
    for (int64_t f = 0; f < h.faces; ++f) {
        if (!lines.next(tokens)) {
            fail(path, "truncated: expected ", h.faces, " faces, found ", f);
        }
        int64_t corners = 0;
        if (!parse_int(tokens[0], corners)) {
            fail(path, "face ", f, " (line ", lines.line(), "): invalid vertex count ",
                 quoted(tokens[0]));
        }
        if (corners < 3) {
            fail(path, "face ", f, " (line ", lines.line(), "): degenerate face with ", corners,
                 corners == 1 ? " vertex" : " vertices");
        }
        extra |= tokens.size() - 1 > static_cast<uint64_t>(corners);
        if (tokens.size() - 1 < static_cast<uint64_t>(corners)) {
            fail(path, "face ", f, " (line ", lines.line(), "): expected ",
                 static_cast<uint64_t>(corners) + 1,
                 " values, found ", tokens.size());
        }
        uint32_t index[2] = {};
        for (int64_t k = 0; k < corners; ++k) {
            int64_t v = 0;
            if (!parse_int(tokens[k + 1], v)) {
                fail(path, "face ", f, " (line ", lines.line(), "): invalid vertex index ",
                     quoted(tokens[k + 1]));
            }
            // Triangles hold 32-bit indices; only a file of tens of GB could exceed them.
            if (v < 0 || v >= h.vertices || v > int64_t{UINT32_MAX}) {
                fail(path, "face ", f, " (line ", lines.line(), "): vertex index ", v,
                     " out of range (", h.vertices, " vertices)");
            }
            const uint32_t u = static_cast<uint32_t>(v);
            if (k == 0) {
                index[0] = u;
            } else if (k >= 2) {
                triangles.push_back({index[0], index[1], u});
            }
            index[1] = u;
        }
    }
    return extra;
}

}  // namespace

ModelData read_off(const std::string& path) try {
    const FileBuffer file = load_file(path);
    if (file.size == 0) fail(path, "empty file");
    LineReader lines(file.begin(), file.end());
    const OffHeader h = read_header(path, lines);
    ModelData out;
    const bool extra_vertex_values = read_vertices(path, h, lines, out.points);
    const bool extra_face_values = read_faces(path, h, lines, out.triangles);
    if (extra_vertex_values)
        out.notes.push_back(path +
                            ": ignored extra values on vertex lines (alpha, texture coordinates)");
    if (extra_face_values) out.notes.push_back(path + ": ignored values after the faces' indices");
    return out;
} catch (const std::bad_alloc&) {
    // Counts are checked against the file size, so only a file too big for memory gets here.
    fail(path, "out of memory while reading");
}

}  // namespace vmap
