// LZF decompression for PCD's binary_compressed data (internal to src/io).
#pragma once

#include <cstddef>
#include <cstdint>

namespace vmap::detail {

// LZF (liblzf's format): control bytes below 32 start a run of ctrl + 1 literal bytes; others
// are a back-reference of length (ctrl >> 5) + 2 (a 7 takes one more length byte) to the
// distance ((ctrl & 31) << 8) + next byte + 1 behind. Returns false for data that reads outside
// either buffer or does not fill `out` exactly; never reads or writes out of bounds.
bool lzf_decompress(const uint8_t* in, size_t in_size, uint8_t* out, size_t out_size);

}  // namespace vmap::detail
