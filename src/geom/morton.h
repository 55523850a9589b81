// Morton (Z-order) codes, shared by the octree builder and the normal estimator's point order.
#pragma once

#include <cstdint>

namespace vmap::detail {

// Spreads the low 21 bits of v so that bit i lands at bit 3i (two zero bits follow each).
// Or-ing three spread coordinates, shifted by 0, 1 and 2, interleaves them into a 63-bit code.
inline uint64_t spread_bits(uint64_t v) {
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffULL;
    v = (v | v << 16) & 0x1f0000ff0000ffULL;
    v = (v | v << 8) & 0x100f00f00f00f00fULL;
    v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
    v = (v | v << 2) & 0x1249249249249249ULL;
    return v;
}

}  // namespace vmap::detail
