// Plain containers for what vmap reads: triangle meshes and point sets.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "vmap/vec.h"

namespace vmap {

// A triangle mesh. Polygons with more than three corners are fan-triangulated on reading.
struct Mesh {
    std::vector<Vec3> vertices;
    std::vector<std::array<uint32_t, 3>> triangles;
};

// A point set: positions and, each optional but either empty or of the same length,
// normals (unit length), colours/albedo (linear RGB in [0,1]), splat radii (scene units) and
// emission.
struct PointSet {
    std::vector<Vec3> positions;
    std::vector<Vec3> normals;
    std::vector<Vec3> colors;
    std::vector<float> radii;
    std::vector<Vec3> emission;  // emitted radiosity (W/m^2 per channel) for lights; optional
    // Where the positions' zero lies in the coordinates they were read in: a cloud far from its
    // file's origin (a georeferenced scan, millions of units out) is read relative to a point
    // near its centre, since float positions out there would lose the millimetres
    // (load_point_cloud). Zero for everything else; write_ply adds it back.
    std::array<double, 3> origin{0, 0, 0};

    size_t size() const { return positions.size(); }
    bool has_normals() const { return !normals.empty(); }
    bool has_colors() const { return !colors.empty(); }
    // Whether the positions are relative to an origin other than the file's zero.
    bool has_origin() const { return origin != std::array<double, 3>{0, 0, 0}; }
    bool has_radii() const { return !radii.empty(); }
};

}  // namespace vmap
