// Pictures: what the renderer draws, checked on pixels of scenes whose geometry is known, and
// bad options.
#include "vmap/render.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "test_util.h"
#include "vmap/error.h"
#include "vmap/io.h"
#include "vmap/query.h"

namespace vmap {
namespace {

std::string render_scene() { return std::string(VMAP_TEST_DATA) + "/render/block-room.json"; }

// The 0.1 m cube of block-room.json: x [0.2264, 0.3264], y [0, 0.1], z [0.35, 0.45].
constexpr Vec3 kCubeLo{0.2264f, 0.f, 0.35f}, kCubeHi{0.3264f, 0.1f, 0.45f};
constexpr Vec3 kEyePos{0.2764f, 0.f, 0.1f};  // on the floor in front of the cube
constexpr float kBack = 0.5592f;             // the back wall's z

// Does the segment a-b pass through the box (slab test)? The geometric truth for the shadow.
bool segment_hits_box(Vec3 a, Vec3 b, Vec3 lo, Vec3 hi) {
    float t0 = 0, t1 = 1;
    const float o[3] = {a.x, a.y, a.z}, d[3] = {b.x - a.x, b.y - a.y, b.z - a.z};
    const float l[3] = {lo.x, lo.y, lo.z}, h[3] = {hi.x, hi.y, hi.z};
    for (int k = 0; k < 3; ++k) {
        if (std::fabs(d[k]) < 1e-12f) {
            if (o[k] < l[k] || o[k] > h[k]) return false;
            continue;
        }
        float ta = (l[k] - o[k]) / d[k], tb = (h[k] - o[k]) / d[k];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
        if (t0 > t1) return false;
    }
    return true;
}

bool is_purple(const uint8_t* p) { return p[2] > p[1] + 60 && p[0] > p[1] + 20; }
bool is_cyan(const uint8_t* p) { return p[0] < 80 && p[1] > 150 && p[2] > 150; }

// Fraction of purple pixels in the (2r+1)^2 window about where world point w lands.
double purple_fraction(const Image& img, const Camera& cam, Vec3 w, int r = 3) {
    const Projection pr = project(cam, img.width, img.height, w);
    EXPECT_GT(pr.depth, 0);
    int n = 0, purple = 0;
    for (int y = int(pr.y) - r; y <= int(pr.y) + r; ++y)
        for (int x = int(pr.x) - r; x <= int(pr.x) + r; ++x) {
            if (x < 0 || y < 0 || x >= img.width || y >= img.height) continue;
            ++n;
            purple += is_purple(img.pixel(x, y));
        }
    EXPECT_GT(n, 0);
    return n ? double(purple) / n : 0;
}

class RenderTest : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        scene_ = new Scene(load_scene(render_scene()));
        BuildParams bp = test::cpu_params(7, 3);
        // K = 1: one occluder disc on the segment hides a pair. With the default K = 2 the
        // sparse discs of this small cloud let many shadow pairs through (both faces of the cube
        // must be hit), which is the V-map's conservative side, not what this test is about.
        bp.visibility.K = 1;
        vm_ = new VisibilityMap(build_vmap(sample_scene(*scene_), bp));
        eye_ = nearest_point(*vm_, kEyePos);
    }
    static void TearDownTestSuite() {
        delete vm_;
        delete scene_;
    }
    static RenderOptions small() {
        RenderOptions o;
        o.width = o.height = 300;
        return o;
    }
    static Scene* scene_;
    static VisibilityMap* vm_;
    static uint32_t eye_;
};
Scene* RenderTest::scene_ = nullptr;
VisibilityMap* RenderTest::vm_ = nullptr;
uint32_t RenderTest::eye_ = 0;

TEST_F(RenderTest, ShadowOfTheBlockOnTheBackWallIsNotPurpleTheWallBesideItIs) {
    ASSERT_TRUE(scene_->camera.has_value());
    const Camera cam = *scene_->camera;
    const Image img = render_visible(*vm_, eye_, cam, small());
    const Vec3 eye = vm_->points().positions[vm_->inverse()[eye_]];
    const Vec3 shadow[] = {{0.2764f, 0.13f, kBack}, {0.24f, 0.11f, kBack}, {0.31f, 0.15f, kBack}};
    const Vec3 lit[] = {{0.08f, 0.13f, kBack}, {0.47f, 0.13f, kBack}, {0.2764f, 0.35f, kBack}};
    for (Vec3 w : shadow) {
        ASSERT_TRUE(segment_hits_box(eye, w, kCubeLo, kCubeHi)) << "test geometry: in shadow";
        EXPECT_LT(purple_fraction(img, cam, w), 0.2) << w.x << "," << w.y;
    }
    for (Vec3 w : lit) {
        ASSERT_FALSE(segment_hits_box(eye, w, kCubeLo, kCubeHi)) << "test geometry: lit";
        EXPECT_GT(purple_fraction(img, cam, w), 0.9) << w.x << "," << w.y;
    }
}

TEST_F(RenderTest, TheEyeIsMarkedCyan) {
    const Camera cam = default_camera(vm_->points());
    const Image img = render_visible(*vm_, eye_, cam, small());
    const Projection pr =
        project(cam, img.width, img.height, vm_->points().positions[vm_->inverse()[eye_]]);
    ASSERT_GT(pr.depth, 0);
    ASSERT_TRUE(pr.x >= 0 && pr.y >= 0 && pr.x < img.width && pr.y < img.height);
    EXPECT_TRUE(is_cyan(img.pixel(int(pr.x), int(pr.y))));
    // Without the marker (albedo render) the same pixel is not cyan: the dot is what makes it.
    const PointSet pts = points_in_input_order(*vm_);
    const Image plain = render_points(pts, pts.colors, cam, small());
    EXPECT_FALSE(is_cyan(plain.pixel(int(pr.x), int(pr.y))));
}

TEST_F(RenderTest, ColouredPlyReadsBackWithTheVisibleSetInPurple) {
    const std::string path = ::testing::TempDir() + "/vmap_visible.ply";
    const PointSet pts = points_in_input_order(*vm_);
    const auto colors = visible_colors(*vm_, eye_);
    write_colored_ply(path, pts, colors);
    const ModelData back = read_ply(path);
    ASSERT_EQ(back.points.size(), pts.size());
    ASSERT_TRUE(back.points.has_normals());
    ASSERT_TRUE(back.points.has_colors());
    const Vec3 purple = VisibleStyle{}.visible;
    const float pr = linear_to_srgb8(purple.x) / 255.f, pb = linear_to_srgb8(purple.z) / 255.f;
    size_t n_purple = 0;
    for (size_t i = 0; i < pts.size(); ++i) {
        ASSERT_EQ(back.points.positions[i], pts.positions[i]);
        const Vec3 c = back.points.colors[i];
        n_purple += std::fabs(c.x - pr) < 1e-3f && std::fabs(c.z - pb) < 1e-3f;
    }
    EXPECT_EQ(n_purple, vm_->visible_set(eye_).size());
    std::filesystem::remove(path);
    std::vector<Vec3> short_colors(colors.begin(), colors.end() - 1);
    EXPECT_THROW(write_colored_ply(path, pts, short_colors), Error);
    EXPECT_FALSE(std::filesystem::exists(path));
}

TEST_F(RenderTest, VisibleColoursFollowTheVisibleSet) {
    const auto colors = visible_colors(*vm_, eye_);
    const auto set = vm_->visible_set(eye_);
    std::vector<uint8_t> in(vm_->points().size(), 0);
    for (uint32_t i : set) in[i] = 1;
    const VisibleStyle style;
    for (uint32_t i = 0; i < colors.size(); ++i) {
        if (in[i]) {
            ASSERT_TRUE(colors[i] == style.visible) << i;
        } else if (vm_->query(eye_, i) == PairVisibility::kSameLeaf) {
            ASSERT_TRUE(colors[i] == style.eye) << i;
        } else {
            ASSERT_FALSE(colors[i] == style.visible) << i;
        }
    }
    EXPECT_THROW(visible_colors(*vm_, uint32_t(vm_->points().size())), Error);
}

// Two squares of points facing the camera: a red one far, a smaller green one near.
PointSet two_squares(std::vector<Vec3>& colors, bool near_first) {
    PointSet p;
    auto square = [&](float z, float half, Vec3 c) {
        const int n = 60;
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) {
                p.positions.push_back(
                    {-half + 2 * half * (i + 0.5f) / n, -half + 2 * half * (j + 0.5f) / n, z});
                p.normals.push_back({0, 0, -1});
                p.radii.push_back(half / n * 1.2f);
                colors.push_back(c);
            }
    };
    if (near_first) square(1.0f, 0.2f, {0, 1, 0});
    square(2.0f, 1.0f, {1, 0, 0});
    if (!near_first) square(1.0f, 0.2f, {0, 1, 0});
    return p;
}

TEST(Render, ANearSurfaceHidesAFarOneWhateverTheOrder) {
    Camera cam;
    cam.eye = {0, 0, -1};
    cam.target = {0, 0, 1};
    RenderOptions o;
    o.width = o.height = 200;
    o.shade = false;
    for (bool near_first : {false, true}) {
        std::vector<Vec3> colors;
        const PointSet p = two_squares(colors, near_first);
        const Image img = render_points(p, colors, cam, o);
        const uint8_t* c = img.pixel(100, 100);  // centre: the near green square
        EXPECT_GT(c[1], 200);
        EXPECT_LT(c[0], 30);
        const Projection pr = project(cam, 200, 200, {0.6f, 0, 2});  // only the far square
        const uint8_t* f = img.pixel(int(pr.x), int(pr.y));
        EXPECT_GT(f[0], 200);
        EXPECT_LT(f[1], 30);
        const uint8_t* bg = img.pixel(2, 2);  // outside both: the background
        EXPECT_EQ(bg[0], linear_to_srgb8(o.background.x));
        EXPECT_EQ(bg[2], linear_to_srgb8(o.background.z));
    }
}

TEST(Render, ShadingDarkensDiscsSeenObliquely) {
    // One wall facing the camera, one at 70 degrees: with shading the tilted one is darker,
    // without shading they are the same.
    PointSet p;
    std::vector<Vec3> colors;
    for (int i = 0; i < 40; ++i)
        for (int j = 0; j < 40; ++j) {
            p.positions.push_back({-0.5f + i * 0.01f, -0.2f + j * 0.01f, 2});
            p.normals.push_back({0, 0, -1});
            const float a = 70 * float(M_PI) / 180;
            // Along (cos a, 0, -sin a) from (0.1, y, 2); the normal 70 degrees from -z.
            p.positions.push_back(
                {0.1f + i * 0.01f * std::cos(a), -0.2f + j * 0.01f, 2 - i * 0.01f * std::sin(a)});
            p.normals.push_back({-std::sin(a), 0, -std::cos(a)});
            p.radii.insert(p.radii.end(), {0.012f, 0.012f});
            colors.insert(colors.end(), {Vec3{0.5f, 0.5f, 0.5f}, Vec3{0.5f, 0.5f, 0.5f}});
        }
    Camera cam;
    cam.eye = {0, 0, 0};
    cam.target = {0, 0, 2};
    RenderOptions o;
    o.width = o.height = 200;
    const Projection a = project(cam, 200, 200, {-0.3f, 0, 2});
    const Projection b = project(cam, 200, 200, {0.1f + 0.2f * 0.342f, 0, 2 - 0.2f * 0.940f});
    const Image shaded = render_points(p, colors, cam, o);
    EXPECT_GT(shaded.pixel(int(a.x), int(a.y))[0], shaded.pixel(int(b.x), int(b.y))[0] + 30);
    o.shade = false;
    const Image flat = render_points(p, colors, cam, o);
    EXPECT_NEAR(flat.pixel(int(a.x), int(a.y))[0], flat.pixel(int(b.x), int(b.y))[0], 2);
}

TEST(Render, ImageSizeIsHonouredAndPngRoundTrips) {
    std::vector<Vec3> colors;
    const PointSet p = two_squares(colors, false);
    Camera cam;
    cam.eye = {0, 0, -1};
    cam.target = {0, 0, 1};
    RenderOptions o;
    o.width = 123;
    o.height = 45;
    const Image img = render_points(p, colors, cam, o);
    EXPECT_EQ(img.width, 123);
    EXPECT_EQ(img.height, 45);
    EXPECT_EQ(img.rgb.size(), size_t(123) * 45 * 3);
    const std::string path = ::testing::TempDir() + "/vmap_render_roundtrip.png";
    write_png(path, img);
    EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
    const Image back = read_png(path);
    EXPECT_EQ(back.width, 123);
    EXPECT_EQ(back.height, 45);
    EXPECT_EQ(back.rgb, img.rgb);
    std::filesystem::remove(path);
}

TEST(Render, SideBySideKeepsEachPanel) {
    Image a{3, 2, std::vector<uint8_t>(3 * 2 * 3, 10)},
        b{4, 4, std::vector<uint8_t>(4 * 4 * 3, 200)};
    const Image images[] = {a, b};
    const Image s = side_by_side(images);
    EXPECT_EQ(s.height, 4);
    EXPECT_GT(s.width, 7);  // a gap between the panels
    EXPECT_EQ(s.pixel(0, 1)[0], 10);
    EXPECT_EQ(s.pixel(s.width - 1, 0)[0], 200);
    EXPECT_THROW(side_by_side(std::span<const Image>{}), Error);
}

TEST(Render, DefaultCameraSeesTheWholeRoom) {
    const PointSet p = test::sample(test::scene_path("cornell-empty"), 5000);
    const Camera cam = default_camera(p);
    for (Vec3 q : p.positions) {
        const Projection pr = project(cam, 400, 400, q);
        ASSERT_GT(pr.depth, 0);
        ASSERT_TRUE(pr.x >= 0 && pr.x < 400 && pr.y >= 0 && pr.y < 400) << q.x << " " << q.y;
    }
    EXPECT_LT(cam.eye.z, 0);  // in front of the open side (z = 0)
}

TEST(Render, BadOptionsAreErrors) {
    std::vector<Vec3> colors;
    const PointSet p = two_squares(colors, false);
    Camera cam;
    cam.eye = {0, 0, -1};
    cam.target = {0, 0, 1};
    RenderOptions o;
    o.width = 0;
    EXPECT_THROW(render_points(p, colors, cam, o), Error);
    o.width = 100;
    o.height = -3;
    EXPECT_THROW(render_points(p, colors, cam, o), Error);
    o.height = 100;
    o.supersample = 9;
    EXPECT_THROW(render_points(p, colors, cam, o), Error);
    o.supersample = 2;
    o.splat_scale = std::nanf("");
    EXPECT_THROW(render_points(p, colors, cam, o), Error);
    o.splat_scale = 2;
    Camera bad = cam;
    bad.eye.x = std::nanf("");
    EXPECT_THROW(render_points(p, colors, bad, o), Error);
    bad = cam;
    bad.target = bad.eye;
    EXPECT_THROW(render_points(p, colors, bad, o), Error);
    bad = cam;
    bad.up = {0, 0, 1};  // parallel to the view direction
    EXPECT_THROW(render_points(p, colors, bad, o), Error);
    bad = cam;
    bad.fov_y_deg = 0;
    EXPECT_THROW(render_points(p, colors, bad, o), Error);
    colors.pop_back();
    EXPECT_THROW(render_points(p, colors, cam, o), Error);
    EXPECT_THROW(default_camera(PointSet{}), Error);
}

TEST(Render, WritePngToAMissingFolderFailsAndLeavesNothing) {
    const Image img{2, 2, std::vector<uint8_t>(12, 0)};
    const std::string path = ::testing::TempDir() + "/no_such_folder_vmap/x.png";
    EXPECT_THROW(write_png(path, img), Error);
    EXPECT_FALSE(std::filesystem::exists(path));
    EXPECT_THROW(write_png(::testing::TempDir() + "/bad.png", Image{2, 2, {}}), Error);
}

TEST(SceneCamera, IsReadFromTheSceneFile) {
    const Scene sc = load_scene(render_scene());
    ASSERT_TRUE(sc.camera.has_value());
    EXPECT_FLOAT_EQ(sc.camera->eye.y, 0.54f);
    EXPECT_FLOAT_EQ(sc.camera->fov_y_deg, 50.f);
    EXPECT_FALSE(load_scene(test::scene_path("cornell-empty")).camera.has_value());
}

TEST(SceneCamera, BadCameraFieldsAreNamed) {
    const std::string dir = ::testing::TempDir();
    auto expect_error = [&](const std::string& camera, const std::string& field) {
        const std::string path = dir + "/vmap_bad_camera.json";
        std::ofstream(path) << "{ \"camera\": " << camera << " }";
        try {
            load_scene(path);
            ADD_FAILURE() << "no error for " << camera;
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
        }
    };
    expect_error(R"({"eye": [0,0,-1], "target": [0,0,1], "fov": 0})", "camera.fov");
    expect_error(R"({"eye": [0,0,1], "target": [0,0,1]})", "camera.target");
    expect_error(R"({"target": [0,0,1]})", "camera.eye");
    expect_error(R"({"eye": [0,0,-1], "target": [0,0,1], "up": [0,0,2]})", "camera.up");
    expect_error(R"({"eye": [0,0,-1], "target": [0,0,1], "zoom": 2})", "camera.zoom");
}

}  // namespace
}  // namespace vmap
