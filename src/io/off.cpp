// OFF reading (OFF, COFF, NOFF and CNOFF headers; ascii only).
//
// Like the PLY reader, the file is read whole and split into lines in place, one vertex or face
// per line, so that a short line is reported with the line it is on.

#include <algorithm>
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

}  // namespace

ModelData read_off(const std::string& path) try {
    const FileBuffer file = load_file(path);
    if (file.size == 0) fail(path, "empty file");
    LineReader lines(file.begin(), file.end());
    std::vector<std::string_view> tokens;
    if (!lines.next(tokens)) fail(path, "header: bad magic (no 'OFF' line, only comments)");

    const std::string_view keyword = tokens[0];
    const bool has_colors = keyword == "COFF" || keyword == "CNOFF";
    const bool has_normals = keyword == "NOFF" || keyword == "CNOFF";
    if (!has_colors && !has_normals && keyword != "OFF") {
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
    const int64_t vertex_count = parse_count(path, counts[0], "vertex");
    const int64_t face_count = parse_count(path, counts[1], "face");
    if (counts.size() > 2) parse_count(path, counts[2], "edge");

    // A corrupt count must not become a huge allocation: a vertex line is at least "0 0 0\n"
    // and a face line at least "3 0 0 0\n" (the last line may lack its newline).
    const uint64_t room = lines.remaining() + 1;
    if (static_cast<uint64_t>(vertex_count) > room / 6 ||
        static_cast<uint64_t>(face_count) > (room - 6 * static_cast<uint64_t>(vertex_count)) / 8) {
        fail(path, "truncated: ", vertex_count,
             vertex_count == 1 ? " vertex and " : " vertices and ", face_count,
             face_count == 1 ? " face" : " faces", " cannot fit in the ", lines.remaining(),
             " bytes after the header");
    }

    ModelData out;
    PointSet& points = out.points;
    points.positions.reserve(vertex_count);
    if (has_normals) points.normals.reserve(vertex_count);
    if (has_colors) points.colors.reserve(vertex_count);
    const size_t needed_values = 3 + (has_normals ? 3 : 0) + (has_colors ? 3 : 0);
    float max_channel = 0;
    bool extra_vertex_values = false, extra_face_values = false;
    for (int64_t i = 0; i < vertex_count; ++i) {
        if (!lines.next(tokens)) {
            fail(path, "truncated: expected ", vertex_count, " vertices, found ", i);
        }
        // Extra values (alpha, texture coordinates) are allowed, ignored and noted.
        extra_vertex_values |= tokens.size() > needed_values;
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
        const Vec3 p{v[0], v[1], v[2]};
        if (!is_finite(p)) {
            fail(path, "vertex ", i, " (line ", lines.line(), "): non-finite coordinate (", p.x,
                 ", ", p.y, ", ", p.z, ")");
        }
        points.positions.push_back(p);
        size_t next = 3;
        if (has_normals) {
            const Vec3 n{v[3], v[4], v[5]};
            if (!is_finite(n)) {
                fail(path, "vertex ", i, " (line ", lines.line(), "): non-finite normal (", n.x,
                     ", ", n.y, ", ", n.z, ")");
            }
            points.normals.push_back(n);
            next = 6;
        }
        if (has_colors) {
            const Vec3 c{v[next], v[next + 1], v[next + 2]};
            if (!is_finite(c)) {
                fail(path, "vertex ", i, " (line ", lines.line(), "): non-finite colour (", c.x,
                     ", ", c.y, ", ", c.z, ")");
            }
            max_channel = std::max({max_channel, c.x, c.y, c.z});
            points.colors.push_back(c);
        }
    }
    // OFF does not say whether colours are 0..1 floats or 0..255 integers; writers use both.
    // Any channel above 1 can only mean the latter.
    if (max_channel > 1.0f) {
        for (Vec3& c : points.colors) c = c / 255.0f;
    }

    out.triangles.reserve(face_count);
    for (int64_t f = 0; f < face_count; ++f) {
        if (!lines.next(tokens)) {
            fail(path, "truncated: expected ", face_count, " faces, found ", f);
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
        // Values after the indices (a face colour) are allowed, ignored and noted.
        extra_face_values |= tokens.size() - 1 > static_cast<uint64_t>(corners);
        if (tokens.size() - 1 < static_cast<uint64_t>(corners)) {
            fail(path, "face ", f, " (line ", lines.line(), "): expected ", corners + 1,
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
            if (v < 0 || v >= vertex_count || v > int64_t{UINT32_MAX}) {
                fail(path, "face ", f, " (line ", lines.line(), "): vertex index ", v,
                     " out of range (", vertex_count, " vertices)");
            }
            const uint32_t u = static_cast<uint32_t>(v);
            if (k == 0) {
                index[0] = u;
            } else if (k >= 2) {
                out.triangles.push_back({index[0], index[1], u});
            }
            index[1] = u;
        }
    }
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
