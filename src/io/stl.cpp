// STL, ASCII and binary. Binary: an 80-byte header, a uint32 facet count, then 50 bytes a facet
// (normal, three corners as little-endian floats, a 2-byte attribute). Binary files may begin
// with "solid" too, so a file whose size is exactly what its count implies is binary; any other
// file starting with "solid" is read as ASCII:
//   solid name / facet normal nx ny nz / outer loop / vertex x y z (x3) / endloop / endfacet /
//   ... / endsolid name   (several solids may follow one another)
// Corners are merged into shared vertices when bit-equal, so a mesh comes back indexed.
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <new>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "io/line_reader.h"
#include "vmap/io.h"

namespace vmap {

using detail::fail;
using detail::InputFile;
using detail::parse_real;
using detail::quoted;

namespace {

struct KeyHash {
    size_t operator()(const std::array<uint32_t, 3>& k) const {
        uint64_t h = k[0] * 0x9e3779b97f4a7c15ULL;
        h ^= (h >> 29) + k[1] * 0xbf58476d1ce4e5b9ULL;
        h ^= (h >> 31) + k[2] * 0x94d049bb133111ebULL;
        return static_cast<size_t>(h ^ (h >> 32));
    }
};

// Collects facets into an indexed mesh.
struct Welder {
    ModelData out;
    std::unordered_map<std::array<uint32_t, 3>, uint32_t, KeyHash> index;

    uint32_t vertex(Vec3 p) {
        auto bits = [](float f) { return f == 0.0f ? 0u : std::bit_cast<uint32_t>(f); };
        const std::array<uint32_t, 3> key{bits(p.x), bits(p.y), bits(p.z)};
        auto [it, added] = index.try_emplace(key, uint32_t(out.points.positions.size()));
        if (added) out.points.positions.push_back(p);
        return it->second;
    }

    // A facet whose stored normal points against its winding is re-wound (the normal is the
    // more deliberate of the two); a zero normal leaves the winding as it is.
    void facet(Vec3 n, const Vec3 (&c)[3]) {
        std::array<uint32_t, 3> t{vertex(c[0]), vertex(c[1]), vertex(c[2])};
        if (dot(n, cross(c[1] - c[0], c[2] - c[0])) < 0) std::swap(t[1], t[2]);
        out.triangles.push_back(t);
    }
};

float little_float(const char* p) {
    uint32_t u;
    std::memcpy(&u, p, 4);
    if constexpr (std::endian::native == std::endian::big) u = __builtin_bswap32(u);
    return std::bit_cast<float>(u);
}

void read_binary(InputFile& in, uint64_t facets, Welder& w) {
    // A closed mesh has about half as many vertices as facets; the count was checked against
    // the file's size, so these reservations are bounded by it.
    w.index.reserve(facets / 2 + 16);
    w.out.points.positions.reserve(facets / 2 + 16);
    w.out.triangles.reserve(facets);
    constexpr uint64_t kChunk = 4096;
    std::vector<char> buf(50 * std::min(facets, kChunk));
    for (uint64_t done = 0; done < facets;) {
        const uint64_t n = std::min(kChunk, facets - done);
        const uint64_t at = in.offset();
        if (in.read_bytes(buf.data(), 50 * n) != 50 * n) {
            fail(in.path(), "truncated: byte ", at, ": facets ", done, "..", done + n - 1);
        }
        for (uint64_t i = 0; i < n; ++i) {
            const char* rec = buf.data() + 50 * i;
            float v[12];
            for (int k = 0; k < 12; ++k) v[k] = little_float(rec + 4 * k);
            const Vec3 c[3] = {{v[3], v[4], v[5]}, {v[6], v[7], v[8]}, {v[9], v[10], v[11]}};
            for (const Vec3& p : c) {
                if (!is_finite(p)) {
                    fail(in.path(), "byte ", at + 50 * i, ": facet ", done + i,
                         ": non-finite vertex coordinate");
                }
            }
            const Vec3 normal{v[0], v[1], v[2]};
            w.facet(is_finite(normal) ? normal : Vec3{0, 0, 0}, c);
        }
        done += n;
    }
}

class AsciiStl {
  public:
    AsciiStl(InputFile& in, Welder& w) : in_(in), w_(w) {}

    void read() {
        bool any = false;
        while (next()) {
            expect("solid", 1, true);
            any = true;
            while (next() && words_[0] != "endsolid") facet();
            if (words_.empty()) fail(in_.path(), "truncated: no 'endsolid' after line ", line_);
        }
        if (!any) fail(in_.path(), "no 'solid' line");
    }

  private:
    bool next() {
        std::string_view line;
        words_.clear();
        while (words_.empty()) {
            if (!in_.next_line(line)) return false;
            detail::append_words(line.data(), line.data() + line.size(), words_);
        }
        line_ = in_.line();
        return true;
    }

    // The current line is `keyword` with `values` more words (any number when `open`).
    void expect(std::string_view keyword, size_t values, bool open = false) {
        if (words_.empty()) {
            fail(in_.path(), "truncated: expected '", keyword, "' after line ", line_);
        }
        if (words_[0] != keyword) {
            fail(in_.path(), "line ", line_, ": expected '", keyword, "', found ",
                 quoted(words_[0]));
        }
        if (!open && words_.size() != values + 1) {
            fail(in_.path(), "line ", line_, ": '", keyword, "': expected ", values,
                 " values, found ", words_.size() - 1);
        }
    }

    Vec3 numbers(size_t first, const char* what) {
        float v[3];
        for (int k = 0; k < 3; ++k) {
            if (!parse_real(words_[first + k], v[k]) || !std::isfinite(v[k])) {
                fail(in_.path(), "line ", line_, ": ", what, ": invalid number ",
                     quoted(words_[first + k]));
            }
        }
        return {v[0], v[1], v[2]};
    }

    void facet() {
        expect("facet", 4);
        if (words_[1] != "normal") fail(in_.path(), "line ", line_, ": expected 'facet normal'");
        const Vec3 n = numbers(2, "facet normal");
        next();
        expect("outer", 1);
        Vec3 c[3];
        for (Vec3& p : c) {
            next();
            expect("vertex", 3);
            p = numbers(1, "vertex");
        }
        next();
        expect("endloop", 0);
        next();
        expect("endfacet", 0);
        w_.facet(n, c);
    }

    InputFile& in_;
    Welder& w_;
    std::vector<std::string_view> words_;
    size_t line_ = 0;
};

}  // namespace

ModelData read_stl(const std::string& path) try {
    InputFile in(path);
    if (in.size() == 0) fail(path, "empty file");
    char head[84] = {};
    const size_t got = in.read_bytes(head, 84);
    uint32_t count = 0;
    std::memcpy(&count, head + 80, 4);
    if constexpr (std::endian::native == std::endian::big) count = __builtin_bswap32(count);
    const bool sized_binary = got == 84 && in.size() == 84 + 50 * uint64_t(count);
    const bool says_solid = std::string_view(head, std::min<size_t>(got, 5)) == "solid";
    Welder w;
    if (sized_binary || !says_solid) {
        if (got < 84) fail(path, "truncated: ", in.size(), " bytes, a binary STL has at least 84");
        if (!sized_binary) {
            fail(path, "byte 80: the header says ", count, " facets (", 84 + 50 * uint64_t(count),
                 " bytes), the file has ", in.size(), " bytes");
        }
        read_binary(in, count, w);
    } else {
        InputFile text(path);  // from the start again, as lines
        AsciiStl(text, w).read();
    }
    return std::move(w.out);
} catch (const std::bad_alloc&) {
    fail(path, "out of memory while reading");
}

}  // namespace vmap
