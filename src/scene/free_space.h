// Which side of each surface point is free space: the cue behind the default orientation
// (docs/design.md, "Raw clouds: orientation").
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "vmap/vec.h"

namespace vmap::detail {

enum class SideCue : uint8_t {
    kNone,   // no preference found: the sign comes from the neighbours
    kSpace,  // one side lies in free space, the other in solid (voxel topology)
    kRays,   // both sides free (or unknown): the side that sees surface farther away
};

struct SideVotes {
    std::vector<int8_t> sign;  // +1: the normal as given points to the free side; -1: flip it
    std::vector<SideCue> cue;
    std::string method;  // the free-space verdict, in words
};

// For points with unoriented normals and splat radii (all of one length, radii > 0 somewhere):
// 1. voxelise the points (cell about twice the sample spacing, closed by one cell), flood-fill
//    the empty cells into regions, the one touching the padded border being the outside;
// 2. probe both sides of every point for the region it faces and link the two regions;
// 3. number the regions by nesting depth from the outside (breadth first over those links):
//    regions of one parity are free, the other solid. If some region lies two levels deep, the
//    larger total volume of the odd levels (a room with things in it) or of the even levels
//    beyond the outside (a shell with a cavity) is free; otherwise (a lone object) the outside
//    and the even levels are free;
// 4. where both sides are free or unknown, cast rays into each hemisphere against the points'
//    discs: the side whose rays travel farther before meeting surface is free (a ray that
//    escapes travels without end, unless it leaves the bounding box at once: a room's walls
//    lie on the box and see nothing outside it).
SideVotes vote_sides(const std::vector<Vec3>& pts, const std::vector<Vec3>& normals,
                     const std::vector<float>& radii);

}  // namespace vmap::detail
