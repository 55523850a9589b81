// Point rendering to images: disc splats with a depth buffer, simple shading and
// supersampled anti-aliasing, on all CPU cores (oneTBB, screen tiles).
//
// A point is drawn as its surface disc: centre = position, orientation = normal (a disc facing
// the camera when the set has no normals), radius = splat radius x RenderOptions::splat_scale
// (one pixel when the set has no radii). Each pixel's ray is intersected with the disc's plane,
// so depth is exact and neighbouring discs of one surface meet without seams; the fragments
// within a small depth band of the nearest one are blended with weights falling off towards each
// disc's rim (two-pass surface splatting), then the supersamples are averaged.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "vmap/camera.h"
#include "vmap/mesh.h"
#include "vmap/visibility_map.h"

namespace vmap {

// The Cornell room seen through its open side (z = 0) with the whole room in view; for a raw
// cloud, its bounding box seen from -z: the eye on the box's centre line in x and y, far enough
// in front of the box's near face (z = min z) that the face fills the view with a small margin
// at a square aspect. Throws vmap::Error for an empty set.
Camera default_camera(const PointSet& points);

// Throws vmap::Error naming `source` for a camera that cannot render: non-finite eye, target or
// up, fov outside [0.1, 179] degrees, eye == target, up zero or parallel to the view. Callers
// check before expensive work; render_points checks again.
void check_camera(const Camera& cam, const std::string& source);

struct RenderOptions {
    int width = 800;  // pixels, 1..16384
    int height = 800;
    bool shade = true;         // multiply the colour by ambient + (1 - ambient) |n . v|
    float ambient = 0.25f;     // shading floor in [0, 1]
    float splat_scale = 3.0f;  // disc radius = splat radius x this (> 0); > 1 closes the gaps
                               // that random sampling leaves between discs (single-pixel holes
                               // left over are filled from their neighbours)
    int supersample = 2;       // s x s samples per pixel, 1..4
    Vec3 background{0.02f, 0.02f, 0.025f};  // linear RGB
    bool keep_linear = false;  // also keep the linear colours, unclamped (Image::linear)
};

// 8-bit sRGB, rows top-down, 3 bytes per pixel.
struct Image {
    int width = 0, height = 0;
    std::vector<uint8_t> rgb;
    std::vector<Vec3> linear =
        {};  // linear RGB before clamping and sRGB (RenderOptions::keep_linear)

    const uint8_t* pixel(int x, int y) const { return rgb.data() + 3 * (size_t(y) * width + x); }
    uint8_t* pixel(int x, int y) { return rgb.data() + 3 * (size_t(y) * width + x); }
};

// Where a world point lands in the image of `cam` at width x height: pixel coordinates (x right,
// y down, pixel centres at .5) and the distance along the view axis (<= 0: behind the eye).
struct Projection {
    float x = 0, y = 0, depth = 0;
};
Projection project(const Camera& cam, int width, int height, Vec3 p);

// Renders `points` with per-point `colors` (linear RGB, same order and size as
// points.positions). Throws vmap::Error when the sizes differ, the set is empty, the options are
// out of range, or the camera is degenerate (non-finite, eye == target, up parallel to the view
// direction, fov outside (0, 180)).
struct RenderStats {
    uint64_t discs = 0;      // discs in front of the camera and on screen
    uint64_t tile_refs = 0;  // (disc, tile) pairs after binning
    uint64_t fragments = 0;  // samples a disc covers (depth pass)
};
Image render_points(const PointSet& points, std::span<const Vec3> colors, const Camera& cam,
                    const RenderOptions& opt, RenderStats* stats = nullptr);

// Images left to right with a thin gap (background colour); heights may differ (shorter ones are
// centred vertically). Throws vmap::Error for an empty list.
Image side_by_side(std::span<const Image> images);

// Draws a filled disc of `radius` pixels at (x, y) with a one-pixel dark rim; colour is sRGB
// bytes. Parts outside the image are clipped.
void draw_dot(Image& img, float x, float y, float radius, const uint8_t rgb[3]);

// Writes `text` (digits, lower-case letters, space and a few signs; others are drawn as blanks)
// with a built-in 5x7 pixel font scaled by `scale`, its top-left corner at (x, y).
void draw_text(Image& img, int x, int y, const std::string& text, int scale, const uint8_t rgb[3]);

// Writes a PNG (stb_image_write) to a temporary name and renames it into place, so a failure
// leaves no half-written file. Throws vmap::Error naming the path.
void write_png(const std::string& path, const Image& img);
// Reads a PNG as 8-bit RGB (for tests and tools). Throws vmap::Error naming the path.
Image read_png(const std::string& path);

// ---- visibility pictures (paper Fig. 9 and 11) ----

// The V-map's points back in input order and units (vm.points are in octree order and frame),
// so that input ids index them directly.
PointSet points_in_input_order(const VisibilityMap& vm);

struct VisibleStyle {
    Vec3 visible{0.30f, 0.02f, 0.72f};  // purple (linear RGB)
    Vec3 eye{0.0f, 0.85f, 0.85f};       // cyan: the eye point and the points of its leaf
    float hidden_dim = 0.45f;           // other points: albedo x this
};
// Per point, in input order: `visible` for the points of vm.visible_set(eye), `eye` for the eye
// and the other points of its leaf, the dimmed albedo (grey 0.8 without colours) for the rest.
// Throws vmap::Error for an eye id out of range.
std::vector<Vec3> visible_colors(const VisibilityMap& vm, uint32_t eye,
                                 const VisibleStyle& style = {});
// Renders visible_colors(vm, eye) and marks the eye with a cyan dot (when it is in front of the
// camera), as in Fig. 9.
Image render_visible(const VisibilityMap& vm, uint32_t eye, const Camera& cam,
                     const RenderOptions& opt, const VisibleStyle& style = {});

// Exports `points` with per-point `colors` (linear RGB, same size) as a binary PLY that MeshLab
// and CloudCompare read: float x y z, nx ny nz (when present), uchar red green blue, float radius
// (when present). The colour bytes are sRGB, as viewers display them. Temp file + rename; throws
// vmap::Error naming the path.
void write_colored_ply(const std::string& path, const PointSet& points,
                       std::span<const Vec3> colors);

// Linear [0,1] to 8-bit sRGB and back (the transfer curve of IEC 61966-2-1).
uint8_t linear_to_srgb8(float c);
float srgb8_to_linear(uint8_t c);

}  // namespace vmap
