// The readers beyond PLY and OFF (xyz/pts, PCD, OBJ, STL), PLY's PCL names and emission, mesh
// files as scenes, scenes without the room: each tool's dialect written here by hand, round
// trips, bad input of every kind, and one geometry giving one V-map in every mesh format.

// vec.h calls isfinite unqualified, which <cmath> alone does not declare globally (libstdc++);
// <math.h> does, so it must come first.
// clang-format off
#include <math.h>
// clang-format on

#include <gtest/gtest.h>

#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "io/lzf.h"
#include "test_files.h"
#include "test_util.h"
#include "vmap/error.h"
#include "vmap/io.h"
#include "vmap/scene.h"
#include "vmap/vmap.h"

namespace vmap {
namespace {

using test::expect_error;
using test::ScratchDir;
using Tri = std::array<uint32_t, 3>;

#define EXPECT_READ_ERROR(call, ...)                        \
    do {                                                    \
        SCOPED_TRACE(#call);                                \
        expect_error([&] { (void)(call); }, {__VA_ARGS__}); \
    } while (0)

std::string num(float v) {
    char b[32];
    return std::string(b, std::to_chars(b, b + sizeof b, v).ptr);
}

template <class T>
void put(std::string& out, T v) {
    char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    out.append(b, sizeof(T));
}

// Four points with normals and colours, the common content of the point-list tests.
const std::vector<Vec3> kP = {{0.5f, -1.25f, 3}, {1, 0, 2}, {0, 1, -4}, {0.125f, 0.25f, 0.375f}};
const std::vector<Vec3> kN = {{0, 0, 1}, {1, 0, 0}, {0, 1, 0}, {0, -1, 0}};
const std::vector<Vec3> kRgb8 = {{255, 0, 51}, {0, 128, 7}, {9, 9, 9}, {1, 2, 3}};

void expect_points(const ModelData& m, bool normals, bool colours) {
    ASSERT_EQ(m.points.size(), kP.size());
    for (size_t i = 0; i < kP.size(); ++i) EXPECT_EQ(m.points.positions[i], kP[i]) << i;
    ASSERT_EQ(m.points.normals.size(), normals ? kP.size() : 0u);
    for (size_t i = 0; normals && i < kP.size(); ++i) EXPECT_EQ(m.points.normals[i], kN[i]) << i;
    ASSERT_EQ(m.points.colors.size(), colours ? kP.size() : 0u);
    for (size_t i = 0; colours && i < kP.size(); ++i) {
        EXPECT_EQ(m.points.colors[i], kRgb8[i] / 255.0f) << i;
    }
}

// ---- xyz, pts, asc, csv ------------------------------------------------------------------------

std::string rows(const char* sep, bool normals, bool colours, bool rgb_first = true,
                 bool float_colours = false) {
    std::string s;
    for (size_t i = 0; i < kP.size(); ++i) {
        std::vector<std::string> v = {num(kP[i].x), num(kP[i].y), num(kP[i].z)};
        std::vector<std::string> n = {num(kN[i].x), num(kN[i].y), num(kN[i].z)};
        std::vector<std::string> c;
        for (float x : {kRgb8[i].x, kRgb8[i].y, kRgb8[i].z}) {
            c.push_back(float_colours ? num(x / 255.0f) : std::to_string(int(x)));
        }
        if (colours && rgb_first) v.insert(v.end(), c.begin(), c.end());
        if (normals) v.insert(v.end(), n.begin(), n.end());
        if (colours && !rgb_first) v.insert(v.end(), c.begin(), c.end());
        for (size_t k = 0; k < v.size(); ++k) s += (k ? sep : "") + v[k];
        s += "\n";
    }
    return s;
}

TEST(Xyz, Open3DDialectsReadExactly) {
    ScratchDir dir;
    expect_points(read_model(dir.write("a.xyz", rows(" ", false, false))), false, false);
    expect_points(read_model(dir.write("a.xyzn", rows(" ", true, false))), true, false);
    const ModelData rgb = read_model(dir.write("a.xyzrgb", rows(" ", false, true, true, true)));
    ASSERT_EQ(rgb.points.colors.size(), 4u);
    for (size_t i = 0; i < 4; ++i) EXPECT_EQ(rgb.points.colors[i], kRgb8[i] / 255.0f);
}

TEST(Xyz, CloudCompareDialectsReadExactly) {
    ScratchDir dir;
    // Header line, commas, colours as integers, normals last.
    expect_points(
        read_model(dir.write("h.asc", "//X,Y,Z,R,G,B,Nx,Ny,Nz\n" + rows(",", true, true))), true,
        true);
    // No header: nine columns are x y z r g b nx ny nz; semicolons and blanks around them.
    expect_points(read_model(dir.write("s.txt.csv", rows(" ; ", true, true))), true, true);
    // Six columns: integers are colours, a unit vector a normal.
    expect_points(read_model(dir.write("c.xyz", rows(" ", false, true))), false, true);
    expect_points(read_model(dir.write("n.xyz", rows(" ", true, false))), true, false);
    // Named columns in any order, with CRLF line ends and comments; unknown names noted.
    std::string named = "# scanned\r\nnx ny nz x y z intensity\r\n";
    for (size_t i = 0; i < kP.size(); ++i) {
        named += num(kN[i].x) + " " + num(kN[i].y) + " " + num(kN[i].z) + " " + num(kP[i].x) + " " +
                 num(kP[i].y) + " " + num(kP[i].z) + " 7\r\n";
    }
    const ModelData m = read_model(dir.write("named.xyz", named));
    expect_points(m, true, false);
    ASSERT_EQ(m.notes.size(), 1u);
    EXPECT_NE(m.notes[0].find("intensity"), std::string::npos);
}

TEST(Xyz, PtsWithCountIntensityAndColoursReads) {
    ScratchDir dir;
    std::string s = "4\n";
    for (size_t i = 0; i < kP.size(); ++i) {
        s += num(kP[i].x) + " " + num(kP[i].y) + " " + num(kP[i].z) + " -1024 " +
             std::to_string(int(kRgb8[i].x)) + " " + std::to_string(int(kRgb8[i].y)) + " " +
             std::to_string(int(kRgb8[i].z)) + "\n";
    }
    const ModelData m = read_model(dir.write("scan.pts", s));
    expect_points(m, false, true);
    ASSERT_EQ(m.notes.size(), 1u);
    EXPECT_NE(m.notes[0].find("intensity"), std::string::npos);
    EXPECT_READ_ERROR(read_model(dir.write("short.pts", "5" + s.substr(1))), "short.pts", "line 1",
                      "says 5 points", "has 4");
}

TEST(Xyz, BadInputIsRejectedNamingTheLine) {
    ScratchDir dir;
    const std::string good = rows(" ", true, false);
    EXPECT_READ_ERROR(read_xyz(dir.write("e.xyz", "")), "e.xyz", "empty file");
    EXPECT_READ_ERROR(read_xyz(dir.write("t.xyzn", good + "1 2 3 0 0\n")), "t.xyzn", "line 5",
                      "expected 6 values, found 5");
    EXPECT_READ_ERROR(read_xyz(dir.write("nan.xyz", "1 2 3\nnan 1 2\n")), "nan.xyz", "line 2",
                      "non-finite");
    EXPECT_READ_ERROR(read_xyz(dir.write("bad.xyz", "1 2 3\n1 2 x3\n")), "bad.xyz", "line 2",
                      "invalid number 'x3'");
    EXPECT_READ_ERROR(read_xyz(dir.write("five.xyz", "1 2 3 4 5\n")), "five.xyz", "line 1",
                      "5 columns", "first line such as //X,Y,Z");
    EXPECT_READ_ERROR(read_xyz(dir.write("six.xyz", "1 2 3 0.5 0.5 7\n")), "six.xyz",
                      "neither colours");
    // A guess from the first line that a later line contradicts is an error, not a misreading.
    EXPECT_READ_ERROR(read_xyz(dir.write("g1.xyz", "1 2 3 0 0 1\n1 2 3 255 0 51\n")), "g1.xyz",
                      "line 2", "not a unit normal as on line 1");
    EXPECT_READ_ERROR(read_xyz(dir.write("g2.xyz", "1 2 3 255 0 51\n1 2 3 0.6 0.8 0\n")), "g2.xyz",
                      "line 2", "not integer colours as on line 1");
    EXPECT_READ_ERROR(read_xyz(dir.write("huge.pts", "99999999999\n1 2 3\n")), "huge.pts",
                      "cannot fit");
    EXPECT_READ_ERROR(read_xyz(dir.write("neg.xyzrgb", "1 2 3 -1 0 0\n")), "neg.xyzrgb",
                      "negative");
    EXPECT_READ_ERROR(read_xyz(dir.write("h.xyz", "//X,Y,R,G,B\n1,2,3,4,5\n")), "h.xyz",
                      "no 'z' column");
    EXPECT_READ_ERROR(read_xyz(dir.write("h2.xyz", "x y z nx ny\n1 2 3 4 5\n")), "h2.xyz",
                      "only 2 of the 3 normal");
    EXPECT_READ_ERROR(read_xyz(dir.write("big.xyzrgb", "1 2 3 300 0 0\n")), "big.xyzrgb",
                      "above 255");
    // A binary file read as text: one endless line, refused without reading it whole.
    EXPECT_READ_ERROR(read_xyz(dir.write("bin.xyz", std::string(3 << 20, 'x'))), "bin.xyz",
                      "line 1", "longer than");
    // Read around an origin (a far cloud's second reading), a coordinate whose difference from
    // it passes a float's range is refused, naming the line.
    EXPECT_READ_ERROR(read_xyz(dir.write("far.xyz", "1 2 3\n3e38 2 3\n"), {-3e38, 0, 0}),
                      "far.xyz", "line 2", "coordinate: out of range");
}

// ---- PCD
// ------------------------------------------------------------------------------------------

// A test-side LZF compressor (greedy, naive search): enough to make files PCL would write.
std::string lzf_compress(const std::string& in) {
    std::string out, lit;
    auto flush = [&] {
        for (size_t k = 0; k < lit.size(); k += 32) {
            const size_t n = std::min<size_t>(32, lit.size() - k);
            out += char(n - 1);
            out += lit.substr(k, n);
        }
        lit.clear();
    };
    for (size_t i = 0; i < in.size();) {
        size_t best = 0, dist = 0;
        for (size_t d = 1; d <= std::min<size_t>(i, 8192); ++d) {
            size_t l = 0;
            while (i + l < in.size() && l < 264 && in[i + l] == in[i - d + l]) ++l;
            if (l > best) best = l, dist = d;
        }
        if (best < 3) {
            lit += in[i++];
            continue;
        }
        flush();
        const size_t len = best - 2, off = dist - 1;
        if (len < 7) {
            out += char((len << 5) | (off >> 8));
        } else {
            out += char((7 << 5) | (off >> 8));
            out += char(len - 7);
        }
        out += char(off & 255);
        i += best;
    }
    flush();
    return out;
}

TEST(Lzf, RandomAndRepetitiveDataRoundTrip) {
    std::mt19937 rng(5);
    for (int trial = 0; trial < 20; ++trial) {
        std::string data(size_t(rng() % 3000), '\0');
        for (char& c : data) c = char(trial % 2 ? rng() % 4 : rng() % 256);
        const std::string z = lzf_compress(data);
        std::vector<uint8_t> back(data.size());
        ASSERT_TRUE(detail::lzf_decompress(reinterpret_cast<const uint8_t*>(z.data()), z.size(),
                                           back.data(), back.size()));
        EXPECT_EQ(std::string(back.begin(), back.end()), data);
        if (z.empty()) continue;
        // Cut short, or expected to expand to more than it does: refused, never overrun.
        EXPECT_FALSE(detail::lzf_decompress(reinterpret_cast<const uint8_t*>(z.data()),
                                            z.size() - 1, back.data(), back.size()));
        std::vector<uint8_t> more(data.size() + 1);
        EXPECT_FALSE(detail::lzf_decompress(reinterpret_cast<const uint8_t*>(z.data()), z.size(),
                                            more.data(), more.size()));
    }
    const uint8_t far_back[] = {0x20, 0x05};  // a reference before the start
    uint8_t out[3];
    EXPECT_FALSE(detail::lzf_decompress(far_back, 2, out, 3));
}

// PCL's layout for PointXYZRGBNormal-like data, fields in a deliberately odd order, with a
// padding field and curvature. `data` is ascii, binary or binary_compressed.
std::string pcd(const std::string& data, const std::string& points_line = "POINTS 4") {
    std::string h =
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
        "FIELDS normal_x normal_y normal_z rgb _ x y z curvature\n"
        "SIZE 4 4 4 4 1 4 4 8 4\nTYPE F F F F U F F F F\nCOUNT 1 1 1 1 3 1 1 1 1\n"
        "WIDTH 4\nHEIGHT 1\nVIEWPOINT 1 2 3 1 0 0 0\n" +
        points_line + "\nDATA " + data + "\n";
    auto rgb = [](size_t i) {
        return (uint32_t(kRgb8[i].x) << 16) | (uint32_t(kRgb8[i].y) << 8) | uint32_t(kRgb8[i].z);
    };
    if (data == "ascii") {
        for (size_t i = 0; i < kP.size(); ++i) {
            h += num(kN[i].x) + " " + num(kN[i].y) + " " + num(kN[i].z) + " " +
                 num(std::bit_cast<float>(rgb(i))) + " 0 0 0 " + num(kP[i].x) + " " + num(kP[i].y) +
                 " " + num(kP[i].z) + " 0.5\n";
        }
        return h;
    }
    std::vector<std::string> field(9);  // each field's values, for the field-major layout
    for (size_t i = 0; i < kP.size(); ++i) {
        put(field[0], kN[i].x), put(field[1], kN[i].y), put(field[2], kN[i].z);
        put(field[3], rgb(i));
        field[4] += std::string(3, '\0');
        put(field[5], kP[i].x), put(field[6], kP[i].y), put(field[7], double(kP[i].z));
        put(field[8], 0.5f);
    }
    const size_t sizes[9] = {4, 4, 4, 4, 3, 4, 4, 8, 4};
    std::string body;
    if (data == "binary") {
        for (size_t i = 0; i < kP.size(); ++i)
            for (size_t f = 0; f < 9; ++f) body += field[f].substr(i * sizes[f], sizes[f]);
        return h + body;
    }
    for (const std::string& f : field) body += f;
    const std::string z = lzf_compress(body);
    put(h, uint32_t(z.size()));
    put(h, uint32_t(body.size()));
    return h + z;
}

TEST(Pcd, AllThreeEncodingsReadAlikeWithTheViewpoint) {
    ScratchDir dir;
    for (const char* data : {"ascii", "binary", "binary_compressed"}) {
        SCOPED_TRACE(data);
        const ModelData m = read_model(dir.write("c.pcd", pcd(data)));
        expect_points(m, true, true);
        ASSERT_TRUE(m.viewpoint.has_value());
        EXPECT_EQ(m.viewpoint->origin, (Vec3{1, 2, 3}));
        EXPECT_EQ(m.viewpoint->orientation, (std::array<float, 4>{1, 0, 0, 0}));
        ASSERT_EQ(m.notes.size(), 1u);
        EXPECT_NE(m.notes[0].find("curvature"), std::string::npos);
        EXPECT_EQ(m.notes[0].find(" _"), std::string::npos);  // padding is not news
    }
}

TEST(Pcd, NanPointsOfAnOrganisedCloudAreLeftOutWithANote) {
    ScratchDir dir;
    const std::string s =
        "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nHEIGHT 2\nDATA ascii\n"
        "1 2 3\nnan nan nan\n4 5 6\nnan 0 0\n";
    const ModelData m = read_pcd(dir.write("org.pcd", s));
    ASSERT_EQ(m.points.size(), 2u);
    EXPECT_EQ(m.points.positions[1], (Vec3{4, 5, 6}));
    EXPECT_FALSE(m.viewpoint.has_value());
    ASSERT_EQ(m.notes.size(), 1u);
    EXPECT_NE(m.notes[0].find("2 points with NaN"), std::string::npos);
}

TEST(Pcd, BadInputIsRejectedNamingTheFieldOrByte) {
    ScratchDir dir;
    const std::string bin = pcd("binary"), zip = pcd("binary_compressed");
    auto file = [&](const char* name, const std::string& s) { return dir.write(name, s); };
    EXPECT_READ_ERROR(read_pcd(file("t.pcd", bin.substr(0, bin.size() - 5))), "t.pcd", "truncated",
                      "byte");
    EXPECT_READ_ERROR(read_pcd(file("x.pcd", bin + "x")), "x.pcd", "after the last point");
    EXPECT_READ_ERROR(read_pcd(file("w.pcd", pcd("ascii", "POINTS 5"))), "w.pcd",
                      "WIDTH 4 x HEIGHT 1 is not POINTS 5");
    EXPECT_READ_ERROR(read_pcd(file("h.pcd",
                                    "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n"
                                    "POINTS 4000000000\nDATA binary\n")),
                      "h.pcd", "cannot fit");
    EXPECT_READ_ERROR(read_pcd(file("d.pcd", "FIELDS x y z\nDATA lzma\n")), "d.pcd",
                      "header line 2", "unknown DATA 'lzma'");
    EXPECT_READ_ERROR(read_pcd(file("nox.pcd", "FIELDS y z\nDATA ascii\n")), "nox.pcd",
                      "no 'x' field");
    EXPECT_READ_ERROR(read_pcd(file("sz.pcd", "FIELDS x y z\nSIZE 4 4\nDATA ascii\n")), "sz.pcd",
                      "SIZE has 2 entries for 3 fields");
    EXPECT_READ_ERROR(read_pcd(file("ty.pcd", "FIELDS x y z\nTYPE F F Q\nDATA ascii\n")), "ty.pcd",
                      "field z", "unknown TYPE 'Q'");
    EXPECT_READ_ERROR(read_pcd(file("nd.pcd", "FIELDS x y z\nPOINTS 1\n")), "nd.pcd",
                      "missing DATA");
    EXPECT_READ_ERROR(read_pcd(file("kw.pcd", "FIELDS x y z\nBOGUS 1\nDATA ascii\n")), "kw.pcd",
                      "unknown keyword 'BOGUS'");
    EXPECT_READ_ERROR(
        read_pcd(file("a.pcd", "FIELDS x y z\nPOINTS 2\nDATA ascii\n1.0 2.0 3.0\n1.0 2.0\n")),
        "a.pcd", "point 1 (line 5)", "expected 3 values, found 2");
    EXPECT_READ_ERROR(read_pcd(file("nn.pcd",
                                    "FIELDS x y z normal_x normal_y normal_z\nPOINTS 1\n"
                                    "DATA ascii\n1 2 3 nan 0 0\n")),
                      "nn.pcd", "point 0 (line 4)", "non-finite normal");
    std::string inf = bin;  // the first point's normal_x, in the binary records
    const float infinity = INFINITY;
    std::memcpy(&inf[bin.find("DATA binary\n") + 12], &infinity, 4);
    EXPECT_READ_ERROR(read_pcd(file("inf.pcd", inf)), "inf.pcd", "point 0 (byte",
                      "non-finite normal");
    EXPECT_READ_ERROR(
        read_pcd(file("g.pcd", "FIELDS x y z\nPOINTS 2\nDATA ascii\n1 2 3\n1 2 zz\n")), "g.pcd",
        "point 1 (line 5): field z", "invalid number 'zz'");
    // A packed colour written as an integer must fit 32 bits (a fuzzer's 3.3e19 once was UB).
    const std::string urgb = "FIELDS x y z rgb\nTYPE F F F U\nPOINTS 1\nDATA ascii\n1 2 3 ";
    EXPECT_READ_ERROR(read_pcd(file("c1.pcd", urgb + "3.27e19\n")), "c1.pcd",
                      "point 0 (line 5): field rgb", "not a packed 32-bit colour");
    EXPECT_READ_ERROR(read_pcd(file("c2.pcd", urgb + "1.5\n")), "c2.pcd", "field rgb",
                      "not a packed 32-bit colour");
    const ModelData ok = read_pcd(file("c3.pcd", urgb + std::to_string(0xff8040u) + "\n"));
    ASSERT_EQ(ok.points.colors.size(), 1u);
    EXPECT_EQ(ok.points.colors[0], (Vec3{255, 128, 64} / 255.0f));
    const size_t sizes = zip.find("DATA binary_compressed\n") + 23;
    std::string lie = zip;
    lie[sizes + 3] = '\x7f';  // a compressed size larger than the file
    EXPECT_READ_ERROR(read_pcd(file("z1.pcd", lie)), "z1.pcd", "compressed size");
    std::string big = zip;
    big[sizes + 7] = '\x7f';  // an uncompressed size that is not POINTS x the record
    EXPECT_READ_ERROR(read_pcd(file("z2.pcd", big)), "z2.pcd", "uncompressed size");
    std::string corrupt = zip;
    corrupt[sizes + 8] = '\xff';  // a back-reference before the start of the output
    EXPECT_READ_ERROR(read_pcd(file("z3.pcd", corrupt)), "z3.pcd", "corrupt LZF");
}

// ---- OBJ
// ------------------------------------------------------------------------------------------

TEST(Obj, PolygonsNegativeIndicesAndEveryCornerFormRead) {
    ScratchDir dir;
    const std::string s =
        "# exported\nmtllib m.mtl\no square\n"
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
        "usemtl red\ns off\n"
        "f 1/1/1 2//1 3/1/1 4//1\n"  // a quad: two triangles
        "g top\nv 0.5 0.5 1\n"
        "f -2 -3 -1\n"                   // relative: vertices 3, 2, 5
        "f 5/1 4/1 -4/1\nl 1 2\np 1\n";  // v/vt; lines and points are skipped
    const ModelData m = read_model(dir.write("m.obj", s));
    ASSERT_EQ(m.points.size(), 5u);
    EXPECT_EQ(m.points.positions[4], (Vec3{0.5f, 0.5f, 1}));
    ASSERT_EQ(m.triangles.size(), 4u);
    EXPECT_EQ(m.triangles[0], (Tri{0, 1, 2}));
    EXPECT_EQ(m.triangles[1], (Tri{0, 2, 3}));
    EXPECT_EQ(m.triangles[2], (Tri{3, 2, 4}));
    EXPECT_EQ(m.triangles[3], (Tri{4, 3, 1}));
    // Vertex 5 has no vn: the normals are not kept, and that is noted.
    EXPECT_TRUE(m.points.normals.empty());
    ASSERT_EQ(m.notes.size(), 1u);
    EXPECT_NE(m.notes[0].find("vn"), std::string::npos);
}

TEST(Obj, VertexNormalsAndColoursAreKeptWhenEveryVertexHasOne) {
    ScratchDir dir;
    const ModelData m = read_obj(dir.write(
        "c.obj", "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nvn 0 0 -1\nf 1//1 3//1 2//1\n"));
    ASSERT_EQ(m.points.normals.size(), 3u);
    EXPECT_EQ(m.points.normals[2], (Vec3{0, 0, -1}));
    ASSERT_EQ(m.points.colors.size(), 3u);
    EXPECT_EQ(m.points.colors[1], (Vec3{0, 1, 0}));
    EXPECT_TRUE(m.notes.empty());
}

TEST(Obj, BadInputIsRejectedNamingTheLine) {
    ScratchDir dir;
    const std::string v3 = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    auto file = [&](const char* name, const std::string& s) { return dir.write(name, s); };
    EXPECT_READ_ERROR(read_obj(file("z.obj", v3 + "f 0 1 2\n")), "z.obj", "line 4",
                      "vertex index 0 out of range");
    EXPECT_READ_ERROR(read_obj(file("r.obj", v3 + "f 1 2 4\n")), "r.obj", "line 4",
                      "index 4 out of range (3 defined so far)");
    EXPECT_READ_ERROR(read_obj(file("n.obj", v3 + "f -1 -2 -4\n")), "n.obj", "index -4");
    EXPECT_READ_ERROR(read_obj(file("vn.obj", v3 + "f 1//1 2 3\n")), "vn.obj", "normal index 1");
    EXPECT_READ_ERROR(read_obj(file("d.obj", v3 + "f 1 2\n")), "d.obj", "degenerate face");
    EXPECT_READ_ERROR(read_obj(file("s.obj", "v 1 2\n")), "s.obj", "line 1",
                      "expected 3, 4 or 6 numbers, found 2");
    EXPECT_READ_ERROR(read_obj(file("nan.obj", "v 1 nan 2\n")), "nan.obj", "non-finite");
    EXPECT_READ_ERROR(read_obj(file("g.obj", "v 1 2 3\nPK\x03\x04 junk\n")), "g.obj", "line 2",
                      "unknown statement");
    EXPECT_READ_ERROR(read_obj(file("i.obj", v3 + "f 1 2 x\n")), "i.obj", "invalid vertex index");
    EXPECT_READ_ERROR(read_obj(file("e.obj", "")), "e.obj", "empty file");
}

// ---- STL
// ------------------------------------------------------------------------------------------

// A unit tetrahedron, outward wound, as triangles of corners.
const std::vector<std::array<Vec3, 3>> kTetra = {
    {{{0, 0, 0}, {0, 1, 0}, {1, 0, 0}}},
    {{{0, 0, 0}, {1, 0, 0}, {0, 0, 1}}},
    {{{0, 0, 0}, {0, 0, 1}, {0, 1, 0}}},
    {{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}},
};

Vec3 facet_normal(const std::array<Vec3, 3>& t) {
    const Vec3 n = cross(t[1] - t[0], t[2] - t[0]);
    return n / length(n);
}

std::string ascii_stl(const std::vector<std::array<Vec3, 3>>& tris) {
    std::string s = "solid tetra\n";
    for (const auto& t : tris) {
        const Vec3 n = facet_normal(t);
        s += "  facet normal " + num(n.x) + " " + num(n.y) + " " + num(n.z) + "\n    outer loop\n";
        for (Vec3 v : t) s += "      vertex " + num(v.x) + " " + num(v.y) + " " + num(v.z) + "\n";
        s += "    endloop\n  endfacet\n";
    }
    return s + "endsolid tetra\n";
}

std::string binary_stl(const std::vector<std::array<Vec3, 3>>& tris, const std::string& header) {
    std::string s = header;
    s.resize(80, ' ');
    put(s, uint32_t(tris.size()));
    for (const auto& t : tris) {
        const Vec3 n = facet_normal(t);
        for (Vec3 v : {n, t[0], t[1], t[2]}) put(s, v.x), put(s, v.y), put(s, v.z);
        put(s, uint16_t(0));
    }
    return s;
}

void expect_tetra(const ModelData& m) {
    ASSERT_EQ(m.points.size(), 4u);  // twelve corners merged into four vertices
    ASSERT_EQ(m.triangles.size(), 4u);
    for (size_t f = 0; f < 4; ++f) {
        for (int k = 0; k < 3; ++k) EXPECT_EQ(m.points.positions[m.triangles[f][k]], kTetra[f][k]);
    }
}

TEST(Stl, AsciiAndBinaryReadAlikeAndMergeCorners) {
    ScratchDir dir;
    expect_tetra(read_model(dir.write("a.stl", ascii_stl(kTetra))));
    expect_tetra(read_model(dir.write("b.stl", binary_stl(kTetra, "binary"))));
    // Many exporters start the binary header with "solid": the size tells.
    expect_tetra(read_model(dir.write("c.STL", binary_stl(kTetra, "solid exported"))));
}

TEST(Stl, AFacetWoundAgainstItsNormalIsRewound) {
    ScratchDir dir;
    std::string s = ascii_stl(kTetra);
    const std::string first = "vertex 0 1 0\n      vertex 1 0 0";
    const size_t at = s.find(first);
    ASSERT_NE(at, std::string::npos);
    s.replace(at, first.size(), "vertex 1 0 0\n      vertex 0 1 0");
    expect_tetra(read_stl(dir.write("w.stl", s)));
}

TEST(Stl, BadInputIsRejectedNamingTheLineOrByte) {
    ScratchDir dir;
    const std::string bin = binary_stl(kTetra, "x");
    auto file = [&](const char* name, const std::string& s) { return dir.write(name, s); };
    EXPECT_READ_ERROR(read_stl(file("t.stl", bin.substr(0, bin.size() - 1))), "t.stl", "byte 80",
                      "says 4 facets");
    EXPECT_READ_ERROR(read_stl(file("h.stl", bin.substr(0, 50))), "h.stl", "truncated");
    std::string huge = bin;
    huge[83] = '\x7f';
    EXPECT_READ_ERROR(read_stl(file("c.stl", huge)), "c.stl", "facets");
    std::string nan = bin;
    const float q = std::nanf("");
    std::memcpy(&nan[84 + 12], &q, 4);
    EXPECT_READ_ERROR(read_stl(file("n.stl", nan)), "n.stl", "byte 84", "facet 0", "non-finite");
    const std::string a = ascii_stl(kTetra);
    EXPECT_READ_ERROR(read_stl(file("at.stl", a.substr(0, a.find("endloop")))), "at.stl",
                      "truncated");
    std::string two = a;
    two.replace(two.find("vertex 0 0 0"), 12, "vertex 0 0");
    EXPECT_READ_ERROR(read_stl(file("v.stl", two)), "v.stl", "line 4", "expected 3 values");
    std::string word = a;
    word.replace(word.find("outer loop"), 10, "inner loop");
    EXPECT_READ_ERROR(read_stl(file("o.stl", word)), "o.stl", "line 3", "expected 'outer'");
    std::string bad = a;
    bad.replace(bad.find("vertex 0 0 0"), 12, "vertex 0 0 q");
    EXPECT_READ_ERROR(read_stl(file("q.stl", bad)), "q.stl", "invalid number 'q'");
    EXPECT_READ_ERROR(read_stl(file("e.stl", "")), "e.stl", "empty file");
}

// ---- PLY: PCL's names, doubles, emission ------------------------------------------------------

TEST(PlyFields, PclNormalNamesDoubleCoordinatesAndEmissionAreRead) {
    ScratchDir dir;
    const std::string s =
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
        "property double z\nproperty float normal_x\nproperty float normal_y\n"
        "property float normal_z\nproperty float curvature\nproperty float emission_r\n"
        "property float emission_g\nproperty float emission_b\nend_header\n"
        "0.1 0.2 0.30000000000000004 0 0 1 0.5 2 3 4\n1 2 3 1 0 0 0.5 0 0 0\n";
    const ModelData m = read_ply(dir.write("pcl.ply", s));
    ASSERT_EQ(m.points.size(), 2u);
    EXPECT_EQ(m.points.positions[0], (Vec3{0.1f, 0.2f, 0.3f}));
    ASSERT_EQ(m.points.normals.size(), 2u);
    EXPECT_EQ(m.points.normals[1], (Vec3{1, 0, 0}));
    ASSERT_EQ(m.points.emission.size(), 2u);
    EXPECT_EQ(m.points.emission[0], (Vec3{2, 3, 4}));
    ASSERT_EQ(m.notes.size(), 1u);
    EXPECT_NE(m.notes[0].find("vertex.curvature"), std::string::npos);
    EXPECT_READ_ERROR(read_ply(dir.write("neg.ply", s.substr(0, s.rfind("0 0 0")) + "0 -1 0\n")),
                      "neg.ply", "vertex 1", "invalid emission");
}

TEST(PlyFields, EmissionRoundTripsThroughTheWriter) {
    ScratchDir dir;
    PointSet ps;
    ps.positions = kP;
    ps.emission = {{0, 0, 0}, {1.5f, 2, 0}, {0, 0, 0}, {0, 0, 7}};
    for (bool binary : {true, false}) {
        write_ply(dir.path("e.ply"), ps, binary);
        const ModelData m = read_ply(dir.path("e.ply"));
        EXPECT_EQ(m.points.emission.size(), 4u);
        for (size_t i = 0; i < 4; ++i) EXPECT_EQ(m.points.emission[i], ps.emission[i]);
    }
    ps.emission.assign(4, Vec3{});  // nothing emits: nothing written
    write_ply(dir.path("n.ply"), ps);
    EXPECT_TRUE(read_ply(dir.path("n.ply")).points.emission.empty());
}

TEST(OffNotes, FaceColoursAndExtraVertexValuesAreNoted) {
    const ModelData m = read_off(std::string(VMAP_TEST_DATA) + "/io/pyramid.off");
    ASSERT_FALSE(m.notes.empty());
    EXPECT_NE(m.notes.back().find("after the faces' indices"), std::string::npos);
    ScratchDir dir;
    const ModelData v =
        read_off(dir.write("uv.off", "OFF\n3 1 0\n0 0 0 9\n1 0 0 9\n0 1 0 9\n3 0 1 2\n"));
    ASSERT_EQ(v.notes.size(), 1u);
    EXPECT_NE(v.notes[0].find("vertex lines"), std::string::npos);
}

// ---- dispatch ------------------------------------------------------------------------------

TEST(Formats, MeshFilesAreToldFromPointClouds) {
    ScratchDir dir;
    EXPECT_TRUE(model_has_faces(dir.write("a.stl", ascii_stl(kTetra))));
    EXPECT_TRUE(model_has_faces(dir.write("a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")));
    EXPECT_FALSE(model_has_faces(dir.write("b.obj", "v 0 0 0\nv 1 0 0\n")));
    EXPECT_TRUE(model_has_faces(dir.write("a.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")));
    EXPECT_FALSE(model_has_faces(dir.write("b.off", "OFF 1 0 0\n0 0 0\n")));
    EXPECT_FALSE(model_has_faces(dir.write("a.xyz", "0 0 0\n")));
    EXPECT_FALSE(model_has_faces(dir.write("a.pcd", pcd("ascii"))));
    EXPECT_TRUE(is_scene_input(dir.path("a.obj")));
    EXPECT_FALSE(is_scene_input(dir.path("a.obj"), /*as_points=*/true));
    EXPECT_TRUE(is_scene_input(dir.path("whatever.json")));
    EXPECT_READ_ERROR(model_has_faces(dir.path("gone.ply")), "gone.ply", "no such file");
    EXPECT_READ_ERROR(read_model(dir.write("m.3ds", "x")), "m.3ds", "unknown model format");
}

// ---- one geometry, one V-map, whatever the format -------------------------------------------

// Two boxes facing each other (a convex mesh alone sees nothing of itself), written as OFF
// and rewritten in each format from the floats it reads to.
TEST(Formats, TheSameMeshGivesTheSameVmapAsOffPlyObjOrStl) {
    ScratchDir dir;
    const ModelData cube = read_off(std::string(VMAP_TEST_DATA) + "/oracle/cube.off");
    ASSERT_FALSE(cube.triangles.empty());
    std::string off_text = "OFF\n" + std::to_string(2 * cube.points.size()) + " " +
                           std::to_string(2 * cube.triangles.size()) + " 0\n";
    for (float dx : {0.0f, 2.5f}) {
        for (Vec3 p : cube.points.positions) {
            off_text += num(p.x * 0.7f + dx) + " " + num(p.y * 1.3f) + " " + num(p.z) + "\n";
        }
    }
    for (uint32_t o : {0u, uint32_t(cube.points.size())}) {
        for (const Tri& t : cube.triangles) {
            off_text += "3 " + std::to_string(t[0] + o) + " " + std::to_string(t[1] + o) + " " +
                        std::to_string(t[2] + o) + "\n";
        }
    }
    const std::string off_path = dir.write("boxes.off", off_text);
    const ModelData off = read_off(off_path);
    const auto& v = off.points.positions;
    std::vector<std::array<Vec3, 3>> tris;
    std::string obj, ply = "ply\nformat ascii 1.0\nelement vertex " + std::to_string(v.size()) +
                           "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                           std::to_string(off.triangles.size()) +
                           "\nproperty list uchar int vertex_indices\nend_header\n";
    for (Vec3 p : v) {
        obj += "v " + num(p.x) + " " + num(p.y) + " " + num(p.z) + "\n";
        ply += num(p.x) + " " + num(p.y) + " " + num(p.z) + "\n";
    }
    for (const Tri& t : off.triangles) {
        obj += "f " + std::to_string(int(t[0]) - int(v.size())) + " " + std::to_string(t[1] + 1) +
               " " + std::to_string(t[2] + 1) + "\n";
        ply += "3 " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " +
               std::to_string(t[2]) + "\n";
        tris.push_back({v[t[0]], v[t[1]], v[t[2]]});
    }
    const std::vector<std::string> files = {
        off_path, dir.write("boxes.ply", ply), dir.write("boxes.obj", obj),
        dir.write("boxes.stl", ascii_stl(tris)),
        dir.write("boxes_b.stl", binary_stl(tris, "solid binary"))};
    std::optional<VisibilityMap> first;
    for (const std::string& f : files) {
        SCOPED_TRACE(f);
        Scene sc = load_scene(f);
        sc.points = 1500;
        VisibilityMap vm = build_vmap(sample_scene(sc), test::cpu_params(5, 4));
        ASSERT_GT(vm.num_links(), 0u);
        if (!first) {
            first = std::move(vm);
            continue;
        }
        EXPECT_EQ(vm.points().positions, first->points().positions);
        EXPECT_EQ(vm.points().normals, first->points().normals);
        EXPECT_EQ(vm.link_offsets(), first->link_offsets());
        EXPECT_TRUE(std::ranges::equal(vm.link_targets(), first->link_targets()));
    }
}

// ---- meshes as scenes, scenes without the room -------------------------------------------------

TEST(MeshScene, AMeshFileIsOneOutwardSurfaceWithItsVertexColours) {
    ScratchDir dir;
    // Inside-out tetrahedron with per-vertex colours: re-wound outward, colours interpolated.
    std::string s =
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nproperty uchar red\nproperty uchar green\n"
        "property uchar blue\nelement face 4\nproperty list uchar int vertex_indices\n"
        "end_header\n0 0 0 255 0 0\n1 0 0 255 0 0\n0 1 0 255 0 0\n0 0 1 255 0 0\n"
        "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
    s.replace(s.find("3 0 2 1"), 7, "3 0 1 2");  // now every face winds inward
    s.replace(s.find("3 0 1 3"), 7, "3 0 3 1");
    s.replace(s.find("3 0 3 2"), 7, "3 0 2 3");
    s.replace(s.find("3 1 2 3"), 7, "3 1 3 2");
    const Scene sc = load_scene(dir.write("t.ply", s));
    EXPECT_FALSE(sc.has_room);
    ASSERT_EQ(sc.surfaces.size(), 1u);
    EXPECT_EQ(sc.room_size, (Vec3{1, 1, 1}));
    const PointSet ps = sample_scene(sc);
    const Vec3 centre{0.25f, 0.25f, 0.25f};
    for (size_t i = 0; i < ps.size(); ++i) {
        ASSERT_GT(dot(ps.normals[i], ps.positions[i] - centre), 0) << i;
        ASSERT_NEAR(ps.colors[i].x, 1.0f, 1e-6f);
        ASSERT_EQ(ps.colors[i].y, 0.0f);
    }
    EXPECT_READ_ERROR(load_scene(dir.write("c.xyz", "0 0 0\n1 0 0\n0 1 0\n")), "c.xyz",
                      "has no faces");
}

TEST(MeshScene, ANullRoomKeepsMeshesWhereTheFileHasThemWithTheirEmission) {
    ScratchDir dir;
    dir.write("t.stl", ascii_stl(kTetra));
    dir.write("c.xyzn", rows(" ", true, false));
    const std::string path =
        dir.write("s.json",
                  R"({"room": null, "meshes": [{"file": "t.stl", "emission": [1, 2, 3]},
            {"file": "t.stl", "position": [5, 0, 0], "size": 2, "albedo": [0.1, 0.2, 0.3]}],
            "clouds": [{"file": "c.xyzn", "emission": [4, 4, 4], "albedo": [0.5, 0.5, 0.5]}],
            "sampling": {"points": 400, "seed": 3}})");
    const Scene sc = load_scene(path);
    EXPECT_FALSE(sc.has_room);
    ASSERT_EQ(sc.surfaces.size(), 2u);
    EXPECT_EQ(sc.surfaces[0].mesh.vertices, read_stl(dir.path("t.stl")).points.positions);
    EXPECT_EQ(sc.surfaces[0].emission, (Vec3{1, 2, 3}));
    ASSERT_EQ(sc.clouds.size(), 1u);
    const PointSet ps = sample_scene(sc);
    ASSERT_EQ(ps.size(), 400u + kP.size());
    ASSERT_EQ(ps.emission.size(), ps.size());
    for (size_t i = 0; i < kP.size(); ++i) {
        EXPECT_EQ(ps.positions[400 + i], kP[i]);
        EXPECT_EQ(ps.normals[400 + i], kN[i]);
        EXPECT_EQ(ps.emission[400 + i], (Vec3{4, 4, 4}));
    }
    // The emitting surface's points carry its emission, scaled alike so that they emit the
    // surface's power (sample_scene).
    size_t emitting = 0;
    Vec3 scaled{};
    for (size_t i = 0; i < 400; ++i) {
        const bool first = ps.positions[i].x < 2;
        emitting += first;
        if (first && scaled == Vec3{}) scaled = ps.emission[i];
        EXPECT_EQ(ps.emission[i], (first ? scaled : Vec3{})) << i;
        if (!first) {
            EXPECT_EQ(ps.colors[i], (Vec3{0.1f, 0.2f, 0.3f})) << i;
        }
    }
    EXPECT_GT(emitting, 0u);
    EXPECT_NEAR(scaled.y / scaled.x, 2.0, 1e-5);
    EXPECT_NEAR(scaled.z / scaled.x, 3.0, 1e-5);
    EXPECT_EQ(sc.room_size.x, 6.0f);  // the box of both meshes and the cloud
}

TEST(MeshScene, CloudsArePlacedWithTheirNormalsAndRadii) {
    ScratchDir dir;
    dir.write("c.xyzn", rows(" ", true, false));
    const Scene sc =
        load_scene(dir.write("s.json", R"({"room": null, "clouds": [{"file": "c.xyzn", "scale": 2,
                      "rotate": [0, 0, 90], "position": [10, 0, 0]}]})"));
    ASSERT_EQ(sc.clouds.size(), 1u);
    const PointSet& c = sc.clouds[0];
    const PointSet raw = load_point_cloud(dir.path("c.xyzn"));
    ASSERT_EQ(c.size(), kP.size());
    float ylo = INFINITY;
    for (size_t i = 0; i < c.size(); ++i) {
        // Rotated 90 degrees about z: (x, y, z) -> (-y, x, z), for normals as for positions.
        EXPECT_NEAR(c.normals[i].x, -kN[i].y, 1e-6f) << i;
        EXPECT_NEAR(c.normals[i].y, kN[i].x, 1e-6f) << i;
        EXPECT_FLOAT_EQ(c.radii[i], 2 * raw.radii[i]) << i;
        ylo = std::min(ylo, c.positions[i].y);
    }
    EXPECT_NEAR(ylo, 0.0f, 1e-5f);  // stood on its position
    const Vec3 d = c.positions[1] - c.positions[0], d0 = kP[1] - kP[0];
    EXPECT_NEAR(length(d), 2 * length(d0), 1e-5f);
}

TEST(MeshScene, ScenesWithoutTheRoomAreCheckedByField) {
    ScratchDir dir;
    dir.write("t.stl", ascii_stl(kTetra));
    EXPECT_READ_ERROR(load_scene(dir.write("l.json", R"({"room": null, "light": {}})")), "l.json",
                      "light", "needs the room");
    EXPECT_READ_ERROR(load_scene(dir.write("e.json", R"({"room": null})")), "e.json",
                      "no meshes or clouds");
    EXPECT_READ_ERROR(load_scene(dir.write("m.json", R"({"meshes": [{"file": "t.stl",
                      "emission": [1, -1, 0]}]})")),
                      "m.json", "meshes[0].emission[1]");
    EXPECT_READ_ERROR(load_scene(dir.write("c.json", R"({"clouds": [{"file": "t.stl",
                      "flip_normals": true}]})")),
                      "c.json", "clouds[0].flip_normals", "unknown key");
    // The default room is still there when the key is absent.
    const Scene with_room = load_scene(dir.write("r.json", R"({"meshes": [{"file": "t.stl"}]})"));
    EXPECT_TRUE(with_room.has_room);
    EXPECT_EQ(with_room.surfaces.size(), 7u);
}

}  // namespace
}  // namespace vmap

namespace vmap {
namespace {

// The fuzz seeds (fuzz/corpus/<reader>/) read, or fail with a vmap::Error when their name says
// they are broken; nothing else ever escapes a reader.
TEST(Formats, FuzzSeedsReadOrFailCleanly) {
    namespace fs = std::filesystem;
    const fs::path root = fs::path(VMAP_SOURCE_DIR) / "fuzz" / "corpus";
    size_t seen = 0;
    for (const char* reader : {"xyz", "pcd", "obj", "stl"}) {
        for (const auto& entry : fs::directory_iterator(root / reader)) {
            const std::string name = entry.path().filename().string();
            SCOPED_TRACE(name);
            const bool broken = name.find("bad") != std::string::npos ||
                                name.find("nan") != std::string::npos ||
                                name.find("truncated") != std::string::npos ||
                                name.find("huge") != std::string::npos ||
                                name.find("out-of-range") != std::string::npos;
            ++seen;
            if (broken) {
                EXPECT_THROW((void)read_model(entry.path().string()), Error);
            } else {
                EXPECT_GT(read_model(entry.path().string()).points.size(), 0u);
            }
        }
    }
    EXPECT_GE(seen, 16u);
}

}  // namespace
}  // namespace vmap
