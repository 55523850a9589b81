// Internals of the .vmap format shared with its tests.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "vmap/vmap.h"

namespace vmap::detail {

// The payload checksum stored in the header (see vmap_file.cpp).
uint64_t payload_hash(const uint8_t* p, size_t n);

// One .vmap file, never a shard index (load_vmap reads either): the base of a sharded map is
// read with this, so an index naming an index as its base is an error, not a recursion.
VisibilityMap load_vmap_file(const std::string& path);

}  // namespace vmap::detail
