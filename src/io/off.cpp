// OFF reading (OFF, COFF, NOFF and CNOFF headers; ascii only).
//
// Like the PLY reader, the file is read whole and split into lines in place, one vertex or face
// per line, so that a short line is reported with the line it is on.
//
// The small file and number helpers are the same as in ply.cpp; they stay private to each
// reader rather than grow an internal header for a few lines.

// vec.h calls isfinite unqualified, which <cmath> alone does not declare globally (libstdc++);
// <math.h> does, so it must come first. Remove once vec.h includes what it uses.
// clang-format off
#include <math.h>
// clang-format on

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <new>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "vmap/error.h"
#include "vmap/io.h"

namespace vmap {
namespace {

template <class... Parts>
[[noreturn]] void fail(const std::string& path, const Parts&... parts) {
    std::ostringstream out;
    out << path << ": ";
    (out << ... << parts);
    throw Error(out.str());
}

// Tokens from a broken or binary file end up in messages; keep those one short printable line.
std::string quoted(std::string_view text) {
    constexpr size_t kMax = 32;
    std::string out = "'";
    for (size_t i = 0; i < text.size() && i < kMax; ++i) {
        const unsigned char c = static_cast<unsigned char>(text[i]);
        out += (c >= 0x20 && c < 0x7f) ? static_cast<char>(c) : '?';
    }
    if (text.size() > kMax) out += "...";
    return out + "'";
}

struct FileBuffer {
    std::unique_ptr<char[]> bytes;
    size_t size = 0;
    const char* begin() const { return bytes.get(); }
    const char* end() const { return bytes.get() + size; }
};

FileBuffer load_file(const std::string& path) {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec)) fail(path, "is a directory, not a file");
    std::FILE* file = std::fopen(path.c_str(), "rb");
    if (file == nullptr) {
        if (errno == ENOENT) fail(path, "no such file");
        fail(path, "cannot open: ", std::strerror(errno));
    }
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> closer(file, &std::fclose);
    const auto size = std::filesystem::file_size(path, ec);
    if (ec) fail(path, "cannot determine the file size: ", ec.message());
    FileBuffer buffer;
    // make_unique_for_overwrite: zero-filling tens of megabytes first would be wasted work.
    buffer.bytes = std::make_unique_for_overwrite<char[]>(size + 1);
    buffer.size = static_cast<size_t>(size);
    if (std::fread(buffer.bytes.get(), 1, buffer.size, file) != buffer.size) {
        fail(path, "read error: ", std::ferror(file) ? std::strerror(errno) : "file shrank");
    }
    buffer.bytes[buffer.size] = '\0';
    return buffer;
}

bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

// from_chars rejects a leading '+', which some writers emit; "+-1" must still be rejected.
const char* skip_plus(const char* b, const char* e) {
    if (e - b >= 2 && b[0] == '+' && b[1] != '-' && b[1] != '+') return b + 1;
    return b;
}

// from_chars reports values beyond the type's range as errors; overflow should become an
// infinity (rejected later with a clear message) and underflow a zero, as strtod would give.
template <class T>
bool parse_real(std::string_view token, T& out) {
    const char* b = skip_plus(token.data(), token.data() + token.size());
    const char* e = token.data() + token.size();
    auto [ptr, ec] = std::from_chars(b, e, out);
    if (ptr != e) return false;
    if (ec == std::errc()) return true;
    if (ec != std::errc::result_out_of_range) return false;
    double wide = 0;
    auto [wptr, wec] = std::from_chars(b, e, wide);
    if (wptr == e && wec == std::errc()) {
        out = static_cast<T>(wide);
        return true;
    }
    const bool negative = *b == '-';
    const char* mantissa = negative ? b + 1 : b;
    const char* exponent = std::find_if(mantissa, e, [](char c) { return c == 'e' || c == 'E'; });
    const bool underflow = exponent != e ? (exponent + 1 != e && exponent[1] == '-')
                                         : (*mantissa == '0' || *mantissa == '.');
    const T magnitude = underflow ? T(0) : std::numeric_limits<T>::infinity();
    out = negative ? -magnitude : magnitude;
    return true;
}

bool parse_int(std::string_view token, int64_t& out) {
    const char* e = token.data() + token.size();
    auto [ptr, ec] = std::from_chars(skip_plus(token.data(), e), e, out);
    return ec == std::errc() && ptr == e && !token.empty();
}

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
            const char* q = p_;
            while (q != stop) {
                while (q != stop && is_blank(*q)) ++q;
                const char* start = q;
                while (q != stop && !is_blank(*q)) ++q;
                if (q != start) tokens.emplace_back(start, q - start);
            }
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
    for (int64_t i = 0; i < vertex_count; ++i) {
        if (!lines.next(tokens)) {
            fail(path, "truncated: expected ", vertex_count, " vertices, found ", i);
        }
        // Extra values (alpha, texture coordinates) are allowed and ignored.
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
        // Values after the indices (a face colour) are allowed and ignored.
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
    return out;
} catch (const std::bad_alloc&) {
    // Counts are checked against the file size, so only a file too big for memory gets here.
    fail(path, "out of memory while reading");
}

}  // namespace vmap
