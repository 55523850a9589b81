// Reading point clouds and meshes (PLY, OFF, xyz/xyzn/xyzrgb/pts/asc/csv, PCD, OBJ, STL) and
// writing PLY point clouds.
//
// All readers throw vmap::Error with the file name and the element/field at fault for
// malformed, truncated or inconsistent input (bad magic, unknown format, missing x/y/z,
// a vertex index out of range, fewer values than the header promises, NaN or infinite
// coordinates, ...). They never return partial data.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "vmap/mesh.h"

namespace vmap {

// Where a scan was taken from, as a PCD file's VIEWPOINT line gives it: the sensor's position
// and its orientation as a unit quaternion (w, x, y, z), in the file's coordinates.
struct Viewpoint {
    Vec3 origin{0, 0, 0};
    std::array<float, 4> orientation{1, 0, 0, 0};
};

// What a model file held: vertices as a point set (with normals, colours (linear [0,1]) and
// per-point emission when present), and faces when present (polygons fan-triangulated).
struct ModelData {
    PointSet points;
    std::vector<std::array<uint32_t, 3>> triangles;  // empty for a point cloud
    std::optional<Viewpoint> viewpoint;              // PCD files with a VIEWPOINT line
    // What the file held that vmap read but does not use, one short line each ("fields
    // intensity, curvature ignored"), for the tool to print: nothing is dropped silently.
    std::vector<std::string> notes;
    std::vector<Vec3> sensors;  // per-point scanner positions (PLY sensor_x/y/z, vp_x/y/z or
                                // viewpoint_x/y/z), empty when the file has none

    Mesh mesh() const { return Mesh{points.positions, triangles}; }
};

// PLY: ascii, binary_little_endian and binary_big_endian 1.0; element "vertex" with float or
// double (or any scalar type) x,y,z and optional nx,ny,nz (or PCL's normal_x,normal_y,normal_z),
// red/green/blue (or r/g/b, diffuse_red...), radius, emission_r,emission_g,emission_b
// (emitted radiosity, W/m^2 per channel, for `vmap gi`) and sensor_x/y/z (or vp_x/y/z,
// viewpoint_x/y/z); element "face" with a list property "vertex_indices" (or "vertex_index");
// other elements and properties are skipped (and noted).
ModelData read_ply(const std::string& path, const std::array<double, 3>& origin = {});

// OFF (and COFF/NOFF headers): vertex count, face count, edge count; polygons fan-triangulated.
ModelData read_off(const std::string& path);

// ASCII point lists as Open3D and CloudCompare write them (.xyz, .xyzn, .xyzrgb, .pts, .asc,
// .csv): one point a line, values separated by blanks, commas or semicolons; '#' lines are
// comments. An optional first line names the columns ("//X,Y,Z,R,G,B,Nx,Ny,Nz" or "x y z nx ny
// nz"); without it the column count and the extension say what they hold (src/io/xyz.cpp). A
// .pts file may start with its point count. Colours are 0..1 floats or 0..255 integers.
ModelData read_xyz(const std::string& path, const std::array<double, 3>& origin = {});

// PCD (PCL's point cloud format, v0.5-0.7): DATA ascii, binary or binary_compressed (LZF);
// fields in any order: x y z, normal_x normal_y normal_z, rgb/rgba (packed), emission_r/g/b;
// others (curvature, intensity, padding "_") skipped and noted. Points with NaN coordinates
// (PCL's "no measurement" in organised clouds) are left out, with a note. The VIEWPOINT line is
// kept in ModelData::viewpoint.
ModelData read_pcd(const std::string& path, const std::array<double, 3>& origin = {});

// Wavefront OBJ: "v x y z [w] [r g b]", "vn", "f" with polygons of any size in the forms i,
// i/t, i//n and i/t/n, negative (relative) indices; "vt", "l", "p", groups, materials and
// smoothing are skipped. Vertex normals are kept when every vertex has one.
ModelData read_obj(const std::string& path);

// STL, ASCII ("solid ... endsolid") or binary (80-byte header, count, 50-byte facets; told apart
// by the size the count implies). Vertices shared between facets (bit-equal) are merged; a facet
// whose stored normal disagrees with its winding is re-wound to agree with the normal.
ModelData read_stl(const std::string& path);

// Dispatches on the extension (case-insensitive): .ply, .off, .xyz/.xyzn/.xyzrgb/.pts/.asc/.csv,
// .pcd, .obj, .stl; throws for anything else.
//
// `origin`: positions and sensor positions come back relative to this point of the file's
// coordinates (points.origin says so), subtracted in double before the float conversion, so a
// cloud millions of units from its file's zero keeps its precision. The PLY, point-list and PCD
// readers take the file's values in double; OFF, OBJ and STL store floats and are shifted after
// reading (their precision is the file's float).
ModelData read_model(const std::string& path, const std::array<double, 3>& origin = {});

// A point far from where positions are best read: the centre of `points`' bounding box, rounded
// to a multiple of the power of two at or above the box's extent, when the box lies farther from
// zero than 256 extents (float positions out there lose more than 3e-5 of the extent: a
// millimetre in a 30 m room), else nullopt. load_point_cloud reads such a cloud again relative to
// it.
std::optional<std::array<double, 3>> far_origin(const std::vector<Vec3>& positions);
// Moves `points` back to the file's coordinates (positions + origin, in float; origin zero):
// for a cloud that shares a frame with other input (a scene file's clouds and meshes, the
// triangles `vmap validate --cloud` scores it against).
void to_file_frame(PointSet& points);

// Whether `path` ends with `suffix`, ignoring ASCII case (has_extension("A.PLY", ".ply")).
bool has_extension(std::string_view path, std::string_view suffix);

// Whether the file is a mesh (has faces) without reading all of it where the format allows: the
// PLY and OFF headers; an OBJ's first "f" line; every STL. Point-list formats are never meshes.
// Throws like the reader for a file that cannot be opened or has an unknown extension.
bool model_has_faces(const std::string& path);

// Writes a binary little-endian PLY point cloud with x,y,z, nx,ny,nz when present, and
// red,green,blue (uchar) when present, a float "radius" when present, and float
// emission_r,emission_g,emission_b when some point emits, and sensor_x,sensor_y,sensor_z when
// `sensors` gives one per point (a scan's per-point scanner positions, in the points'
// coordinates). Written to a temporary name and renamed, so a failure leaves no half-written file.
void write_ply(const std::string& path, const PointSet& points, bool binary = true,
               const std::vector<Vec3>& sensors = {});

}  // namespace vmap
