// The library's named choices, and their names for command lines and files: parse<E>(name,
// what) reads one (throwing vmap::Error "what: unknown value 'x' (expected a, b or c)"),
// name_of(e) gives it back. Every tool parses through these, so the names live in one place.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace vmap {

// Where work runs. Auto: the GPU when one is usable, else the CPU (and says why).
enum class Backend { kAuto, kCpu, kCuda };

// How the predicate finds potential occluders of a segment: a walk of the octree that prunes
// with each node's content box (paper §5.2), or a walk of the grid cells the segment crosses
// (the grid walk of [7], CPU only: visibility/grid_walk.h).
enum class OccluderSearch { kBoxes, kGridWalk };

// How the V-map is built: node pairs decided whole where the bounds allow (nodes), every leaf
// pair walked (leaf-pairs, the oracle), or whichever is faster on the backend that runs (auto).
enum class Construction { kAuto, kNodes, kLeafPairs };

// How GI turns links into interactions (vmap/gi.h): blocks of the refinement, or every link.
enum class GiRefine { kBlocks, kLinks };

// How a scene's surfaces are sampled (vmap/scene.h): independent uniform points, or blue noise
// (uniform candidates thinned by sample elimination, so that no two samples of one surface side
// lie much closer than the spacing).
enum class SamplePattern { kUniform, kBlueNoise };

const char* name_of(Backend);
const char* name_of(OccluderSearch);
const char* name_of(Construction);
const char* name_of(GiRefine);
const char* name_of(SamplePattern);

// Every accepted name of E (first the canonical ones, then accepted old spellings).
template <class E>
std::vector<std::string> names_of();

template <class E>
E parse(std::string_view name, std::string_view what);

}  // namespace vmap
