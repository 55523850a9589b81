// Which side of each surface point is free space: the cue behind the default orientation
// (docs/design.md, "Raw clouds: orientation").
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "vmap/vec.h"

namespace vmap::detail {

enum class SideCue : uint8_t {
    kNone,   // no preference found: the sign comes from the neighbours
    kSpace,  // one side lies in free space, the other in solid (voxel topology)
    kRays,   // both sides free (or unknown): the side that sees surface farther away
    kShape,  // an open sheet that wraps around something: the side away from what it wraps
             // (set by the caller: see SideVotes::open)
    kView,   // the side that where the scanner stood sees (SideVotes::scanners, ::view)
};

struct SideVotes {
    std::vector<int8_t> sign;  // +1: the normal as given points to the free side; -1: flip it
    std::vector<SideCue> cue;
    // How sure each vote is, for weighing votes against each other: 2 for kSpace; for kRays the
    // depth contrast (far - near) / (far + near) of the two sides' mean ray travel, in (0, 1];
    // for kShape how squarely the point faces away from its sheet's centroid, in [0, 1] (in a
    // scan of shells, that added to the rays' signed weight: in [0, 2]).
    std::vector<float> weight;
    // Points of an open sheet inside the scene: both sides free by the voxels, and neither side
    // the bounding box's face (a room's walls, floor and ceiling lie on it): 1, or 2 where the
    // first disc along the normal on either side lies within the voxel probe's reach (the other
    // face of a part thinner than that reach, which the probe walked through; or a crease); 0
    // for every other point. Their votes are the rays'; the caller, which has the neighbour
    // graph, may replace them by the sheet's shape (SideCue::kShape).
    std::vector<uint8_t> open;
    // The points' spacing spreads as a scanner's does (kScanSpread in free_space.cpp) and the
    // noise lets it be read (the scanners were searched for by it): a scan, whose shadows open
    // the surfaces of closed objects (SideVotes::open on a closed shell).
    bool scanned = false;
    // Space verdicts that contradicted the surface stacked in front of them and that the rays
    // turned (free_space.cpp, stacked_verdicts: the inner wall of a thin hollow shell).
    size_t stacked = 0;
    std::string method;  // the free-space verdict, in words
    // Where the scanner stood, as far as the points tell (step 7 below), in the cloud's
    // coordinates; none unless the cloud is a scan from inside a room.
    std::optional<Vec3> view;
    // Where the scanners stood by the points' spacing (step 6 below), in the cloud's
    // coordinates; empty unless the cloud is a scan whose spacing tells.
    std::vector<Vec3> scanners;
};

// For points with unoriented normals and splat radii (all of one length, radii > 0 somewhere),
// in the frame of the two most common normal axes (a room's floor and walls):
// 1. voxelise the points' discs (cell = one sample spacing; each disc marks the cells its plane
//    cuts), flood-fill the empty cells into regions, the one touching the padded border being
//    the outside;
// 2. probe both sides of every point for the region it faces and link the two regions;
// 3. number the regions by nesting depth from the outside (breadth first over those links):
//    regions of one parity are free, the other solid. If regions lie two deep, depth 1 is free
//    when its volume per face point is larger than depth 2's (a room's air around things; else
//    a shell around a cavity); otherwise (a lone object, an open room) the outside is free;
// 4. a point with one side free and the other solid takes the free side (also free against
//    occupied cells, unless the free side is the bounding box's face, and solid against
//    occupied cells: a narrow gap), unless the free side is only the padding beyond a room's
//    open-air wall (a box face whose points are mostly free on both sides): nothing was
//    scanned there, as behind a wall a few millimetres behind an object;
// 5. otherwise cast rays into each hemisphere against the points' discs: the side whose rays
//    travel clearly farther before meeting surface is free (a ray that escapes travels without
//    end, unless it leaves the bounding box at once: a room's walls lie on the box and see
//    nothing outside it). No surface seen, or no clear margin: no vote;
// 6. in a scan (its spacing spread): where its scanners stood, from the spacing an equal-angle
//    scanner gives its points (its splat radius grows with the range and with the slant, and
//    shrinks toward the poles of its turning axis): places from which the points' spacing
//    follows that law. A point that a found scanner sees squarely, and no other found scanner
//    sees from its other side, takes that side, unless the voxels decided it (4);
// 7. in a scan from inside a room (its spacing spread over a factor of several, as a scanner's
//    range makes it; walls on three faces or more): the free place that sees the most points,
//    where the scanner stood. A point that it sees squarely, and whose tangent plane leaves every
//    place that sees about as many on that same side, takes that side, unless the voxels
//    decided it (4) or the scanners found by spacing did (6): the side of a sheet scanned from
//    one side (a table top, the cap of an object) that the shadows and the shape cannot tell.
// `noise`: the points' scatter off their surfaces (estimate_surface_noise's sigma; 0 for exact
// samples): a noisy wall's points lie up to a few sigma inside the bounding box's face.
SideVotes vote_sides(const std::vector<Vec3>& pts, const std::vector<Vec3>& normals,
                     const std::vector<float>& radii, float noise = 0);

}  // namespace vmap::detail
