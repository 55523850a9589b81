// Scene files (src/scene/scene.cpp): the shipped scenes, every kind of bad input, and raw
// point cloud loading.
#include "scene_test_util.h"

namespace vmap {
namespace {

// ---- the shipped scenes --------------------------------------------------------------------

TEST(Scene, EveryShippedSceneLoads) {
    for (const char* name :
         {"cornell-empty", "cornell-bunny", "cornell-dragon", "cornell-two-models"}) {
        SCOPED_TRACE(name);
        const std::string path = kScenes + name + ".json";
        Scene sc;
        ASSERT_NO_THROW(sc = load_scene(path));
        EXPECT_EQ(sc.name, name);
        EXPECT_EQ(sc.path, path);
        EXPECT_GE(sc.surfaces.size(), 6u);
        EXPECT_GT(sc.points, 0u);
        EXPECT_TRUE(sc.octree.has_value());
        EXPECT_GT(total_area(sc), 1.0);
        for (const auto& s : sc.surfaces) {
            EXPECT_FALSE(s.mesh.triangles.empty()) << s.name;
            for (Vec3 v : s.mesh.vertices) ASSERT_TRUE(is_finite(v)) << s.name;
        }
    }
}

TEST(Scene, ShippedScenesGiveTheirSamplingAndOctreeDefaults) {
    const Scene empty = load_scene(kScenes + "cornell-empty.json");
    EXPECT_EQ(empty.points, 20000u);
    EXPECT_EQ(empty.seed, 1u);
    ASSERT_TRUE(empty.octree.has_value());
    EXPECT_EQ(empty.octree->max_height, 7);
    EXPECT_EQ(empty.octree->leaf_points, 1);
    EXPECT_EQ(empty.room_size, (Vec3{kW, kH, kD}));

    const Scene two = load_scene(kScenes + "cornell-two-models.json");
    EXPECT_EQ(two.points, 150000u);
    EXPECT_EQ(two.seed, 2u);
    EXPECT_EQ(two.surfaces.size(), 8u);
    ASSERT_TRUE(two.octree.has_value());
    EXPECT_EQ(two.octree->max_height, 9);
}

TEST(Scene, DefaultScenePathIsTheShippedBunnyScene) {
    EXPECT_TRUE(fs::exists(default_scene_path())) << default_scene_path();
    EXPECT_EQ(fs::path(default_scene_path()).filename(), "cornell-bunny.json");
    EXPECT_NO_THROW((void)load_scene(default_scene_path()));
}

TEST(Scene, TheRoomHasFiveWallsAndALightWithTheirAlbedos) {
    const Scene sc = load_scene(kScenes + "cornell-empty.json");
    ASSERT_EQ(sc.surfaces.size(), 6u);
    for (const char* name : {"floor", "ceiling", "back", "left", "right", "light"})
        ASSERT_NE(find_surface(sc, name), nullptr) << name;

    const Vec3 left = find_surface(sc, "left")->albedo, right = find_surface(sc, "right")->albedo;
    EXPECT_GT(left.x, 2 * left.y) << "the left wall is red";
    EXPECT_GT(left.x, 2 * left.z) << "the left wall is red";
    EXPECT_GT(right.y, 2 * right.x) << "the right wall is green";
    EXPECT_GT(right.y, 2 * right.z) << "the right wall is green";
    for (const char* name : {"floor", "ceiling", "back"}) {
        const Vec3 a = find_surface(sc, name)->albedo;
        EXPECT_EQ(a.x, a.y) << name << " is grey";
        EXPECT_EQ(a.y, a.z) << name << " is grey";
        EXPECT_GT(a.x, 0.5f) << name;
        EXPECT_LE(a.x, 1.0f) << name;
    }
    for (const auto& s : sc.surfaces) {
        for (float c : {s.albedo.x, s.albedo.y, s.albedo.z}) {
            EXPECT_GE(c, 0.0f) << s.name;
            EXPECT_LE(c, 1.0f) << s.name;
        }
        if (s.name == "light") {
            EXPECT_EQ(s.emission, (Vec3{17, 12, 4}));
        } else {
            EXPECT_EQ(s.emission, (Vec3{0, 0, 0})) << s.name << " does not emit";
        }
    }
    // Where the walls are: left at x = width, right at x = 0, the light just below the ceiling.
    for (Vec3 v : find_surface(sc, "left")->mesh.vertices) EXPECT_EQ(v.x, kW);
    for (Vec3 v : find_surface(sc, "right")->mesh.vertices) EXPECT_EQ(v.x, 0.0f);
    for (Vec3 v : find_surface(sc, "floor")->mesh.vertices) EXPECT_EQ(v.y, 0.0f);
    for (Vec3 v : find_surface(sc, "ceiling")->mesh.vertices) EXPECT_EQ(v.y, kH);
    for (Vec3 v : find_surface(sc, "back")->mesh.vertices) EXPECT_EQ(v.z, kD);
    for (Vec3 v : find_surface(sc, "light")->mesh.vertices) {
        EXPECT_LT(v.y, kH);
        EXPECT_GT(v.y, 0.99f * kH);
        EXPECT_NEAR(v.x, 0.2764f, 0.13f / 2 + 1e-6f);
        EXPECT_NEAR(v.z, 0.2796f, 0.105f / 2 + 1e-6f);
    }
    EXPECT_NEAR(surface_area(*find_surface(sc, "light")), 0.13 * 0.105, 1e-6);
    EXPECT_NEAR(surface_area(*find_surface(sc, "floor")), double(kW) * kD, 1e-6);
    EXPECT_NEAR(surface_area(*find_surface(sc, "back")), double(kW) * kH, 1e-6);
}

TEST(Scene, WallAndLightTrianglesFaceIntoTheRoom) {
    const Scene sc = load_scene(kScenes + "cornell-empty.json");
    const Vec3 centre{kW / 2, kH / 2, kD / 2};
    for (const auto& s : sc.surfaces) {
        for (const auto& t : s.mesh.triangles) {
            const Vec3 mid =
                (s.mesh.vertices[t[0]] + s.mesh.vertices[t[1]] + s.mesh.vertices[t[2]]) / 3.0f;
            EXPECT_GT(dot(triangle_normal(s.mesh, t), centre - mid), 0.0f) << s.name;
        }
    }
}

TEST(Scene, SampledWallAndLightNormalsPointIntoTheRoom) {
    Scene sc = load_scene(kScenes + "cornell-bunny.json");
    sc.points = 20000;
    const PointSet ps = sample_scene(sc);
    const Vec3 bunny = find_surface(sc, "bunny")->albedo;
    const Vec3 centre{kW / 2, kH / 2, kD / 2};
    size_t room_points = 0, bad = 0;
    for (size_t i = 0; i < ps.size(); ++i) {
        if (ps.colors[i] == bunny) continue;  // a mesh point
        ++room_points;
        if (!(dot(ps.normals[i], centre - ps.positions[i]) > 0) && bad++ < 5)
            ADD_FAILURE() << "point " << i << " faces away from the room";
    }
    EXPECT_EQ(bad, 0u);
    EXPECT_GT(room_points, ps.size() / 2);
    EXPECT_LT(room_points, ps.size());
}

TEST(Scene, MeshesAreWoundOutwardAfterLoading) {
    for (const char* name : {"cornell-bunny", "cornell-two-models"}) {
        SCOPED_TRACE(name);
        const Scene sc = load_scene(kScenes + std::string(name) + ".json");
        ASSERT_GT(sc.surfaces.size(), 6u);
        for (size_t s = 6; s < sc.surfaces.size(); ++s)
            EXPECT_GT(signed_volume(sc.surfaces[s].mesh), 0.0) << sc.surfaces[s].name;
    }
    // A tetrahedron wound inside-out in its file is turned the right way out...
    const Scene tetra = load_scene(kFixtures + "tetra_scene.json");
    ASSERT_EQ(tetra.surfaces.size(), 7u);
    EXPECT_GT(signed_volume(tetra.surfaces[6].mesh), 0.0);
    // ... and "flip_normals" turns it back.
    const Scene flipped = load_scene(kFixtures + "tetra_flipped.json");
    ASSERT_EQ(flipped.surfaces.size(), 7u);
    EXPECT_LT(signed_volume(flipped.surfaces[6].mesh), 0.0);
}

TEST(Scene, SampledMeshNormalsPointOutOfAConvexMesh) {
    const Scene sc = load_scene(kFixtures + "tetra_scene.json");
    const PointSet ps = sample_scene(sc);
    const Mesh& m = sc.surfaces[6].mesh;
    Vec3 mid{};
    for (Vec3 v : m.vertices) mid += v;
    mid = mid / float(m.vertices.size());
    size_t on_mesh = 0;
    for (size_t i = 0; i < ps.size(); ++i) {
        if (!(ps.colors[i] == Vec3{0.2f, 0.4f, 0.6f})) continue;
        ++on_mesh;
        EXPECT_GT(dot(ps.normals[i], ps.positions[i] - mid), 0.0f) << "point " << i;
    }
    EXPECT_GT(on_mesh, 0u);
}

TEST(Scene, MeshesAreScaledAndStoodOnTheirPosition) {
    const Scene sc = load_scene(kFixtures + "tetra_scene.json");
    ASSERT_EQ(sc.surfaces.size(), 7u);
    const SceneSurface& s = sc.surfaces[6];
    EXPECT_EQ(s.name, "tetra_inside_out");
    EXPECT_EQ(s.albedo, (Vec3{0.2f, 0.4f, 0.6f}));
    EXPECT_EQ(s.emission, (Vec3{0, 0, 0}));
    Vec3 lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
    for (Vec3 v : s.mesh.vertices) {
        lo = {std::min(lo.x, v.x), std::min(lo.y, v.y), std::min(lo.z, v.z)};
        hi = {std::max(hi.x, v.x), std::max(hi.y, v.y), std::max(hi.z, v.z)};
    }
    EXPECT_NEAR(std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z}), 0.2f, 1e-5f);
    EXPECT_NEAR(lo.y, 0.0f, 1e-6f);
    EXPECT_NEAR((lo.x + hi.x) / 2, 0.25f, 1e-5f);
    EXPECT_NEAR((lo.z + hi.z) / 2, 0.3f, 1e-5f);

    // The bunny of the default scene: 0.25 m at its largest, on the floor.
    const Scene bunny = load_scene(kScenes + "cornell-bunny.json");
    const SceneSurface* b = find_surface(bunny, "bunny");
    ASSERT_NE(b, nullptr);
    float ylo = INFINITY, ext_lo[3] = {INFINITY, INFINITY, INFINITY},
          ext_hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (Vec3 v : b->mesh.vertices) {
        ylo = std::min(ylo, v.y);
        const float c[3] = {v.x, v.y, v.z};
        for (int k = 0; k < 3; ++k) {
            ext_lo[k] = std::min(ext_lo[k], c[k]);
            ext_hi[k] = std::max(ext_hi[k], c[k]);
        }
    }
    EXPECT_NEAR(ylo, 0.0f, 1e-6f);
    EXPECT_NEAR(std::max({ext_hi[0] - ext_lo[0], ext_hi[1] - ext_lo[1], ext_hi[2] - ext_lo[2]}),
                0.25f, 1e-5f);
    EXPECT_NEAR((ext_lo[0] + ext_hi[0]) / 2, 0.2764f, 1e-5f);
    EXPECT_NEAR((ext_lo[2] + ext_hi[2]) / 2, 0.32f, 1e-5f);
}


// ---- bad scene files -----------------------------------------------------------------------

TEST(SceneErrors, AMissingSceneFileIsNamed) {
    const std::string path = kFixtures + "there_is_no_such_scene.json";
    expect_error([&] { (void)load_scene(path); }, {path});
}

TEST(SceneErrors, NotJsonIsNamedInTheError) {
    expect_scene_error("not_json.json", {"JSON", "line"});
}

TEST(SceneErrors, AnUnknownKeyIsNamedInTheError) {
    expect_scene_error("unknown_key.json", {"meshs", "unknown key"});
}

TEST(SceneErrors, AMissingMeshFileIsNamedInTheError) {
    expect_scene_error("missing_mesh_file.json",
                       {"meshes[0].file", "no_such_model.off", "no such file"});
}

TEST(SceneErrors, AMeshWithoutAFileIsNamedInTheError) {
    expect_scene_error("mesh_without_file.json", {"meshes[0].file"});
}

TEST(SceneErrors, ANegativeMeshSizeIsNamedInTheError) {
    expect_scene_error("mesh_negative_size.json", {"meshes[0].size"});
}

TEST(SceneErrors, AZeroMeshSizeIsNamedInTheError) {
    expect_scene_error("mesh_zero_size.json", {"meshes[0].size"});
}

TEST(SceneErrors, AnAlbedoAboveOneIsNamedInTheError) {
    expect_scene_error("mesh_albedo_out_of_range.json", {"meshes[0].albedo"});
}

TEST(SceneErrors, ANegativeWallAlbedoIsNamedInTheError) {
    expect_scene_error("room_albedo_negative.json", {"room.left"});
}

TEST(SceneErrors, RotateWithTwoNumbersIsNamedInTheError) {
    expect_scene_error("mesh_rotate_two_numbers.json", {"meshes[0].rotate"});
}

TEST(SceneErrors, ZeroSamplingPointsIsNamedInTheError) {
    expect_scene_error("points_zero.json", {"sampling.points"});
}

TEST(SceneErrors, ABillionSamplingPointsIsNamedInTheError) {
    expect_scene_error("points_huge.json", {"sampling.points"});
}

TEST(SceneErrors, PointsAndDensityTogetherIsAnError) {
    expect_scene_error("points_and_density.json", {"sampling"});
}

TEST(SceneErrors, AnOctreeHeightOf30IsNamedInTheError) {
    expect_scene_error("max_height_30.json", {"octree.max_height"});
}

TEST(SceneErrors, AMeshFileWithoutFacesIsNamedInTheError) {
    expect_scene_error("mesh_is_point_cloud.json", {"meshes[0].file", "point_cloud.ply", "faces"});
}

TEST(SceneErrors, ANegativeRoomSizeIsNamedInTheError) {
    expect_scene_error("room_size_negative.json", {"room.size"});
}

TEST(SceneErrors, AMalformedMeshFileIsNamedWithTheSceneAndTheField) {
    // load_scene promises (scene.h) that its errors name the scene file and the field; a broken
    // mesh file is an error in meshes[0].file as much as a missing one is.
    expect_scene_error("mesh_malformed.json", {"meshes[0].file", "malformed.off"});
}

TEST(SceneErrors, AMeshWithoutExtentIsNamedInTheError) {
    // Three coincident vertices: "size" cannot scale a mesh of extent 0 (it would divide by 0
    // and fill the mesh with non-finite coordinates).
    expect_scene_error("mesh_without_extent.json", {"meshes[0]"});
}

TEST(SceneErrors, ATopLevelArrayIsNotAScene) {
    ScratchDir dir;
    const std::string path = dir.write("array.json", "[1, 2, 3]");
    expect_error([&] { (void)load_scene(path); }, {path, "object"});
}

TEST(SceneErrors, AStringWhereANumberBelongsIsNamedInTheError) {
    ScratchDir dir;
    const std::string path = dir.write("string.json", R"({ "sampling": { "seed": "one" } })");
    expect_error([&] { (void)load_scene(path); }, {path, "sampling.seed"});
}

TEST(SceneErrors, ALightOutsideTheCeilingIsNamedInTheError) {
    ScratchDir dir;
    const std::string path = dir.write("light.json", R"({ "light": { "center": [2, 0.2] } })");
    expect_error([&] { (void)load_scene(path); }, {path, "light.center"});
}

// ---- raw point clouds ----------------------------------------------------------------------

// n points on a sphere of radius 0.1 around (1, 2, 3), with outward normals.
struct Sphere3 {
    std::vector<Vec3> p, n;
};
Sphere3 fibonacci_sphere(size_t n) {
    Sphere3 s;
    const double golden = M_PI * (3.0 - std::sqrt(5.0));
    for (size_t i = 0; i < n; ++i) {
        const double y = 1 - 2 * (double(i) + 0.5) / double(n);
        const double r = std::sqrt(1 - y * y), a = golden * double(i);
        const Vec3 d{float(r * std::cos(a)), float(y), float(r * std::sin(a))};
        s.n.push_back(d / length(d));
        s.p.push_back(Vec3{1, 2, 3} + d * 0.1f);
    }
    return s;
}

std::string ascii_ply(const Sphere3& s, bool normals, bool radius) {
    std::string out = "ply\nformat ascii 1.0\nelement vertex " + std::to_string(s.p.size()) +
                      "\nproperty float x\nproperty float y\nproperty float z\n";
    if (normals) out += "property float nx\nproperty float ny\nproperty float nz\n";
    if (radius) out += "property float radius\n";
    out += "end_header\n";
    char line[256];
    for (size_t i = 0; i < s.p.size(); ++i) {
        std::snprintf(line, sizeof line, "%.9g %.9g %.9g", s.p[i].x, s.p[i].y, s.p[i].z);
        out += line;
        if (normals) {
            std::snprintf(line, sizeof line, " %.9g %.9g %.9g", s.n[i].x, s.n[i].y, s.n[i].z);
            out += line;
        }
        if (radius) {
            std::snprintf(line, sizeof line, " %.9g", 0.003 + 0.001 * double(i % 3));
            out += line;
        }
        out += "\n";
    }
    return out;
}

TEST(ScenePointCloud, NormalsInTheFileAreKept) {
    ScratchDir dir;
    const Sphere3 s = fibonacci_sphere(400);
    const PointSet ps = load_point_cloud(dir.write("with_normals.ply", ascii_ply(s, true, false)));
    ASSERT_EQ(ps.size(), s.p.size());
    ASSERT_EQ(ps.normals.size(), s.p.size());
    for (size_t i = 0; i < ps.size(); ++i) {
        ASSERT_EQ(ps.positions[i], s.p[i]) << i;
        ASSERT_EQ(ps.normals[i], s.n[i]) << i;
    }
}

TEST(ScenePointCloud, MissingNormalsAreEstimatedUnitLengthAndOutward) {
    ScratchDir dir;
    const Sphere3 s = fibonacci_sphere(600);
    const PointSet ps = load_point_cloud(dir.write("no_normals.ply", ascii_ply(s, false, false)));
    ASSERT_EQ(ps.size(), s.p.size());
    ASSERT_EQ(ps.normals.size(), s.p.size());
    size_t outward = 0;
    for (size_t i = 0; i < ps.size(); ++i) {
        ASSERT_NEAR(length(ps.normals[i]), 1.0f, 1e-4f) << i;
        EXPECT_GT(std::fabs(dot(ps.normals[i], s.n[i])), 0.95f) << "point " << i;
        outward += dot(ps.normals[i], s.n[i]) > 0;
    }
    // Oriented consistently, away from the centre (normals.h).
    EXPECT_EQ(outward, ps.size());
}

TEST(ScenePointCloud, MissingRadiiAndColoursAreFilledIn) {
    ScratchDir dir;
    const Sphere3 s = fibonacci_sphere(400);
    for (bool normals : {true, false}) {
        SCOPED_TRACE(normals ? "with normals" : "without normals");
        const PointSet ps = load_point_cloud(dir.write("cloud.ply", ascii_ply(s, normals, false)));
        ASSERT_EQ(ps.radii.size(), ps.size());
        ASSERT_EQ(ps.colors.size(), ps.size());
        // Spacing on this sphere is about sqrt(4 pi 0.1^2 / 400) = 0.0177 m.
        for (float r : ps.radii) {
            ASSERT_GT(r, 0.001f);
            ASSERT_LT(r, 0.05f);
        }
        for (Vec3 c : ps.colors) ASSERT_EQ(c, (Vec3{0.8f, 0.8f, 0.8f}));
    }
}

TEST(ScenePointCloud, RadiiInTheFileAreKept) {
    ScratchDir dir;
    const Sphere3 s = fibonacci_sphere(100);
    const PointSet ps = load_point_cloud(dir.write("radius.ply", ascii_ply(s, true, true)));
    ASSERT_EQ(ps.radii.size(), ps.size());
    for (size_t i = 0; i < ps.size(); ++i)
        ASSERT_FLOAT_EQ(ps.radii[i], float(0.003 + 0.001 * double(i % 3))) << i;
}

TEST(ScenePointCloud, AnEmptyPlyIsAClearError) {
    ScratchDir dir;
    const std::string path = dir.write("empty.ply",
                                       "ply\nformat ascii 1.0\nelement vertex 0\n"
                                       "property float x\nproperty float y\nproperty float z\n"
                                       "end_header\n");
    expect_error([&] { (void)load_point_cloud(path); }, {path, "empty"});
}

TEST(ScenePointCloud, AMissingFileIsNamed) {
    const std::string path = kFixtures + "no_such_cloud.ply";
    expect_error([&] { (void)load_point_cloud(path); }, {path});
}

TEST(ScenePointCloud, FacesInTheFileAreIgnored) {
    const PointSet ps = load_point_cloud(kFixtures + "tetra_inside_out.off");
    EXPECT_EQ(ps.size(), 4u);
    EXPECT_EQ(ps.normals.size(), 4u);
    for (Vec3 n : ps.normals) EXPECT_NEAR(length(n), 1.0f, 1e-4f);
}

}  // namespace
}  // namespace vmap
