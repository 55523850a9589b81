// The library's write access to a VisibilityMap: the builder, the .vmap reader and the direct
// (no-links) predictor of validation fill one; users only read it.
#pragma once

#include <cstdint>
#include <type_traits>
#include <utility>
#include <vector>

#include "vmap/visibility_map.h"

namespace vmap::detail {

struct MapAccess {
    // Every part of the map, writable (field names as VisibilityMap's accessors).
    static auto& data(VisibilityMap& vm) { return vm.d_; }
};

using MapData = std::remove_reference_t<decltype(MapAccess::data(std::declval<VisibilityMap&>()))>;

// Sizes the link targets to n, uninitialised (the caller writes every slot), and returns them.
// Large ones are advised as transparent huge pages (src/vmap/links.cpp).
int32_t* allocate_link_targets(MapData& d, size_t n);

// Sets the inverse permutation from d.order.
inline void set_inverse(MapData& d) {
    d.inverse.resize(d.order.size());
    for (uint32_t k = 0; k < d.order.size(); ++k) d.inverse[d.order[k]] = k;
}

}  // namespace vmap::detail

namespace vmap {

// Sets the links from a list of unordered node pairs (each once): sorts into both-direction
// compact arrays (src/vmap/build.cpp). For tests and tools that make maps by hand.
void set_links(VisibilityMap& vm, std::vector<std::pair<int32_t, int32_t>> pairs);

}  // namespace vmap
