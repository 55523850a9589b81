// SplitMix64 (Steele, Lea and Flood, "Fast splittable pseudorandom number generators", 2014):
// the counter-based mix behind the project's seeded draws and hashes. splitmix64(x) is output x
// of the stream that starts at 0, so a draw depends only on (seed, index), whatever the threads.
#pragma once

#include <cstdint>

namespace vmap::detail {

inline constexpr uint64_t kSplitMixGamma = 0x9e3779b97f4a7c15ULL;  // the golden ratio, 64 bits

// The output function alone.
constexpr uint64_t splitmix64_finalize(uint64_t x) {
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    return x ^ (x >> 31);
}

constexpr uint64_t splitmix64(uint64_t x) { return splitmix64_finalize(x + kSplitMixGamma); }

}  // namespace vmap::detail
