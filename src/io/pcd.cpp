// PCD, the Point Cloud Library's format (pointclouds.org, "The PCD file format"): a text header
// (VERSION, FIELDS, SIZE, TYPE, COUNT, WIDTH, HEIGHT, VIEWPOINT, POINTS, DATA), then the points:
//   ascii               one point a line, COUNT values per field;
//   binary              point records of sum(SIZE x COUNT) bytes, little-endian as PCL writes;
//   binary_compressed   uint32 compressed size, uint32 uncompressed size, then LZF data that
//                       expands to the fields one after another (all x, then all y, ...).
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <new>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "io/line_reader.h"
#include "io/lzf.h"
#include "vmap/io.h"

namespace vmap {

using detail::fail;
using detail::InputFile;
using detail::parse_int;
using detail::parse_real;
using detail::quoted;

namespace detail {
bool lzf_decompress(const uint8_t* in, size_t in_size, uint8_t* out, size_t out_size) {
    const uint8_t* ip = in;
    const uint8_t* const in_end = in + in_size;
    uint8_t* op = out;
    uint8_t* const out_end = out + out_size;
    while (ip < in_end) {
        const unsigned ctrl = *ip++;
        if (ctrl < 32) {
            const size_t len = ctrl + 1;
            if (size_t(in_end - ip) < len || size_t(out_end - op) < len) return false;
            std::memcpy(op, ip, len);
            ip += len, op += len;
            continue;
        }
        size_t len = ctrl >> 5;
        if (len == 7) {
            if (ip == in_end) return false;
            len += *ip++;
        }
        if (ip == in_end) return false;
        const size_t distance = ((ctrl & 31u) << 8) + *ip++ + 1;
        len += 2;
        if (size_t(op - out) < distance || size_t(out_end - op) < len) return false;
        const uint8_t* ref = op - distance;
        for (size_t k = 0; k < len; ++k) *op++ = *ref++;  // may overlap: byte by byte
    }
    return op == out_end;
}
}  // namespace detail

namespace {

enum Role : uint8_t { kSkip, kX, kY, kZ, kNx, kNy, kNz, kRgb, kEr, kEg, kEb, kRoleCount };
enum class Data { kAscii, kBinary, kCompressed };

struct Field {
    std::string name;
    int size = 4;
    char type = 'F';
    uint64_t count = 1;
    uint64_t offset = 0;  // bytes into a point record
    Role role = kSkip;
};

struct Header {
    std::vector<Field> fields;
    uint64_t width = 0, height = 1, points = 0;
    bool have_points = false;
    std::optional<Viewpoint> viewpoint;
    std::array<double, 3> view_at{};  // the viewpoint's position as written (double)
    Data data = Data::kAscii;
    uint64_t record = 0;  // bytes a point
    uint64_t values = 0;  // values a point (ascii)
    int role_field[kRoleCount] = {};
};

Role role_of(std::string_view name) {
    static constexpr std::pair<std::string_view, Role> kNames[] = {
        {"x", kX},           {"y", kY},           {"z", kZ},      {"normal_x", kNx},
        {"normal_y", kNy},   {"normal_z", kNz},   {"nx", kNx},    {"ny", kNy},
        {"nz", kNz},         {"rgb", kRgb},       {"rgba", kRgb}, {"emission_r", kEr},
        {"emission_g", kEg}, {"emission_b", kEb},
    };
    for (const auto& [n, r] : kNames)
        if (n == name) return r;
    return kSkip;
}

uint64_t header_count(const InputFile& in, std::string_view word, const char* key) {
    int64_t v = 0;
    if (!parse_int(word, v) || v < 0) {
        fail(in.path(), "header line ", in.line(), ": ", key, ": invalid count ", quoted(word));
    }
    return static_cast<uint64_t>(v);
}

// SIZE, TYPE or COUNT: one word per field.
void per_field(const InputFile& in, Header& h, const std::vector<std::string_view>& w) {
    if (h.fields.empty()) fail(in.path(), "header line ", in.line(), ": ", w[0], " before FIELDS");
    if (w.size() != h.fields.size() + 1) {
        fail(in.path(), "header line ", in.line(), ": ", w[0], " has ", w.size() - 1,
             " entries for ", h.fields.size(), " fields");
    }
    for (size_t i = 0; i < h.fields.size(); ++i) {
        Field& f = h.fields[i];
        const std::string_view v = w[i + 1];
        if (w[0] == "TYPE") {
            if (v != "F" && v != "I" && v != "U") {
                fail(in.path(), "header line ", in.line(), ": field ", f.name, ": unknown TYPE ",
                     quoted(v), " (expected F, I or U)");
            }
            f.type = v[0];
        } else if (w[0] == "SIZE") {
            const uint64_t s = header_count(in, v, "SIZE");
            if (s != 1 && s != 2 && s != 4 && s != 8) {
                fail(in.path(), "header line ", in.line(), ": field ", f.name, ": SIZE ", s,
                     " (expected 1, 2, 4 or 8)");
            }
            f.size = static_cast<int>(s);
        } else {
            f.count = header_count(in, v, "COUNT");
            if (f.count == 0 || f.count > 1000000) {
                fail(in.path(), "header line ", in.line(), ": field ", f.name, ": COUNT ", f.count,
                     " out of range (1..1000000)");
            }
        }
    }
}

void header_line(InputFile& in, Header& h, const std::vector<std::string_view>& w) {
    const std::string_view key = w[0];
    if (key == "VERSION") return;
    if (key == "FIELDS") {
        if (!h.fields.empty()) fail(in.path(), "header line ", in.line(), ": second FIELDS line");
        for (size_t i = 1; i < w.size(); ++i) h.fields.push_back({std::string(w[i])});
        if (h.fields.empty()) fail(in.path(), "header line ", in.line(), ": FIELDS is empty");
    } else if (key == "SIZE" || key == "TYPE" || key == "COUNT") {
        per_field(in, h, w);
    } else if (key == "WIDTH" || key == "HEIGHT" || key == "POINTS") {
        if (w.size() != 2) fail(in.path(), "header line ", in.line(), ": expected '", key, " <n>'");
        const uint64_t n = header_count(in, w[1], key == "WIDTH" ? "WIDTH" : "HEIGHT/POINTS");
        (key == "WIDTH" ? h.width : key == "HEIGHT" ? h.height : h.points) = n;
        h.have_points |= key == "POINTS";
    } else if (key == "VIEWPOINT") {
        if (w.size() != 8) {
            fail(in.path(), "header line ", in.line(),
                 ": VIEWPOINT needs 7 numbers (tx ty tz qw "
                 "qx qy qz), found ",
                 w.size() - 1);
        }
        double v[7];
        for (int k = 0; k < 7; ++k) {
            if (!parse_real(w[k + 1], v[k]) || !std::isfinite(float(v[k]))) {
                fail(in.path(), "header line ", in.line(), ": VIEWPOINT: invalid number ",
                     quoted(w[k + 1]));
            }
        }
        h.viewpoint = Viewpoint{{float(v[0]), float(v[1]), float(v[2])},
                                {float(v[3]), float(v[4]), float(v[5]), float(v[6])}};
        h.view_at = {v[0], v[1], v[2]};
    } else {
        fail(in.path(), "header line ", in.line(), ": unknown keyword ", quoted(key));
    }
}

void check_fields(const InputFile& in, Header& h) {
    if (h.fields.empty()) fail(in.path(), "header: no FIELDS line");
    std::fill(std::begin(h.role_field), std::end(h.role_field), -1);
    for (size_t i = 0; i < h.fields.size(); ++i) {
        Field& f = h.fields[i];
        f.offset = h.record;
        h.record += uint64_t(f.size) * f.count;
        h.values += f.count;
        f.role = role_of(f.name);
        if (f.role == kSkip) continue;
        if (h.role_field[f.role] >= 0) {
            fail(in.path(), "header: fields '", h.fields[h.role_field[f.role]].name, "' and '",
                 f.name, "' give the same value");
        }
        if (f.count != 1) fail(in.path(), "header: field ", f.name, ": COUNT must be 1");
        if (f.role == kRgb ? f.size != 4 : (f.type == 'F' && f.size < 4)) {
            fail(in.path(), "header: field ", f.name, ": SIZE ", f.size, " with TYPE ", f.type,
                 " is not a valid ", f.role == kRgb ? "packed colour (SIZE 4)" : "number");
        }
        h.role_field[f.role] = static_cast<int>(i);
    }
    for (Role r : {kX, kY, kZ}) {
        if (h.role_field[r] < 0) fail(in.path(), "header: no '", "xyz"[r - kX], "' field");
    }
    const int normals =
        (h.role_field[kNx] >= 0) + (h.role_field[kNy] >= 0) + (h.role_field[kNz] >= 0);
    if (normals != 0 && normals != 3) {
        fail(in.path(), "header: only ", normals,
             " of the 3 normal fields (normal_x, normal_y, "
             "normal_z)");
    }
    const int emission =
        (h.role_field[kEr] >= 0) + (h.role_field[kEg] >= 0) + (h.role_field[kEb] >= 0);
    if (emission != 0 && emission != 3) {
        fail(in.path(), "header: only ", emission,
             " of the 3 emission fields (emission_r, "
             "emission_g, emission_b)");
    }
}

Header parse_header(InputFile& in) {
    Header h;
    std::string_view line;
    std::vector<std::string_view> w;
    for (;;) {
        if (!in.next_line(line)) fail(in.path(), "header: missing DATA line");
        w.clear();
        detail::append_words(line.data(), line.data() + line.size(), w);
        if (w.empty() || w[0][0] == '#') continue;
        if (w[0] != "DATA") {
            header_line(in, h, w);
            continue;
        }
        if (w.size() != 2) fail(in.path(), "header line ", in.line(), ": expected 'DATA <type>'");
        if (w[1] == "ascii") {
            h.data = Data::kAscii;
        } else if (w[1] == "binary") {
            h.data = Data::kBinary;
        } else if (w[1] == "binary_compressed") {
            h.data = Data::kCompressed;
        } else {
            fail(in.path(), "header line ", in.line(), ": unknown DATA ", quoted(w[1]),
                 " (expected ascii, binary or binary_compressed)");
        }
        break;
    }
    check_fields(in, h);
    if (!h.have_points) h.points = h.width * h.height;
    if (h.width != 0 &&
        (h.height == 0 || h.points / h.height != h.width || h.points % h.height != 0)) {
        fail(in.path(), "header: WIDTH ", h.width, " x HEIGHT ", h.height, " is not POINTS ",
             h.points);
    }
    // A count the rest of the file cannot hold is refused before anything is allocated.
    const uint64_t left = in.size() - in.offset();
    const uint64_t least = h.data == Data::kAscii ? 2 * h.values : h.record;
    if (h.data != Data::kCompressed && h.points > (left + 1) / least) {
        fail(in.path(), "truncated: ", h.points, " points of at least ", least,
             " bytes each cannot fit in the ", left, " bytes after the header");
    }
    return h;
}

// Builds the point set from the values of each point's fields.
struct Sink {
    Sink(const Header& header, ModelData& data) : h(header), out(data) {}
    const Header& h;
    ModelData& out;
    uint64_t nan_points = 0;

    // value(field, element): the value as a double; bits(field): a packed colour's 32 bits.
    // `at`: the point's line (ascii), its byte offset in the file (binary) or in the
    // decompressed data (binary_compressed), for messages.
    template <class Value, class Bits>
    void add(const InputFile& in, uint64_t index, uint64_t at, Value value, Bits bits) {
        auto get = [&](Role r) { return value(h.role_field[r]); };
        auto where = [&] {
            const char* unit = h.data == Data::kAscii    ? " (line "
                               : h.data == Data::kBinary ? " (byte "
                                                         : " (decompressed byte ";
            return "point " + std::to_string(index) + unit + std::to_string(at) + ")";
        };
        const double x = get(kX), y = get(kY), z = get(kZ);
        if (std::isnan(x) || std::isnan(y) || std::isnan(z)) {
            ++nan_points;
            return;
        }
        const std::array<double, 3>& o = out.points.origin;  // read_pcd's origin
        const Vec3 p{float(x - o[0]), float(y - o[1]), float(z - o[2])};
        if (!is_finite(p)) fail(in.path(), where(), ": non-finite coordinate");
        PointSet& ps = out.points;
        ps.positions.push_back(p);
        if (h.role_field[kNx] >= 0) {
            const Vec3 n{float(get(kNx)), float(get(kNy)), float(get(kNz))};
            if (!is_finite(n)) fail(in.path(), where(), ": normal_x/y/z: non-finite normal");
            ps.normals.push_back(n);
        }
        if (h.role_field[kRgb] >= 0) {
            const uint32_t c = bits(h.role_field[kRgb]);
            ps.colors.push_back(
                Vec3{float((c >> 16) & 255), float((c >> 8) & 255), float(c & 255)} / 255.0f);
        }
        if (h.role_field[kEr] >= 0) {
            const Vec3 e{float(get(kEr)), float(get(kEg)), float(get(kEb))};
            if (!is_finite(e) || e.x < 0 || e.y < 0 || e.z < 0) {
                fail(in.path(), where(), ": emission_r/g/b: not finite and non-negative");
            }
            ps.emission.push_back(e);
        }
    }
};

double load_scalar(const uint8_t* p, char type, int size) {
    auto get = [&](auto v) {
        std::memcpy(&v, p, sizeof(v));
        return static_cast<double>(v);
    };
    if (type == 'F') return size == 4 ? get(float()) : get(double());
    if (type == 'U') {
        switch (size) {
            case 1:
                return get(uint8_t());
            case 2:
                return get(uint16_t());
            case 4:
                return get(uint32_t());
            default:
                return get(uint64_t());
        }
    }
    switch (size) {
        case 1:
            return get(int8_t());
        case 2:
            return get(int16_t());
        case 4:
            return get(int32_t());
        default:
            return get(int64_t());
    }
}

uint32_t load_bits(const uint8_t* p) {
    uint32_t v;
    std::memcpy(&v, p, 4);
    return v;
}

void read_ascii(InputFile& in, const Header& h, Sink& sink) {
    std::string_view line;
    std::vector<std::string_view> w;
    std::vector<uint64_t> first(h.fields.size());  // first token of each field
    for (size_t i = 0, t = 0; i < h.fields.size(); t += h.fields[i].count, ++i) first[i] = t;
    uint64_t index = 0;
    while (index < h.points) {
        if (!in.next_line(line)) {
            fail(in.path(), "truncated: the header says ", h.points, " points, found ", index);
        }
        w.clear();
        detail::append_words(line.data(), line.data() + line.size(), w);
        if (w.empty()) continue;
        if (w.size() != h.values) {
            fail(in.path(), "point ", index, " (line ", in.line(), "): expected ", h.values,
                 " values, found ", w.size());
        }
        auto token = [&](int f) { return w[first[f]]; };
        auto value = [&](int f) {
            double v = 0;
            if (!parse_real(token(f), v)) {
                fail(in.path(), "point ", index, " (line ", in.line(), "): field ",
                     h.fields[f].name, ": invalid number ", quoted(token(f)));
            }
            return v;
        };
        auto bits = [&](int f) {
            const double v = value(f);
            if (h.fields[f].type == 'F') return std::bit_cast<uint32_t>(float(v));
            // A packed colour written as an integer: signed or unsigned 32 bits, nothing else.
            if (!(v >= -2147483648.0 && v < 4294967296.0) || v != std::floor(v)) {
                fail(in.path(), "point ", index, " (line ", in.line(), "): field ",
                     h.fields[f].name, ": ", quoted(token(f)),
                     " is not a packed 32-bit colour (a whole number in [-2^31, 2^32))");
            }
            return static_cast<uint32_t>(static_cast<int64_t>(v));
        };
        sink.add(in, index, in.line(), value, bits);
        ++index;
    }
    while (in.next_line(line)) {
        w.clear();
        detail::append_words(line.data(), line.data() + line.size(), w);
        if (!w.empty()) {
            fail(in.path(), "line ", in.line(), ": more points than the header's ", h.points);
        }
    }
}

void read_binary(InputFile& in, const Header& h, Sink& sink) {
    constexpr uint64_t kChunk = 1 << 16;
    std::vector<uint8_t> buf(std::min(h.points, kChunk) * h.record);
    for (uint64_t done = 0; done < h.points;) {
        const uint64_t n = std::min(kChunk, h.points - done);
        const uint64_t at = in.offset();
        if (in.read_bytes(reinterpret_cast<char*>(buf.data()), n * h.record) != n * h.record) {
            fail(in.path(), "truncated: byte ", at, ": the header says ", h.points, " points of ",
                 h.record, " bytes");
        }
        for (uint64_t i = 0; i < n; ++i) {
            const uint8_t* rec = buf.data() + i * h.record;
            auto value = [&](int f) {
                const Field& fd = h.fields[f];
                return load_scalar(rec + fd.offset, fd.type, fd.size);
            };
            auto bits = [&](int f) { return load_bits(rec + h.fields[f].offset); };
            sink.add(in, done + i, at + i * h.record, value, bits);
        }
        done += n;
    }
    char extra;
    if (in.read_bytes(&extra, 1) != 0) {
        fail(in.path(), "byte ", in.offset() - 1, ": data after the last point");
    }
}

void read_compressed(InputFile& in, const Header& h, Sink& sink) {
    uint8_t sizes[8];
    if (in.read_bytes(reinterpret_cast<char*>(sizes), 8) != 8) {
        fail(in.path(), "truncated: byte ", in.offset(), ": no compressed/uncompressed sizes");
    }
    const uint32_t packed = load_bits(sizes), unpacked = load_bits(sizes + 4);
    const uint64_t left = in.size() - in.offset();
    if (packed > left) {
        fail(in.path(), "truncated: byte ", in.offset() - 8, ": compressed size ", packed,
             " but only ", left, " bytes follow");
    }
    if (unpacked % h.record != 0 || unpacked / h.record != h.points) {
        fail(in.path(), "byte ", in.offset() - 4, ": uncompressed size ", unpacked, " is not ",
             h.points, " points x ", h.record, " bytes");
    }
    // An LZF back-reference of 3 bytes expands to at most 264: a larger ratio is corrupt.
    if (unpacked > 88ull * packed + 32) {
        fail(in.path(), "byte ", in.offset() - 4, ": uncompressed size ", unpacked,
             " cannot come from ", packed, " compressed bytes");
    }
    std::vector<uint8_t> zipped(packed), data(unpacked);
    const uint64_t at = in.offset();
    in.read_bytes(reinterpret_cast<char*>(zipped.data()), packed);
    if (!detail::lzf_decompress(zipped.data(), packed, data.data(), unpacked)) {
        fail(in.path(), "byte ", at, ": corrupt LZF data (does not expand to ", unpacked,
             " bytes)");
    }
    for (uint64_t i = 0; i < h.points; ++i) {
        // Field-major: field f of point i at points x offset(f) + i x size(f).
        auto at_field = [&](int f) {
            const Field& fd = h.fields[f];
            return data.data() + h.points * fd.offset + i * uint64_t(fd.size) * fd.count;
        };
        auto value = [&](int f) {
            return load_scalar(at_field(f), h.fields[f].type, h.fields[f].size);
        };
        auto bits = [&](int f) { return load_bits(at_field(f)); };
        const Field& fx = h.fields[h.role_field[kX]];
        sink.add(in, i, h.points * fx.offset + i * fx.size, value, bits);
    }
}

void add_notes(const std::string& path, const Header& h, const Sink& sink, ModelData& out) {
    std::string ignored;
    for (const Field& f : h.fields) {
        if (f.role == kSkip && f.name != "_") ignored += (ignored.empty() ? "" : ", ") + f.name;
    }
    if (!ignored.empty()) out.notes.push_back(path + ": ignored fields " + ignored);
    if (sink.nan_points > 0) {
        out.notes.push_back(path + ": left out " + std::to_string(sink.nan_points) +
                            " points with NaN coordinates (no measurement)");
    }
}

}  // namespace

ModelData read_pcd(const std::string& path, const std::array<double, 3>& origin) try {
    InputFile in(path);
    if (in.size() == 0) fail(path, "empty file");
    const Header h = parse_header(in);
    ModelData out;
    out.points.origin = origin;
    out.viewpoint = h.viewpoint;
    if (out.viewpoint && origin != std::array<double, 3>{0, 0, 0}) {
        const std::array<double, 3>& v = h.view_at;
        out.viewpoint->origin = {float(v[0] - origin[0]), float(v[1] - origin[1]),
                                 float(v[2] - origin[2])};
    }
    Sink sink(h, out);
    if (h.data == Data::kAscii) {
        read_ascii(in, h, sink);
    } else if (h.data == Data::kBinary) {
        read_binary(in, h, sink);
    } else {
        read_compressed(in, h, sink);
    }
    add_notes(path, h, sink, out);
    return out;
} catch (const std::bad_alloc&) {
    fail(path, "out of memory while reading");
}

}  // namespace vmap
