// Reading and writing PLY and OFF files.
//
// All readers throw vmap::Error with the file name and the element/field at fault for
// malformed, truncated or inconsistent input (bad magic, unknown format, missing x/y/z,
// a vertex index out of range, fewer values than the header promises, NaN or infinite
// coordinates, ...). They never return partial data.
#pragma once

#include <string>

#include "vmap/mesh.h"

namespace vmap {

// What a PLY or OFF file held: vertices as a point set (with normals "nx ny nz" and colours
// "red green blue" (uchar 0..255 or float 0..1) when present), and faces when present.
struct ModelData {
    PointSet points;
    std::vector<std::array<uint32_t, 3>> triangles;  // empty for a point cloud
    std::vector<Vec3> sensors;  // per-point scanner positions (PLY sensor_x/y/z, vp_x/y/z or
                                // viewpoint_x/y/z), empty when the file has none

    Mesh mesh() const { return Mesh{points.positions, triangles}; }
};

// PLY: ascii, binary_little_endian and binary_big_endian 1.0; element "vertex" with float or
// double (or any scalar type) x,y,z and optional nx,ny,nz, red/green/blue (or r/g/b,
// diffuse_red...), radius, sensor_x/y/z (or vp_x/y/z, viewpoint_x/y/z); element "face" with a list
// property "vertex_indices" (or "vertex_index"); other elements and properties are skipped.
ModelData read_ply(const std::string& path);

// OFF (and COFF/NOFF headers): vertex count, face count, edge count; polygons fan-triangulated.
ModelData read_off(const std::string& path);

// Dispatches on the extension (.ply or .off, case-insensitive); throws for anything else.
ModelData read_model(const std::string& path);

// Writes a binary little-endian PLY point cloud with x,y,z, nx,ny,nz when present, and
// red,green,blue (uchar) when present, plus a float "radius" when present. Written to a
// temporary name and renamed, so a failure leaves no half-written file.
void write_ply(const std::string& path, const PointSet& points, bool binary = true);

}  // namespace vmap
