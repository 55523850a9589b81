// libFuzzer target: the .npy reader of `vmap query --pairs` (read_npy_pairs, vmap/npy.h).
#include <string_view>

#include "fuzz/fuzz_input.h"
#include "vmap/npy.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    vmap::fuzz::expect_only_vmap_errors([&] {
        (void)vmap::read_npy_pairs({reinterpret_cast<const char*>(data), size}, "fuzz.npy");
    });
    return 0;
}
