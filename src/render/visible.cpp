// Pictures of the V-map: the region visible from an eye point (paper Fig. 9, Fig. 11).
#include <fmt/format.h>

#include <algorithm>

#include "vmap/error.h"
#include "vmap/io.h"
#include "vmap/render.h"

namespace vmap {

PointSet points_in_input_order(const VisibilityMap& vm) {
    const PointSet& p = vm.points();
    const size_t n = p.size();
    PointSet out;
    auto permute = [&](const auto& src, auto& dst) {
        if (src.empty()) return;
        dst.resize(n);
        for (size_t k = 0; k < n; ++k) dst[vm.order()[k]] = src[k];
    };
    permute(p.positions, out.positions);
    permute(p.normals, out.normals);
    permute(p.colors, out.colors);
    permute(p.radii, out.radii);
    permute(p.emission, out.emission);
    const Octree& t = vm.octree();  // from the octree's frame back to input units (exact)
    for (Vec3& q : out.positions) q = t.to_world(q);
    for (float& r : out.radii) r = float(r * t.scale());
    out.origin = p.origin;  // where the input had the positions' zero
    return out;
}

std::vector<Vec3> visible_colors(const VisibilityMap& vm, uint32_t eye, const VisibleStyle& style) {
    const size_t n = vm.points().size();
    if (eye >= n)
        throw Error(fmt::format("eye point id {} out of range (the V-map has {} points)", eye, n));
    std::vector<Vec3> c(n);
    for (size_t k = 0; k < n; ++k) {
        const Vec3 albedo = vm.points().has_colors() ? vm.points().colors[k] : Vec3{0.8f, 0.8f, 0.8f};
        c[vm.order()[k]] = albedo * style.hidden_dim;
    }
    for (uint32_t i : vm.visible_set(eye)) c[i] = style.visible;
    const int32_t node = vm.octree().leaf_node()[vm.octree().leaf_of_point(vm.inverse()[eye])];
    for (uint32_t k = vm.octree().point_begin()[node]; k < vm.octree().point_end()[node]; ++k)
        c[vm.order()[k]] = style.eye;
    return c;
}

void write_colored_ply(const std::string& path, const PointSet& points,
                       std::span<const Vec3> colors) {
    if (colors.size() != points.size())
        throw Error(
            fmt::format("{}: {} colours for {} points", path, colors.size(), points.size()));
    PointSet out;
    out.positions = points.positions;
    out.origin = points.origin;
    out.normals = points.normals;
    out.radii = points.radii;
    out.colors.resize(colors.size());
    for (size_t i = 0; i < colors.size(); ++i)
        out.colors[i] = {linear_to_srgb8(colors[i].x) / 255.f, linear_to_srgb8(colors[i].y) / 255.f,
                         linear_to_srgb8(colors[i].z) / 255.f};
    write_ply(path, out);
}

Image render_visible(const VisibilityMap& vm, uint32_t eye, const Camera& cam,
                     const RenderOptions& opt, const VisibleStyle& style) {
    const std::vector<Vec3> colors = visible_colors(vm, eye, style);
    const PointSet pts = points_in_input_order(vm);
    Image img = render_points(pts, colors, cam, opt);
    const Projection pr = project(cam, img.width, img.height, pts.positions[eye]);
    if (pr.depth > 0) {
        const uint8_t cyan[3] = {linear_to_srgb8(style.eye.x), linear_to_srgb8(style.eye.y),
                                 linear_to_srgb8(style.eye.z)};
        draw_dot(img, pr.x, pr.y, std::max(3.f, 0.008f * float(std::min(img.width, img.height))),
                 cyan);
    }
    return img;
}

}  // namespace vmap
