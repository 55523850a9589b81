// The PLY reader and writer (src/io/ply.cpp): formats, round trips, every kind of bad input.
#include "io/ply_pieces.h"
#include "io_test_util.h"

namespace vmap {
namespace {

// ---- PLY: reading ----------------------------------------------------------------------------

TEST(Ply, AllThreeFormatsReadAlikeAndSkipUnusedElementsAndLists) {
    ScratchDir dir;
    const std::vector<PlyElement> elements = {
        {"camera", {{"float", "pose", "uchar"}, {"int", "id"}}, {{3, 1, 2, 3, 42}, {0, 7}}},
        {"vertex",
         {{"float", "x"},
          {"double", "confidence"},
          {"float", "y"},
          {"float", "uv", "int"},
          {"float", "z"},
          {"float", "nx"},
          {"float", "ny"},
          {"float", "nz"},
          {"uchar", "red"},
          {"uchar", "green"},
          {"uchar", "blue"},
          {"uchar", "alpha"}},
         {{0.5, 0.9, -1.25, 2, 0.1, 0.2, 3, 0, 0, 1, 255, 0, 51, 128},
          {1, 0.8, 0, 0, 2, 1, 0, 0, 0, 255, 0, 7},
          {0, 0.7, 1, 1, 0.3, -4, 0, 1, 0, 0, 0, 255, 9}}},
        {"face",
         {{"int", "tags", "uchar"}, {"uint", "vertex_indices", "uchar"}, {"char", "f"}},
         {{2, 5, 6, 3, 2, 1, 0, -1}}},
        {"trailer", {{"short", "values", "ushort"}}, {{3, 1, 2, 3}, {0}}},
    };
    for (const char* format : kPlyFormats) {
        SCOPED_TRACE(format);
        const ModelData m = read_ply(dir.write("all.ply", make_ply(format, elements)));
        ASSERT_EQ(m.points.size(), 3u);
        EXPECT_EQ(m.points.positions[0], (Vec3{0.5f, -1.25f, 3.0f}));
        EXPECT_EQ(m.points.positions[1], (Vec3{1.0f, 0.0f, 2.0f}));
        EXPECT_EQ(m.points.positions[2], (Vec3{0.0f, 1.0f, -4.0f}));
        ASSERT_EQ(m.points.normals.size(), 3u);
        EXPECT_EQ(m.points.normals[1], (Vec3{1, 0, 0}));
        EXPECT_EQ(m.points.normals[2], (Vec3{0, 1, 0}));
        ASSERT_EQ(m.points.colors.size(), 3u);
        EXPECT_EQ(m.points.colors[0], (Vec3{1.0f, 0.0f, 51.0f / 255.0f}));
        EXPECT_TRUE(m.points.radii.empty());
        ASSERT_EQ(m.triangles.size(), 1u);
        EXPECT_EQ(m.triangles[0], (Tri{2, 1, 0}));
    }
}

TEST(Ply, CoordinatesOfEveryScalarTypeNameAreRead) {
    ScratchDir dir;
    const char* const types[] = {"char",  "uchar",  "short",   "ushort", "int",   "uint",
                                 "float", "double", "int8",    "uint8",  "int16", "uint16",
                                 "int32", "uint32", "float32", "float64"};
    for (const char* format : kPlyFormats) {
        for (const char* type : types) {
            SCOPED_TRACE(std::string(format) + " " + type);
            const std::string path = dir.write(
                "t.ply", make_ply(format, {xyz_vertices({{1, 2, 100}, {0, 127, 3}}, type)}));
            const ModelData m = read_ply(path);
            ASSERT_EQ(m.points.size(), 2u);
            EXPECT_EQ(m.points.positions[0], (Vec3{1, 2, 100}));
            EXPECT_EQ(m.points.positions[1], (Vec3{0, 127, 3}));
        }
    }
}

TEST(Ply, FaceListsOfAnyCountAndIndexTypeAreRead) {
    ScratchDir dir;
    const char* const count_types[] = {"uchar", "char", "ushort", "short", "uint", "int"};
    const char* const index_types[] = {"uchar", "char", "ushort", "short",
                                       "uint",  "int",  "uint32", "int32"};
    for (const char* format : kPlyFormats) {
        for (const char* count_type : count_types) {
            for (const char* index_type : index_types) {
                SCOPED_TRACE(std::string(format) + " list " + count_type + " " + index_type);
                const std::string path = dir.write(
                    "t.ply",
                    make_ply(format, {xyz_vertices(kSquare), faces({{3, 0, 1, 2}, {3, 0, 2, 3}},
                                                                   count_type, index_type)}));
                const ModelData m = read_ply(path);
                ASSERT_EQ(m.triangles.size(), 2u);
                EXPECT_EQ(m.triangles[0], (Tri{0, 1, 2}));
                EXPECT_EQ(m.triangles[1], (Tri{0, 2, 3}));
            }
        }
    }
}

TEST(Ply, PolygonsWithMoreThanThreeCornersAreFanTriangulated) {
    ScratchDir dir;
    const std::vector<std::vector<double>> pentagon = {
        {0, 0, 0}, {1, 0, 0}, {1.5, 1, 0}, {0.5, 2, 0}, {-0.5, 1, 0}};
    for (const char* format : kPlyFormats) {
        SCOPED_TRACE(format);
        const ModelData m = read_ply(dir.write(
            "fan.ply",
            make_ply(format, {xyz_vertices(pentagon),
                              faces({{5, 0, 1, 2, 3, 4}, {4, 4, 3, 1, 0}, {3, 2, 3, 4}})})));
        const std::vector<Tri> expected = {{0, 1, 2}, {0, 2, 3}, {0, 3, 4},
                                           {4, 3, 1}, {4, 1, 0}, {2, 3, 4}};
        EXPECT_EQ(m.triangles, expected);
        EXPECT_EQ(m.mesh().vertices.size(), 5u);
        EXPECT_EQ(m.mesh().triangles, expected);
    }
}

TEST(Ply, AsciiCubeFixtureOfQuadsGivesTwelveOutwardTriangles) {
    const ModelData m = read_ply(kData + "cube_quads.ply");
    ASSERT_EQ(m.points.size(), 8u);
    EXPECT_FALSE(m.points.has_normals());
    EXPECT_FALSE(m.points.has_colors());
    EXPECT_EQ(m.points.positions[2], (Vec3{1, 1, 0}));
    EXPECT_EQ(m.points.positions[7], (Vec3{0, 1, 1}));
    ASSERT_EQ(m.triangles.size(), 12u);
    EXPECT_EQ(m.triangles[0], (Tri{0, 3, 2}));
    EXPECT_EQ(m.triangles[1], (Tri{0, 2, 1}));
    const Vec3 centre{0.5f, 0.5f, 0.5f};
    for (const Tri& t : m.triangles) {
        const Vec3 a = m.points.positions[t[0]], b = m.points.positions[t[1]],
                   c = m.points.positions[t[2]];
        const Vec3 n = cross(b - a, c - a);
        EXPECT_GT(dot(n, (a + b + c) / 3.0f - centre), 0.0f) << t[0] << " " << t[1] << " " << t[2];
    }
}

TEST(Ply, BigEndianBinaryFixtureWithMixedTypesIsRead) {
    const ModelData m = read_ply(kData + "tetra_big_endian.ply");
    ASSERT_EQ(m.points.size(), 4u);
    EXPECT_EQ(m.points.positions[3], (Vec3{0, 0, 1}));
    ASSERT_TRUE(m.points.has_normals());
    EXPECT_EQ(m.points.normals[0], (Vec3{-1, -1, -1}));  // kept as stored, not normalised
    EXPECT_EQ(m.points.normals[3], (Vec3{0, 0, 2}));
    ASSERT_TRUE(m.points.has_colors());
    EXPECT_EQ(m.points.colors[1], (Vec3{0, 1, 0}));
    EXPECT_NEAR(m.points.colors[3].x, 0.2f, 1e-7);
    EXPECT_NEAR(m.points.colors[3].y, 0.4f, 1e-7);
    EXPECT_NEAR(m.points.colors[3].z, 0.8f, 1e-7);
    ASSERT_TRUE(m.points.has_radii());
    EXPECT_EQ(m.points.radii, (std::vector<float>{0.5f, 0.25f, 0.125f, 1.5f}));
    const std::vector<Tri> expected = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
    EXPECT_EQ(m.triangles, expected);
}

TEST(Ply, ColourChannelNamesAndTypesAreNormalised) {
    ScratchDir dir;
    struct Case {
        const char* type;
        const char* r;
        const char* g;
        const char* b;
        std::vector<double> values;
        Vec3 expected;
    };
    const Case cases[] = {
        {"uchar", "red", "green", "blue", {255, 0, 51}, {1, 0, 51.0f / 255}},
        {"uint8", "r", "g", "b", {0, 255, 102}, {0, 1, 102.0f / 255}},
        {"uchar", "diffuse_red", "diffuse_green", "diffuse_blue", {255, 255, 0}, {1, 1, 0}},
        {"float", "red", "green", "blue", {0.25, 0.5, 0.75}, {0.25f, 0.5f, 0.75f}},
        {"double", "r", "g", "b", {0.125, 1, 0}, {0.125f, 1, 0}},
        {"ushort", "red", "green", "blue", {65535, 0, 65535}, {1, 0, 1}},
    };
    for (const char* format : kPlyFormats) {
        for (const Case& c : cases) {
            SCOPED_TRACE(std::string(format) + " " + c.type + " " + c.r);
            std::vector<double> row = {1, 2, 3};
            row.insert(row.end(), c.values.begin(), c.values.end());
            const PlyElement vertices = {"vertex",
                                         {{"float", "x"},
                                          {"float", "y"},
                                          {"float", "z"},
                                          {c.type, c.r},
                                          {c.type, c.g},
                                          {c.type, c.b}},
                                         {row}};
            const ModelData m = read_ply(dir.write("c.ply", make_ply(format, {vertices})));
            ASSERT_EQ(m.points.colors.size(), 1u);
            EXPECT_FLOAT_EQ(m.points.colors[0].x, c.expected.x);
            EXPECT_FLOAT_EQ(m.points.colors[0].y, c.expected.y);
            EXPECT_FLOAT_EQ(m.points.colors[0].z, c.expected.z);
        }
    }
}

TEST(Ply, PointCloudWithoutFacesHasNoTriangles) {
    ScratchDir dir;
    const ModelData m = read_ply(dir.write("p.ply", make_ply("ascii", {xyz_vertices(kSquare)})));
    EXPECT_EQ(m.points.size(), 4u);
    EXPECT_TRUE(m.triangles.empty());
}

TEST(Ply, EmptyVertexElementGivesAnEmptyModel) {
    ScratchDir dir;
    for (const char* format : kPlyFormats) {
        SCOPED_TRACE(format);
        const ModelData m =
            read_ply(dir.write("e.ply", make_ply(format, {xyz_vertices({}), faces({})})));
        EXPECT_EQ(m.points.size(), 0u);
        EXPECT_TRUE(m.triangles.empty());
    }
}

TEST(Ply, CommentsObjInfoCrlfLineEndingsAndPlusSignsAreAccepted) {
    ScratchDir dir;
    const std::string text =
        "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\nobj_info scanner 3\r\n"
        "element vertex 3\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\n"
        "comment between properties\r\nelement face 1\r\n"
        "property list uchar int vertex_index\r\nend_header\r\n"
        "0 0 0\r\n+1.5 0 -0\r\n\r\n0\t1e0   2E-1 \r\n3 0 1 +2\r\n";
    const ModelData m = read_ply(dir.write("crlf.ply", text));
    ASSERT_EQ(m.points.size(), 3u);
    EXPECT_EQ(m.points.positions[1], (Vec3{1.5f, 0, 0}));
    EXPECT_EQ(m.points.positions[2], (Vec3{0, 1, 0.2f}));
    EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}}));
}

TEST(Ply, AsciiFloatsReadToTheNearestFloatEvenBeyondItsRange) {
    ScratchDir dir;
    const std::string text =
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n"
        "0.1 1e-50 -1e-60\n3.4028234e38 1.17549435e-38 1.4e-45\n";
    const ModelData m = read_ply(dir.write("f.ply", text));
    ASSERT_EQ(m.points.size(), 2u);
    EXPECT_EQ(m.points.positions[0].x, 0.1f);
    EXPECT_EQ(m.points.positions[0].y, 0.0f);  // underflows to zero, like strtof
    EXPECT_EQ(m.points.positions[0].z, 0.0f);
    EXPECT_EQ(m.points.positions[1].x, std::numeric_limits<float>::max());
    EXPECT_EQ(m.points.positions[1].y, std::numeric_limits<float>::min());
    EXPECT_EQ(m.points.positions[1].z, std::numeric_limits<float>::denorm_min());
}

// ---- PLY: writing and round trips ------------------------------------------------------------

PointSet sample_points(size_t n, bool normals, bool colors, bool radii) {
    std::mt19937 rng(1234);
    std::uniform_real_distribution<float> u(-1000.0f, 1000.0f);
    std::uniform_int_distribution<int> byte(0, 255);
    PointSet p;
    for (size_t i = 0; i < n; ++i) {
        p.positions.push_back({u(rng), u(rng) * 1e-6f, u(rng) * 1e30f});
        if (normals) p.normals.push_back({u(rng) / 1000, u(rng) / 1000, u(rng) / 1000});
        // Colours that survive 8-bit quantisation unchanged.
        if (colors) {
            p.colors.push_back({static_cast<float>(byte(rng)) / 255.0f,
                                static_cast<float>(byte(rng)) / 255.0f,
                                static_cast<float>(byte(rng)) / 255.0f});
        }
        if (radii) p.radii.push_back(std::abs(u(rng)) * 1e-3f);
    }
    // Awkward values: signed zero, extremes, denormals.
    if (n >= 2) {
        p.positions[0] = {-0.0f, std::numeric_limits<float>::max(),
                          std::numeric_limits<float>::denorm_min()};
        p.positions[1] = {std::numeric_limits<float>::lowest(), 1e-40f, 0.1f};
    }
    return p;
}

void expect_same_points(const PointSet& a, const PointSet& b) {
    ASSERT_EQ(a.size(), b.size());
    for (size_t i = 0; i < a.size(); ++i) {
        // Bitwise: round trips must be exact, signed zeros included.
        ASSERT_EQ(std::bit_cast<uint32_t>(a.positions[i].x),
                  std::bit_cast<uint32_t>(b.positions[i].x))
            << i;
        ASSERT_EQ(std::bit_cast<uint32_t>(a.positions[i].y),
                  std::bit_cast<uint32_t>(b.positions[i].y))
            << i;
        ASSERT_EQ(std::bit_cast<uint32_t>(a.positions[i].z),
                  std::bit_cast<uint32_t>(b.positions[i].z))
            << i;
    }
    EXPECT_EQ(a.normals, b.normals);
    EXPECT_EQ(a.colors, b.colors);
    EXPECT_EQ(a.radii, b.radii);
}

TEST(Ply, PointCloudsRoundTripExactlyThroughWriterInBothEncodings) {
    ScratchDir dir;
    for (bool binary : {true, false}) {
        for (int mask = 0; mask < 8; ++mask) {
            const bool normals = mask & 1, colors = mask & 2, radii = mask & 4;
            SCOPED_TRACE(std::string(binary ? "binary" : "ascii") + (normals ? " normals" : "") +
                         (colors ? " colours" : "") + (radii ? " radii" : ""));
            const PointSet points = sample_points(500, normals, colors, radii);
            const std::string path = dir.path("rt.ply");
            write_ply(path, points, binary);
            const ModelData m = read_ply(path);
            expect_same_points(points, m.points);
            EXPECT_TRUE(m.triangles.empty());
        }
    }
}

// A scan's per-point scanner positions (sensor_x/y/z) go out and come back, in both encodings;
// a count that does not match the points, or a non-finite one, is refused with no file left.
TEST(Ply, SensorPositionsRoundTripThroughWriter) {
    ScratchDir dir;
    const PointSet points = sample_points(300, true, false, false);
    std::vector<Vec3> sensors(points.size());
    for (size_t i = 0; i < sensors.size(); ++i)
        sensors[i] = {0.25f * float(i % 4), 1.5f, -0.125f * float(i % 3)};
    for (bool binary : {true, false}) {
        SCOPED_TRACE(binary ? "binary" : "ascii");
        const std::string path = dir.path("sensors.ply");
        write_ply(path, points, binary, sensors);
        const ModelData m = read_ply(path);
        expect_same_points(points, m.points);
        ASSERT_EQ(m.sensors.size(), sensors.size());
        for (size_t i = 0; i < sensors.size(); ++i) EXPECT_EQ(m.sensors[i], sensors[i]) << i;
    }
    const std::string bad = dir.path("bad.ply");
    std::vector<Vec3> short_list(sensors.begin(), sensors.end() - 1);
    EXPECT_THROW(write_ply(bad, points, true, short_list), Error);
    std::vector<Vec3> nan_list = sensors;
    nan_list[7].y = std::numeric_limits<float>::quiet_NaN();
    EXPECT_THROW(write_ply(bad, points, true, nan_list), Error);
    EXPECT_FALSE(std::filesystem::exists(bad));
}

// The writer only writes little-endian; flipping every value of its output by hand gives a
// big-endian file that must read back the same.
TEST(Ply, BigEndianBinaryRoundTripsThroughWriter) {
    ScratchDir dir;
    const PointSet points = sample_points(100, true, true, true);
    const std::string little = dir.path("little.ply");
    write_ply(little, points, true);
    std::string bytes = slurp(little);
    const std::string marker = "end_header\n";
    const size_t body = bytes.find(marker) + marker.size();
    std::string header = bytes.substr(0, body);
    header.replace(header.find("binary_little_endian"), 20, "binary_big_endian");
    // x y z nx ny nz (4 bytes each), r g b (1 byte each), radius (4 bytes).
    const int sizes[] = {4, 4, 4, 4, 4, 4, 1, 1, 1, 4};
    size_t at = body;
    for (size_t i = 0; i < points.size(); ++i) {
        for (int s : sizes) {
            std::reverse(bytes.begin() + static_cast<std::ptrdiff_t>(at),
                         bytes.begin() + static_cast<std::ptrdiff_t>(at + s));
            at += s;
        }
    }
    ASSERT_EQ(at, bytes.size());
    const ModelData m = read_ply(dir.write("big.ply", header + bytes.substr(body)));
    expect_same_points(points, m.points);
}

TEST(Ply, WriterHeaderListsPropertiesInAFixedOrder) {
    ScratchDir dir;
    const std::string path = dir.path("h.ply");
    write_ply(path, sample_points(3, true, true, true), true);
    const std::string bytes = slurp(path);
    const std::string header = bytes.substr(0, bytes.find("end_header\n") + 11);
    EXPECT_EQ(header,
              "ply\nformat binary_little_endian 1.0\ncomment written by vmap\n"
              "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
              "property float nx\nproperty float ny\nproperty float nz\n"
              "property uchar red\nproperty uchar green\nproperty uchar blue\n"
              "property float radius\nend_header\n");
    EXPECT_EQ(bytes.size(), header.size() + 3 * (6 * 4 + 3 + 4));
}

TEST(Ply, WriterClampsAndRoundsColours) {
    ScratchDir dir;
    PointSet p;
    p.positions = {{0, 0, 0}, {1, 1, 1}};
    p.colors = {{-0.5f, 0.5f, 1.5f}, {std::nanf(""), 0.2f, 1.0f}};
    for (bool binary : {true, false}) {
        SCOPED_TRACE(binary ? "binary" : "ascii");
        const std::string path = dir.path("c.ply");
        write_ply(path, p, binary);
        const ModelData m = read_ply(path);
        ASSERT_EQ(m.points.colors.size(), 2u);
        EXPECT_EQ(m.points.colors[0], (Vec3{0, 128.0f / 255, 1}));  // 127.5 rounds up
        EXPECT_EQ(m.points.colors[1], (Vec3{0, 51.0f / 255, 1}));
    }
}

TEST(Ply, EmptyPointSetRoundTrips) {
    ScratchDir dir;
    for (bool binary : {true, false}) {
        const std::string path = dir.path("empty.ply");
        write_ply(path, PointSet{}, binary);
        EXPECT_EQ(read_ply(path).points.size(), 0u);
    }
}

TEST(Ply, WriterReplacesAnExistingFileAndLeavesNoTemporary) {
    ScratchDir dir;
    const std::string path = dir.write("out.ply", "old contents");
    write_ply(path, sample_points(10, false, false, false));
    EXPECT_EQ(read_ply(path).points.size(), 10u);
    EXPECT_EQ(dir.files(), (std::vector<std::string>{"out.ply"}));
}

TEST(Ply, WriterFailureThrowsAndLeavesNothingBehind) {
    ScratchDir dir;
    const PointSet points = sample_points(10, false, false, false);
    // The directory does not exist: the temporary cannot even be created.
    EXPECT_READ_ERROR(write_ply(dir.path("missing/out.ply"), points), "missing/out.ply");
    // The target is a directory: refused before anything is written.
    fs::create_directory(dir.path("target.ply"));
    EXPECT_READ_ERROR(write_ply(dir.path("target.ply"), points), "target.ply", "is a folder");
    EXPECT_EQ(dir.files(), (std::vector<std::string>{"target.ply"}));
}

TEST(Ply, WriterRejectsInconsistentOrNonFinitePoints) {
    ScratchDir dir;
    const std::string path = dir.path("bad.ply");
    PointSet p = sample_points(4, true, true, true);
    p.normals.pop_back();
    EXPECT_READ_ERROR(write_ply(path, p), "bad.ply", "3 normals for 4 points");
    p = sample_points(4, false, true, false);
    p.colors.push_back({});
    EXPECT_READ_ERROR(write_ply(path, p), "bad.ply", "5 colours for 4 points");
    p = sample_points(4, false, false, true);
    p.radii.resize(2);
    EXPECT_READ_ERROR(write_ply(path, p), "bad.ply", "2 radii for 4 points");
    p = sample_points(4, false, false, false);
    p.positions[2].y = std::numeric_limits<float>::infinity();
    EXPECT_READ_ERROR(write_ply(path, p), "bad.ply", "point 2", "position");
    p = sample_points(4, true, false, false);
    p.normals[1].z = std::nanf("");
    EXPECT_READ_ERROR(write_ply(path, p), "bad.ply", "point 1", "normal");
    EXPECT_TRUE(dir.files().empty());
}

// ---- PLY: bad input ----------------------------------------------------------------------------

TEST(Ply, MissingEmptyAndDirectoryPathsAreRejected) {
    ScratchDir dir;
    EXPECT_READ_ERROR(read_ply(dir.path("nothing.ply")), "nothing.ply: no such file");
    EXPECT_READ_ERROR(read_ply(dir.write("empty.ply", "")), "empty.ply: empty file");
    fs::create_directory(dir.path("folder.ply"));
    EXPECT_READ_ERROR(read_ply(dir.path("folder.ply")), "folder.ply", "directory");
}

TEST(Ply, MalformedHeadersAreRejectedWithTheLineAtFault) {
    ScratchDir dir;
    const std::string vertex =
        "element vertex 1\nproperty float x\nproperty float y\n"
        "property float z\n";
    struct Case {
        std::string text;
        std::vector<std::string_view> parts;
    };
    const Case cases[] = {
        {"OFF\n3 1 0\n", {"header", "bad magic"}},
        {"plyx\nformat ascii 1.0\n", {"header", "bad magic"}},
        {"ply\nformat binary_middle_endian 1.0\n" + vertex + "end_header\n",
         {"header line 2", "unknown format 'binary_middle_endian'"}},
        {"ply\nformat ascii 2.0\n" + vertex + "end_header\n", {"header line 2", "version"}},
        {"ply\nformat ascii\n" + vertex + "end_header\n", {"header line 2", "format"}},
        {"ply\n" + vertex + "end_header\n", {"header", "missing 'format'"}},
        {"ply\nformat ascii 1.0\n" + vertex, {"header", "missing 'end_header'"}},
        {"ply\nformat ascii 1.0\n" + vertex + "end_headr\n0 0 0\n",
         {"header", "missing 'end_header'"}},
        {"ply\nformat ascii 1.0\nproperty float x\n" + vertex + "end_header\n",
         {"header line 3", "property before any element"}},
        {"ply\nformat ascii 1.0\n" + vertex + "property flaot w\nend_header\n",
         {"header line 7", "unknown property type 'flaot'"}},
        {"ply\nformat ascii 1.0\n" + vertex + "propertty float w\nend_header\n",
         {"header line 7", "unknown keyword 'propertty'"}},
        {"ply\nformat ascii 1.0\n" + vertex + "property list float int w\nend_header\n",
         {"header line 7", "count type"}},
        {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float z\n"
         "end_header\n0 0\n",
         {"header", "vertex", "no 'y' property"}},
        {"ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar float x\nproperty float "
         "y\nproperty float z\nend_header\n",
         {"header", "vertex", "'x'", "list"}},
        {"ply\nformat ascii 1.0\n" + vertex + "property float y\nend_header\n",
         {"header", "vertex", "duplicate property 'y'"}},
        {"ply\nformat ascii 1.0\n" + vertex + "property float nx\nproperty float ny\n" +
             "end_header\n",
         {"header", "vertex", "2 of the 3 normal"}},
        {"ply\nformat ascii 1.0\n" + vertex + "property uchar red\nend_header\n",
         {"header", "vertex", "1 of the 3 colour"}},
        {"ply\nformat ascii 1.0\nelement point 1\nproperty float x\nend_header\n",
         {"header", "no 'vertex' element"}},
        {"ply\nformat ascii 1.0\n" + vertex + vertex + "end_header\n",
         {"header", "more than one 'vertex'"}},
        {"ply\nformat ascii 1.0\n" + vertex + "element face 1\nproperty uchar flags\n" +
             "end_header\n",
         {"header", "face", "no 'vertex_indices'"}},
        {"ply\nformat ascii 1.0\n" + vertex + "element face 1\n" +
             "property list uchar float vertex_indices\nend_header\n",
         {"header", "face", "'vertex_indices'", "integer"}},
        {"ply\nformat ascii 1.0\nelement vertex -3\nproperty float x\nproperty float y\n"
         "property float z\nend_header\n",
         {"header", "element vertex", "negative count -3"}},
        {"ply\nformat ascii 1.0\nelement vertex 3x\nproperty float x\nproperty float y\n"
         "property float z\nend_header\n",
         {"header", "element vertex", "invalid count '3x'"}},
        {"ply\nformat ascii 1.0\nelement vertex 99999999999999999999999\nproperty float "
         "x\nproperty float y\nproperty float z\nend_header\n",
         {"header", "element vertex", "too large"}},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.text);
        const std::string path = dir.write("head.ply", c.text);
        std::vector<std::string_view> parts = {"head.ply: "};
        parts.insert(parts.end(), c.parts.begin(), c.parts.end());
        expect_error([&] { (void)read_ply(path); }, parts);
    }
}

TEST(Ply, AbsurdCountsAreRejectedBeforeAllocating) {
    ScratchDir dir;
    for (const char* format : kPlyFormats) {
        SCOPED_TRACE(format);
        PlyElement v = xyz_vertices(kSquare);
        v.count = "99999999999";
        EXPECT_READ_ERROR(read_ply(dir.write("huge.ply", make_ply(format, {v}))), "huge.ply",
                          "truncated: element vertex: 99999999999 elements", "cannot fit");
        PlyElement f = faces({{3, 0, 1, 2}});
        f.count = "4000000000";
        EXPECT_READ_ERROR(
            read_ply(dir.write("huge.ply", make_ply(format, {xyz_vertices(kSquare), f}))),
            "huge.ply", "element face", "cannot fit");
        PlyElement other = {"extra", {{"int", "list", "uint"}}, {{0}}, "18446744073709551615"};
        EXPECT_READ_ERROR(
            read_ply(dir.write("huge.ply", make_ply(format, {xyz_vertices(kSquare), other}))),
            "huge.ply", "element extra", "cannot fit");
    }
}

TEST(Ply, TruncatedDataIsRejectedInEveryFormat) {
    ScratchDir dir;
    // Values long enough in ascii that the early size check passes and the reader runs dry.
    const std::vector<PlyElement> elements = {
        xyz_vertices({{0.5, 0.5, 0.5}, {1.5, 0.5, 0.5}, {1.5, 1.5, 0.5}, {0.5, 1.5, 0.5}}),
        faces({{3, 0, 1, 2}, {4, 0, 1, 2, 3}})};
    for (const char* format : kPlyFormats) {
        SCOPED_TRACE(format);
        const std::string header = ply_header(format, elements);
        const std::string body = ply_body(format, elements);
        const bool ascii = std::string_view(format) == "ascii";
        // Cut inside the vertices. In binary the early size check catches it.
        const size_t vertex_cut = ascii ? body.find("0.5 1.5 0.5\n") : 3 * 12 + 5;
        EXPECT_READ_ERROR(read_ply(dir.write("cut.ply", header + body.substr(0, vertex_cut))),
                          "cut.ply: truncated", "vertex");
        if (ascii) {
            EXPECT_READ_ERROR(read_ply(dir.write("cut.ply", header + body.substr(0, vertex_cut))),
                              "cut.ply: truncated: expected 4 vertex elements, found 3");
        }
        // Cut inside the faces.
        const size_t face_cut = ascii ? body.rfind("4 0 1 2 3") : body.size() - 3;
        EXPECT_READ_ERROR(read_ply(dir.write("cut.ply", header + body.substr(0, face_cut))),
                          "cut.ply: truncated: expected 2 face elements, found 1");
        // No data at all.
        EXPECT_READ_ERROR(read_ply(dir.write("cut.ply", header)), "cut.ply: truncated",
                          "element vertex");
    }
}

TEST(Ply, AsciiLinesWithTooFewOrTooManyOrBadTokensAreRejected) {
    ScratchDir dir;
    const std::string header =
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
    const std::string ok = "0 0 0 1 2 3\n1 0 0 1 2 3\n";
    struct Case {
        std::string body;
        std::vector<std::string_view> parts;
    };
    const Case cases[] = {
        {ok + "0 1 0 1 2\n3 0 1 2\n", {"vertex 2 (line 15)", "expected 6 values, found 5"}},
        {ok + "0 1 0 1 2 3 4\n3 0 1 2\n", {"vertex 2 (line 15)", "expected 6 values, found 7"}},
        {ok + "0 1 0 1 2 3\n3 0 1\n", {"face 0 (line 16)", "expected 4 values, found 3"}},
        {ok + "0 1 0 1 2 3\n3 0 1 2 0\n", {"face 0 (line 16)", "expected 4 values, found 5"}},
        {ok + "0 1 zero 1 2 3\n3 0 1 2\n", {"vertex 2 (line 15)", "invalid number 'zero'"}},
        {ok + "0 1 0.5.5 1 2 3\n3 0 1 2\n", {"vertex 2", "invalid number '0.5.5'"}},
        {ok + "0 1 0 1 2 3.5\n3 0 1 2\n", {"vertex 2", "invalid integer '3.5'"}},
        {ok + "0 1 0 1 2 300\n3 0 1 2\n", {"vertex 2", "value 300 out of range for uchar"}},
        {ok + "0 1 0 1 -2 3\n3 0 1 2\n", {"vertex 2", "value -2 out of range for uchar"}},
        {ok + "0 1 0 1 2 3\nthree 0 1 2\n", {"face 0", "invalid integer 'three'"}},
        {ok + "0 1 0 1 2 3\n3 0 1 2\n1 2 3\n", {"line 17", "unexpected data after the last"}},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.body);
        EXPECT_READ_ERROR(read_ply(dir.write("tokens.ply", header + c.body)),
                          "tokens.ply: ", c.parts[0], c.parts[1]);
    }
}

TEST(Ply, FaceIndicesOutOfRangeAndDegenerateFacesAreRejected) {
    ScratchDir dir;
    for (const char* format : kPlyFormats) {
        SCOPED_TRACE(format);
        auto read_faces = [&](std::vector<std::vector<double>> rows) {
            return read_ply(
                dir.write("faces.ply", make_ply(format, {xyz_vertices(kSquare), faces(rows)})));
        };
        EXPECT_READ_ERROR(read_faces({{3, 0, 1, 2}, {3, 0, 4, 2}}), "faces.ply", "face 1",
                          "vertex index 4 out of range (4 vertices)");
        EXPECT_READ_ERROR(read_faces({{3, 0, 1, -1}}), "faces.ply", "face 0",
                          "vertex index -1 out of range");
        EXPECT_READ_ERROR(read_faces({{3, 0, 1, 2}, {2, 0, 1}}), "faces.ply", "face 1",
                          "degenerate face with 2 vertices");
        EXPECT_READ_ERROR(read_faces({{0}}), "faces.ply", "face 0",
                          "degenerate face with 0 vertices");
    }
}

TEST(Ply, NegativeListLengthIsRejected) {
    ScratchDir dir;
    for (const char* format : kPlyFormats) {
        SCOPED_TRACE(format);
        PlyElement f = faces({{-1, 0, 1, 2}}, "char");
        EXPECT_READ_ERROR(
            read_ply(dir.write("neg.ply", make_ply(format, {xyz_vertices(kSquare), f}))), "neg.ply",
            "face 0", "negative list length -1");
    }
}

TEST(Ply, TrailingBinaryBytesAreRejected) {
    ScratchDir dir;
    for (const char* format : {"binary_little_endian", "binary_big_endian"}) {
        SCOPED_TRACE(format);
        EXPECT_READ_ERROR(
            read_ply(dir.write("extra.ply", make_ply(format, {xyz_vertices(kSquare)}) + "xyz")),
            "extra.ply", "3 bytes after the last element");
    }
}

TEST(Ply, NonFiniteCoordinatesNormalsColoursAndRadiiAreRejected) {
    ScratchDir dir;
    const double inf = std::numeric_limits<double>::infinity();
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const PlyElement full = {"vertex",
                             {{"float", "x"},
                              {"double", "y"},
                              {"float", "z"},
                              {"float", "nx"},
                              {"float", "ny"},
                              {"float", "nz"},
                              {"float", "red"},
                              {"float", "green"},
                              {"float", "blue"},
                              {"float", "radius"}},
                             {}};
    const std::vector<double> ok = {0, 0, 0, 0, 0, 1, 0.5, 0.5, 0.5, 0.1};
    struct Case {
        size_t index;
        double value;
        std::string_view what;
    };
    const Case cases[] = {
        {0, nan, "non-finite coordinate (nan"}, {1, inf, "non-finite coordinate (0, inf"},
        {2, -inf, "non-finite coordinate"},     {1, 1e300, "non-finite coordinate (0, 1e+300"},
        {3, nan, "non-finite normal (nan"},     {5, inf, "non-finite normal"},
        {7, nan, "non-finite colour"},          {9, inf, "invalid radius inf"},
        {9, -1, "invalid radius -1"},
    };
    for (const char* format : kPlyFormats) {
        for (const Case& c : cases) {
            SCOPED_TRACE(std::string(format) + " " + std::string(c.what));
            PlyElement v = full;
            v.rows = {ok, ok, ok};
            v.rows[1][c.index] = c.value;
            EXPECT_READ_ERROR(read_ply(dir.write("nan.ply", make_ply(format, {v}))), "nan.ply",
                              "vertex 1", c.what);
        }
    }
    // Ascii spellings of non-finite values and of floats too large for a float.
    for (const char* token : {"nan", "-nan", "inf", "-Infinity", "1e39", "-1e400"}) {
        SCOPED_TRACE(token);
        const std::string text =
            "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
            "property float z\nend_header\n0 0 0\n0 " +
            std::string(token) + " 0\n";
        EXPECT_READ_ERROR(read_ply(dir.write("nan.ply", text)), "nan.ply", "vertex 1 (line 9)",
                          "non-finite coordinate");
    }
}

// Vertex properties by name: uchar for the colours, float for the rest.
std::vector<PlyProp> vertex_props(std::initializer_list<const char*> names) {
    std::vector<PlyProp> props;
    for (const char* n : names) {
        const std::string name = n;
        props.push_back(
            {name == "red" || name == "green" || name == "blue" ? "uchar" : "float", name});
    }
    return props;
}

// A body of 4 MB or more is parsed in pieces in parallel (read_ascii in src/io/ply.cpp): the
// same model as the binary encoding gives, blank lines and CRLF endings anywhere, and each error
// the one a line-by-line reader meets first, with its element, index and line number.
TEST(Ply, LargeAsciiBodiesReadInPiecesAsTheBinaryEncodingAndFailAtTheFirstError) {
    ScratchDir dir;
    const size_t nv = 90000, nf = 60000;
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-1, 1);
    PlyElement vertices{
        "vertex", vertex_props({"x", "y", "z", "nx", "ny", "nz", "red", "green", "blue"}), {}};
    for (size_t i = 0; i < nv; ++i)
        vertices.rows.push_back({double(float(u(rng))), double(float(u(rng))),
                                 double(float(u(rng))), double(float(u(rng))),
                                 double(float(u(rng))), double(float(u(rng))), double(i % 256),
                                 double(i / 256 % 256), 7});
    PlyElement quads = faces({});
    for (size_t f = 0; f < nf; ++f) {
        const double a = double((f * 7919) % (nv - 3));
        quads.rows.push_back(f % 3 ? std::vector<double>{3, a, a + 1, a + 2}
                                   : std::vector<double>{4, a, a + 1, a + 2, a + 3});
    }
    const std::vector<PlyElement> elements = {
        {"camera", {{"float", "pose", "uchar"}}, {{2, 1, 2}}}, vertices, quads};
    const std::string header = ply_header("ascii", elements);
    const std::string body = ply_body("ascii", elements);
    ASSERT_GE(body.size(), size_t(8) << 20) << "the body must span several pieces";
    const ModelData want =
        read_ply(dir.write("bin.ply", make_ply("binary_little_endian", elements)));
    ASSERT_EQ(want.points.size(), nv);
    auto expect_same = [&](const ModelData& m) {
        ASSERT_EQ(m.points.size(), nv);
        EXPECT_EQ(m.points.positions, want.points.positions);
        EXPECT_EQ(m.points.normals, want.points.normals);
        EXPECT_EQ(m.points.colors, want.points.colors);
        EXPECT_EQ(m.triangles, want.triangles);
        EXPECT_EQ(m.triangles.size(), nf + nf / 3 + (nf % 3 ? 1 : 0));
    };
    expect_same(read_ply(dir.write("big.ply", header + body)));

    // Line starts: lines[k] is where body line k begins (line 0 is the camera's element).
    std::vector<size_t> lines{0};
    for (size_t i = 0; i + 1 < body.size(); ++i)
        if (body[i] == '\n') lines.push_back(i + 1);
    ASSERT_EQ(lines.size(), 1 + nv + nf);
    const size_t first_line = size_t(std::count(header.begin(), header.end(), '\n')) + 1;
    auto vertex_line = [&](size_t i) { return 1 + i; };  // body lines before vertex i
    auto face_line = [&](size_t f) { return 1 + nv + f; };
    // A body line replaced (without its line end) by `text`.
    auto with_line = [&](std::string b, size_t line, const std::string& text) {
        const size_t end = b.find('\n', lines[line]);
        return b.replace(lines[line], end - lines[line], text);
    };
    auto at = [&](size_t body_line) {
        return "(line " + std::to_string(first_line + body_line) + ")";
    };

    // Blank lines and CRLF endings move line numbers, not elements.
    {
        std::string b = body;
        for (size_t line : {face_line(nf - 1), vertex_line(70000), vertex_line(20000), size_t(1)})
            b.insert(lines[line], " \t\r\n\n");
        for (size_t i = b.size() / 3; i < b.size(); i += 9973) {
            const size_t nl = b.find('\n', i);
            if (nl == std::string::npos) break;
            if (b[nl - 1] != '\r') b.insert(nl, "\r");
            i = nl;
        }
        expect_same(read_ply(dir.write("blank.ply", header + b)));
        // An error past the inserted lines is reported on its own line.
        std::string bad = with_line(body, vertex_line(80000), "0 0 zero 0 0 1 1 2 3");
        bad.insert(lines[vertex_line(20000)], "\n\n");
        const std::string where =
            "vertex 80000 (line " + std::to_string(first_line + vertex_line(80000) + 2) + ")";
        EXPECT_READ_ERROR(read_ply(dir.write("blank.ply", header + bad)), where,
                          "invalid number 'zero'");
    }
    // Errors late in the body, and the first of two.
    const std::string late = with_line(body, vertex_line(85000), "0 0 zero 0 0 1 1 2 3");
    EXPECT_READ_ERROR(read_ply(dir.write("late.ply", header + late)),
                      "late.ply: vertex 85000 " + at(vertex_line(85000)), "invalid number 'zero'");
    EXPECT_READ_ERROR(
        read_ply(
            dir.write("two.ply", header + with_line(late, vertex_line(10), "0 0 0 1 1 1 300 0 0"))),
        "two.ply: vertex 10 " + at(vertex_line(10)), "value 300 out of range for uchar");
    EXPECT_READ_ERROR(
        read_ply(dir.write("face.ply", header + with_line(body, face_line(nf - 2), "3 0 1 90000"))),
        "face.ply: face " + std::to_string(nf - 2) + " " + at(face_line(nf - 2)),
        "vertex index 90000 out of range (90000 vertices)");
    EXPECT_READ_ERROR(
        read_ply(dir.write("short.ply",
                           header + with_line(body, vertex_line(60000), "0 0 0 1 1 1 2 3"))),
        "short.ply: vertex 60000 " + at(vertex_line(60000)), "expected 9 values, found 8");
    // Truncated, and data after the last element.
    EXPECT_READ_ERROR(
        read_ply(dir.write("cut.ply", header + body.substr(0, lines[face_line(nf - 5)]))),
        "cut.ply: truncated: expected " + std::to_string(nf) + " face elements, found " +
            std::to_string(nf - 5));
    EXPECT_READ_ERROR(
        read_ply(dir.write("cut.ply", header + body.substr(0, lines[vertex_line(70000)]))),
        "cut.ply: truncated: expected " + std::to_string(nv) + " vertex elements, found 70000");
    EXPECT_READ_ERROR(read_ply(dir.write("extra.ply", header + body + "\n \n1 2 3\n")),
                      "extra.ply: line " + std::to_string(first_line + lines.size() + 2),
                      "unexpected data after the last element");
    // Random damage to the body (bytes changed or dropped, the file cut): the pieces only ever
    // succeed or throw vmap::Error (memory-checked under the sanitizer build).
    std::mt19937 damage(11);
    for (int i = 0; i < 12; ++i) {
        std::string b = body;
        for (int k = 0; k < 3; ++k) {
            const size_t at = std::uniform_int_distribution<size_t>(0, b.size() - 1)(damage);
            const char bytes[] = {'\n', ' ', '-', 'e', '\0', '\xff', '7'};
            if (k == 2 && i % 3 == 0) {
                b.resize(std::max(at, b.size() / 2));  // cut, still over 4 MB
            } else if (i % 2) {
                b.erase(at, 1 + damage() % 8);
            } else {
                b[at] = bytes[damage() % sizeof(bytes)];
            }
        }
        const std::string path = dir.write("damaged.ply", header + b);
        expect_only_vmap_errors(path, [&] { return read_ply(path); });
    }
}

// Differential: an ascii body cut into pieces of a few bytes (detail::read_ply_in_pieces) reads
// exactly as line by line, model or error message, for good files and randomly damaged ones.
TEST(Ply, AsciiBodiesInPiecesReadAsLineByLineEvenWhenDamaged) {
    ScratchDir dir;
    std::mt19937 rng(5);
    const std::vector<PlyElement> elements = {
        {"camera", {{"float", "pose", "uchar"}}, {{2, 1, 2}}},
        {"vertex",
         vertex_props({"x", "y", "z", "nx", "ny", "nz", "red", "green", "blue", "radius"}),
         {{0, 0, 0, 0, 0, 1, 1, 2, 3, 0.5},
          {1, 0, 0, 0, 1, 0, 4, 5, 6, 1},
          {1, 1, 0, 1, 0, 0, 7, 8, 9, 2},
          {0, 1, 0.5, 0, 0, -1, 10, 11, 12, 0.25}}},
        faces({{3, 0, 1, 2}, {4, 0, 1, 2, 3}, {3, 3, 2, 1}}),
        {"trailer", {{"short", "values", "ushort"}}, {{3, 1, 2, 3}, {0}}},
    };
    const std::string good = make_ply("ascii", elements);
    size_t same_models = 0, same_errors = 0;
    for (int i = 0; i < 600; ++i) {
        std::string text = i < 4 ? good : damaged(good, rng);
        if (i % 4 == 0) {  // harmless edits instead: blanks and CRs beside the body's blanks
            text = good;
            const size_t body = text.find("end_header\n") + 11;
            for (int k = 0; k < 6; ++k) {
                const size_t at = body + rng() % (text.size() - body);
                if (text[at] == ' ' || text[at] == '\n') text.insert(at, rng() % 2 ? " \t" : "\r");
            }
        }
        const size_t body_at = text.find("end_header\n");
        if (i % 5 == 1 && body_at != std::string::npos) text.insert(body_at + 11, "\n \n");
        const std::string path = dir.write("pieces.ply", text);
        const std::string want = detail::read_outcome(path, 0);
        for (size_t piece : {size_t(1), size_t(7), size_t(30)}) {
            SCOPED_TRACE("damage " + std::to_string(i) + ", pieces of " + std::to_string(piece));
            ASSERT_EQ(detail::read_outcome(path, piece), want) << text;
        }
        (want.rfind("error: ", 0) == 0 ? same_errors : same_models)++;
    }
    EXPECT_GT(same_models, 20u) << "the damage left too few readable files to compare";
    EXPECT_GT(same_errors, 100u);
}

TEST(Ply, DamagedFilesOnlyEverThrowVmapErrors) {
    ScratchDir dir;
    std::mt19937 rng(42);
    const std::vector<PlyElement> elements = {
        {"camera", {{"float", "pose", "uchar"}}, {{2, 1, 2}}},
        {"vertex",
         vertex_props({"x", "y", "z", "red", "green", "blue", "radius"}),
         {{0, 0, 0, 1, 2, 3, 0.5}, {1, 0, 0, 4, 5, 6, 1}, {1, 1, 0, 7, 8, 9, 2}}},
        faces({{3, 0, 1, 2}, {4, 0, 1, 2, 1}}),
    };
    for (const char* format : kPlyFormats) {
        SCOPED_TRACE(format);
        expect_damage_only_throws_vmap_errors(
            dir, make_ply(format, elements), ".ply",
            [](const std::string& f) { return read_ply(f); }, rng);
    }
}

}  // namespace
}  // namespace vmap
