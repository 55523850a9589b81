// What scene_test and sampling_test share: the scenes' folders, the Cornell room's size, areas
// and normals of a scene's surfaces, and comparing point sets bit for bit.
#pragma once

#include "vmap/scene.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <initializer_list>
#include <string>
#include <string_view>
#include <vector>

#include "test_files.h"
#include "vmap/error.h"

namespace vmap {
namespace {

namespace fs = std::filesystem;

const std::string kScenes = std::string(VMAP_SOURCE_DIR) + "/scenes/";
const std::string kFixtures = std::string(VMAP_TEST_DATA) + "/scenes/";

// The Cornell room as the shipped scenes give it.
constexpr float kW = 0.5528f, kH = 0.5488f, kD = 0.5592f;

using test::expect_error;
using test::ScratchDir;

// The scene fixture `name` must fail to load with an error naming the file and `parts`.
inline void expect_scene_error(const std::string& name, std::initializer_list<std::string_view> parts) {
    SCOPED_TRACE(name);
    const std::string path = kFixtures + name;
    ASSERT_TRUE(fs::exists(path)) << path;
    expect_error([&] { (void)load_scene(path); }, {path});
    expect_error([&] { (void)load_scene(path); }, parts);
}

inline double triangle_area(const Mesh& m, const std::array<uint32_t, 3>& t) {
    const Vec3 a = m.vertices[t[0]], b = m.vertices[t[1]], c = m.vertices[t[2]];
    const Vec3 x = cross(b - a, c - a);
    return 0.5 * std::sqrt(double(x.x) * x.x + double(x.y) * x.y + double(x.z) * x.z);
}

inline double surface_area(const SceneSurface& s) {
    double a = 0;
    for (const auto& t : s.mesh.triangles) a += triangle_area(s.mesh, t);
    return a;
}

inline double total_area(const Scene& sc) {
    double a = 0;
    for (const auto& s : sc.surfaces) a += surface_area(s);
    return a;
}

// Positive for a closed mesh whose triangles wind counter-clockwise seen from outside.
inline double signed_volume(const Mesh& m) {
    double v = 0;
    for (const auto& t : m.triangles) {
        const Vec3 a = m.vertices[t[0]], b = m.vertices[t[1]], c = m.vertices[t[2]];
        const Vec3 x = cross(b, c);
        v += double(a.x) * x.x + double(a.y) * x.y + double(a.z) * x.z;
    }
    return v / 6.0;
}

inline Vec3 triangle_normal(const Mesh& m, const std::array<uint32_t, 3>& t) {
    const Vec3 a = m.vertices[t[0]], b = m.vertices[t[1]], c = m.vertices[t[2]];
    const Vec3 x = cross(b - a, c - a);
    return x / length(x);
}

inline const SceneSurface* find_surface(const Scene& sc, const std::string& name) {
    for (const auto& s : sc.surfaces)
        if (s.name == name) return &s;
    return nullptr;
}

inline void expect_bits_equal(const PointSet& a, const PointSet& b) {
    ASSERT_EQ(a.size(), b.size());
    ASSERT_EQ(a.normals.size(), b.normals.size());
    ASSERT_EQ(a.colors.size(), b.colors.size());
    ASSERT_EQ(a.radii.size(), b.radii.size());
    ASSERT_EQ(a.emission.size(), b.emission.size());
    size_t differ = 0;
    for (size_t i = 0; i < a.size(); ++i) {
        const bool same = a.positions[i] == b.positions[i] && a.normals[i] == b.normals[i] &&
                          a.colors[i] == b.colors[i] && a.radii[i] == b.radii[i] &&
                          a.emission[i] == b.emission[i];
        if (!same && differ++ < 5) ADD_FAILURE() << "point " << i << " differs";
    }
    EXPECT_EQ(differ, 0u);
}

}  // namespace
}  // namespace vmap
