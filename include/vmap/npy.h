// NumPy's .npy format (version 1.0-3.0), what batch queries need (vmap query --pairs, and any
// program that keeps its pairs in NumPy files): reading an M x 2 array of integer point-id pairs
// and writing a 1-D uint8 array of answers. Errors name the file and the header field.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace vmap {

// Pairs (i0, j0, i1, j1, ...) from the bytes of an .npy file (`path` names it in errors):
// an M x 2 array of any integer dtype (little- or big-endian,
// C or Fortran order). Throws vmap::Error for a bad magic, header, dtype, shape, a truncated
// body, or a negative id or one above 2^32 - 1.
std::vector<uint32_t> read_npy_pairs(std::string_view data, const std::string& path);

// A 1-D array of uint8 ("|u1"), written to a temporary name and renamed.
void write_npy_u8(const std::string& path, std::span<const uint8_t> values);

}  // namespace vmap
