// The OFF reader (src/io/off.cpp): headers, colours and normals, every kind of bad input.
#include "io_test_util.h"

namespace vmap {
namespace {

// ---- OFF ---------------------------------------------------------------------------------------

TEST(Off, PyramidFixtureWithCommentsBlankLinesQuadAndFaceColoursIsRead) {
    const ModelData m = read_off(kData + "pyramid.off");
    ASSERT_EQ(m.points.size(), 5u);
    EXPECT_FALSE(m.points.has_normals());
    EXPECT_FALSE(m.points.has_colors());
    EXPECT_EQ(m.points.positions[2], (Vec3{1, 1, 0}));
    EXPECT_EQ(m.points.positions[4], (Vec3{0.5f, 0.5f, 1}));
    const std::vector<Tri> expected = {{0, 3, 2}, {0, 2, 1}, {0, 1, 4},
                                       {1, 2, 4}, {2, 3, 4}, {3, 0, 4}};
    EXPECT_EQ(m.triangles, expected);
}

TEST(Off, CountsMayShareTheHeaderLine) {
    ScratchDir dir;
    const ModelData m = read_off(
        dir.write("inline.off", "OFF 4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n"));
    EXPECT_EQ(m.points.size(), 4u);
    EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}, {0, 2, 3}}));
    // The edge count may be left out, and lines may end in CRLF.
    const ModelData n =
        read_off(dir.write("crlf.off", "OFF\r\n3 1\r\n0 0 0\r\n1 0 0\r\n0 1 0\r\n3 0 1 2\r\n"));
    EXPECT_EQ(n.triangles, (std::vector<Tri>{{0, 1, 2}}));
}

TEST(Off, VertexColoursAndNormalsAreReadForColouredAndNormalHeaders) {
    ScratchDir dir;
    // Integer 0..255 colours (with alpha) are scaled; float colours are kept.
    const ModelData c = read_off(dir.write(
        "c.off", "COFF\n3 1 0\n0 0 0 255 0 0 255\n1 0 0 0 51 0 255\n0 1 0 0 0 255 255\n3 0 1 2\n"));
    ASSERT_EQ(c.points.colors.size(), 3u);
    EXPECT_EQ(c.points.colors[0], (Vec3{1, 0, 0}));
    EXPECT_FLOAT_EQ(c.points.colors[1].y, 0.2f);
    const ModelData f = read_off(
        dir.write("f.off", "COFF\n3 1 0\n0 0 0 0.25 0.5 1\n1 0 0 0 0 0\n0 1 0 1 1 1\n3 0 1 2\n"));
    EXPECT_EQ(f.points.colors[0], (Vec3{0.25f, 0.5f, 1}));
    EXPECT_FALSE(f.points.has_normals());

    const ModelData n = read_off(
        dir.write("n.off", "NOFF\n3 1 0\n0 0 0 0 0 2\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n"));
    ASSERT_EQ(n.points.normals.size(), 3u);
    EXPECT_EQ(n.points.normals[0], (Vec3{0, 0, 2}));  // kept as stored
    EXPECT_FALSE(n.points.has_colors());

    const ModelData cn = read_off(dir.write(
        "cn.off",
        "CNOFF\n3 1 0\n0 0 0 0 0 1 255 0 0\n1 0 0 0 0 1 0 255 0\n0 1 0 0 1 0 0 0 255\n3 0 1 2\n"));
    EXPECT_EQ(cn.points.positions[2], (Vec3{0, 1, 0}));
    EXPECT_EQ(cn.points.normals[2], (Vec3{0, 1, 0}));
    EXPECT_EQ(cn.points.colors[2], (Vec3{0, 0, 1}));
    EXPECT_EQ(cn.triangles.size(), 1u);
}

TEST(Off, BadInputIsRejectedNamingTheFileAndField) {
    ScratchDir dir;
    // Written out long enough that the early size check lets the reader reach the fault.
    const std::string square = "0.0 0.0 0.0\n1.0 0.0 0.0\n1.0 1.0 0.0\n0.0 1.0 0.0\n";
    struct Case {
        std::string text;
        std::vector<std::string_view> parts;
    };
    const Case cases[] = {
        {"", {"empty file"}},
        {"# only a comment\n\n", {"header", "bad magic"}},
        {"ply\nformat ascii 1.0\n", {"header", "bad magic 'ply'"}},
        {"4OFF\n1 0 0\n0 0 0 0\n", {"header", "bad magic '4OFF'"}},
        {"OFF BINARY\n", {"header", "binary OFF"}},
        {"OFF\n", {"header", "missing vertex, face and edge counts"}},
        {"OFF\n4\n", {"header", "found 1 value"}},
        {"OFF\nfour 2 0\n" + square, {"header", "invalid vertex count 'four'"}},
        {"OFF\n-4 2 0\n" + square, {"header", "negative vertex count -4"}},
        {"OFF\n4 -2 0\n" + square, {"header", "negative face count -2"}},
        {"OFF\n4 2 -1\n" + square, {"header", "negative edge count -1"}},
        {"OFF\n99999999999 2 0\n" + square, {"truncated", "99999999999 vertices", "cannot fit"}},
        {"OFF\n4 4000000000 0\n" + square, {"truncated", "4000000000 faces", "cannot fit"}},
        {"OFF\n4 1 0\n0 0 0\n1 0 0\n", {"truncated", "4 vertices", "cannot fit"}},
        {"OFF\n4 1 0\n0.000 0.000 0.000\n1.000 0.000 0.000\n",
         {"truncated: expected 4 vertices, found 2"}},
        {"OFF\n4 2 0\n" + square + "3 0 1 2\n", {"truncated: expected 2 faces, found 1"}},
        {"OFF\n4 1 0\n0.0 0.0 0.0\n1.0 0.0\n1.0 1.0 0.0\n0.0 1.0 0.0\n3 0 1 2\n",
         {"vertex 1 (line 4)", "expected 3 values, found 2"}},
        {"NOFF\n1 0 0\n0 0 0 0 1\n", {"vertex 0 (line 3)", "expected 6 values, found 5"}},
        {"CNOFF\n1 0 0\n0 0 0 0 0 1 1 1\n", {"vertex 0", "expected 9 values, found 8"}},
        {"OFF\n4 1 0\n0 0 0\n1 zero 0\n1 1 0\n0 1 0.0\n3 0 1 2\n",
         {"vertex 1 (line 4)", "invalid number 'zero'"}},
        {"OFF\n4 1 0\n0 0 0\nnan 0 0\n1 1 0\n0 1 0\n3 0 1 2\n",
         {"vertex 1", "non-finite coordinate (nan"}},
        {"OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 -inf\n0 1 0\n3 0 1 2\n",
         {"vertex 2", "non-finite coordinate"}},
        {"OFF\n1 0 0\n0 0 1e39\n", {"vertex 0", "non-finite coordinate"}},
        {"NOFF\n1 0 0\n0 0 0 0 nan 1\n", {"vertex 0", "non-finite normal"}},
        {"COFF\n1 0 0\n0 0 0 1 inf 1\n", {"vertex 0", "non-finite colour"}},
        {"OFF\n4 1 0\n" + square + "4 0 1 2\n", {"face 0 (line 7)", "expected 5 values, found 4"}},
        // A count at the top of int64's range: the message must not overflow adding the count.
        {"OFF\n4 1 0\n" + square + "9223372036854775807 0 1 2\n",
         {"face 0 (line 7)", "expected 9223372036854775808 values, found 4"}},
        {"OFF\n4 1 0\n" + square + "3 0 1 4\n",
         {"face 0 (line 7)", "vertex index 4 out of range (4 vertices)"}},
        {"OFF\n4 1 0\n" + square + "3 0 -1 2\n", {"face 0", "vertex index -1 out of range"}},
        {"OFF\n4 1 0\n" + square + "3 0 1.5 2\n", {"face 0", "invalid vertex index '1.5'"}},
        {"OFF\n4 1 0\n" + square + "2 0 1\n", {"face 0", "degenerate face with 2 vertices"}},
        {"OFF\n4 1 0\n" + square + "x 0 1 2\n", {"face 0", "invalid vertex count 'x'"}},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.text);
        const std::string path = dir.write("bad.off", c.text);
        std::vector<std::string_view> parts = {"bad.off: "};
        parts.insert(parts.end(), c.parts.begin(), c.parts.end());
        expect_error([&] { (void)read_off(path); }, parts);
    }
    EXPECT_READ_ERROR(read_off(dir.path("nothing.off")), "nothing.off: no such file");
}

TEST(Off, DamagedFilesOnlyEverThrowVmapErrors) {
    ScratchDir dir;
    std::mt19937 rng(7);
    for (const std::string& good :
         {slurp(kData + "pyramid.off"),
          std::string("CNOFF 3 1 0\n0 0 0 0 0 1 9 9 9\n1 0 0 0 0 1 1 1 1\n0 1 0 0 1 0 1 0 1\n"
                      "3 0 1 2\n")}) {
        expect_damage_only_throws_vmap_errors(dir, good, ".off", read_off, rng);
    }
}

}  // namespace
}  // namespace vmap
