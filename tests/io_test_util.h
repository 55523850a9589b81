// What the reader tests (ply_test, off_test, model_test) share: the test data's folders, PLY
// files built in any of the three encodings, and damaging a good file at random.
#pragma once

// vec.h calls isfinite unqualified, which <cmath> alone does not declare globally (libstdc++);
// <math.h> does, so it must come first. Remove once vec.h includes what it uses.
// clang-format off
#include <math.h>
// clang-format on

#include <gtest/gtest.h>

#include "vmap/io.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <initializer_list>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "test_files.h"
#include "vmap/error.h"
#include "test_files.h"
#include "vmap/error.h"

namespace vmap {
namespace {

namespace fs = std::filesystem;

const std::string kData = std::string(VMAP_TEST_DATA) + "/io/";
const std::string kModels = std::string(VMAP_SOURCE_DIR) + "/models/";

const char* const kPlyFormats[] = {"ascii", "binary_little_endian", "binary_big_endian"};

using test::expect_error;
using test::ScratchDir;
using test::slurp;

#define EXPECT_READ_ERROR(call, ...)                        \
    do {                                                    \
        SCOPED_TRACE(#call);                                \
        expect_error([&] { (void)(call); }, {__VA_ARGS__}); \
    } while (0)

// ---- building PLY files in any format --------------------------------------------------------

struct PlyProp {
    std::string type;
    std::string name;
    std::string count_type = {};  // non-empty: a list with this count type, `type` per item
};

struct PlyElement {
    std::string name;
    std::vector<PlyProp> props;
    // One row per element: a scalar takes one value, a list its length then its items.
    std::vector<std::vector<double>> rows;
    std::string count = {};  // overrides rows.size() in the header
};

inline bool is_big_endian_format(std::string_view format) { return format == "binary_big_endian"; }

inline void put_binary(std::string& out, const std::string& type, double v, bool big_endian) {
    auto put = [&](auto x) {
        char bytes[sizeof(x)];
        std::memcpy(bytes, &x, sizeof(x));
        if (big_endian != (std::endian::native == std::endian::big)) {
            std::reverse(bytes, bytes + sizeof(x));
        }
        out.append(bytes, sizeof(x));
    };
    if (type == "char" || type == "int8") return put(static_cast<int8_t>(v));
    if (type == "uchar" || type == "uint8") return put(static_cast<uint8_t>(v));
    if (type == "short" || type == "int16") return put(static_cast<int16_t>(v));
    if (type == "ushort" || type == "uint16") return put(static_cast<uint16_t>(v));
    if (type == "int" || type == "int32") return put(static_cast<int32_t>(v));
    if (type == "uint" || type == "uint32") return put(static_cast<uint32_t>(v));
    if (type == "float" || type == "float32") return put(static_cast<float>(v));
    if (type == "double" || type == "float64") return put(v);
    ADD_FAILURE() << "test bug: unknown type " << type;
}

inline std::string ply_header(std::string_view format, const std::vector<PlyElement>& elements) {
    std::string h = "ply\nformat " + std::string(format) + " 1.0\n";
    for (const PlyElement& e : elements) {
        h += "element " + e.name + " " +
             (e.count.empty() ? std::to_string(e.rows.size()) : e.count) + "\n";
        for (const PlyProp& p : e.props) {
            h += p.count_type.empty()
                     ? "property " + p.type + " " + p.name + "\n"
                     : "property list " + p.count_type + " " + p.type + " " + p.name + "\n";
        }
    }
    return h + "end_header\n";
}

inline std::string ply_body(std::string_view format, const std::vector<PlyElement>& elements) {
    const bool ascii = format == "ascii";
    const bool big = is_big_endian_format(format);
    std::string body;
    for (const PlyElement& e : elements) {
        for (const auto& row : e.rows) {
            size_t k = 0;
            auto emit = [&](const std::string& type) {
                const double v = k < row.size() ? row[k] : 0.0;
                ++k;
                if (ascii) {
                    std::ostringstream s;
                    s.precision(17);
                    s << v;
                    if (!body.empty() && body.back() != '\n') body += ' ';
                    body += s.str();
                } else {
                    put_binary(body, type, v, big);
                }
            };
            for (const PlyProp& p : e.props) {
                if (p.count_type.empty()) {
                    emit(p.type);
                    continue;
                }
                // A negative length (to test the reader) has no items.
                const size_t n = k < row.size() && row[k] > 0 ? static_cast<size_t>(row[k]) : 0;
                emit(p.count_type);
                for (size_t i = 0; i < n; ++i) emit(p.type);
            }
            if (ascii) body += '\n';
        }
    }
    return body;
}

inline std::string make_ply(std::string_view format, const std::vector<PlyElement>& elements) {
    return ply_header(format, elements) + ply_body(format, elements);
}

inline PlyElement xyz_vertices(std::vector<std::vector<double>> rows, const std::string& type = "float") {
    return {"vertex", {{type, "x"}, {type, "y"}, {type, "z"}}, std::move(rows)};
}

inline PlyElement faces(std::vector<std::vector<double>> rows, const std::string& count_type = "uchar",
                 const std::string& index_type = "int") {
    return {"face", {{index_type, "vertex_indices", count_type}}, std::move(rows)};
}

const std::vector<std::vector<double>> kSquare = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};

using Tri = std::array<uint32_t, 3>;

// Whatever the damage, reading either succeeds or throws vmap::Error: no crash, hang, other
// exception or partial result. Under the sanitizer build this also checks memory safety.
inline void expect_only_vmap_errors(const std::string& path, const std::function<ModelData()>& read) {
    try {
        const ModelData m = read();
        for (const Tri& t : m.triangles) {
            for (uint32_t i : t) ASSERT_LT(i, m.points.size()) << path;
        }
        for (const Vec3& p : m.points.positions) ASSERT_TRUE(is_finite(p)) << path;
    } catch (const Error&) {
    } catch (const std::exception& e) {
        ADD_FAILURE() << "non-vmap exception: " << e.what();
    }
}

inline std::string damaged(std::string bytes, std::mt19937& rng) {
    std::uniform_int_distribution<int> byte(0, 255), kind(0, 3), count(1, 4);
    const char interesting[] = {'\n', ' ', '-', '9', 'e', '.', '\0', '\xff'};
    for (int n = count(rng); n > 0; --n) {
        const size_t at = std::uniform_int_distribution<size_t>(0, bytes.size() - 1)(rng);
        switch (kind(rng)) {
            case 0:
                bytes[at] = static_cast<char>(byte(rng));
                break;
            case 1:
                bytes[at] = interesting[static_cast<size_t>(byte(rng)) % sizeof(interesting)];
                break;
            case 2:
                bytes.erase(at, 1);
                break;
            default:
                bytes.resize(at + 1);
                break;
        }
        if (bytes.empty()) break;
    }
    return bytes;
}

// Reads every prefix of `good`, then 1000 random damages of it (drawn from rng), written to
// files ending in `ext`, with `read`: each only ever succeeds or throws vmap::Error.
inline void expect_damage_only_throws_vmap_errors(const ScratchDir& dir, const std::string& good,
                                           const std::string& ext,
                                           ModelData (*read)(const std::string&),
                                           std::mt19937& rng) {
    for (size_t length = 0; length < good.size(); ++length) {
        const std::string path = dir.write("prefix" + ext, good.substr(0, length));
        expect_only_vmap_errors(path, [&] { return read(path); });
    }
    for (int i = 0; i < 1000; ++i) {
        const std::string path = dir.write("fuzz" + ext, damaged(good, rng));
        expect_only_vmap_errors(path, [&] { return read(path); });
    }
}

}  // namespace
}  // namespace vmap
