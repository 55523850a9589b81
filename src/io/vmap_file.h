// Internals of the .vmap format shared with its tests.
#pragma once

#include <cstddef>
#include <cstdint>

namespace vmap::detail {

// The payload checksum stored in the header (see vmap_file.cpp).
uint64_t payload_hash(const uint8_t* p, size_t n);

}  // namespace vmap::detail
