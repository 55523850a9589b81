// libFuzzer target: the .npz reader (read_npz, src/validate/npz.h) and, on the same bytes, its
// .npy parser (parse_npy). The zip entries' CRCs would stop almost every mutated .npy inside an
// archive, so the parser is also handed the raw input: seeds of both kinds are in the corpus.
// An array read back is written out again (npy_bytes), which re-checks its shape and size.
#include <string_view>

#include "fuzz/fuzz_input.h"
#include "validate/npz.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    const vmap::fuzz::MemFile file(data, size, "fuzz.npz");
    vmap::fuzz::expect_only_vmap_errors([&] {
        for (const vmap::detail::NpyArray& a : vmap::detail::read_npz(file.path()))
            (void)vmap::detail::npy_bytes(a);
    });
    vmap::fuzz::expect_only_vmap_errors([&] {
        const std::string_view bytes(reinterpret_cast<const char*>(data), size);
        (void)vmap::detail::npy_bytes(vmap::detail::parse_npy(bytes, "a", "fuzz.npy"));
    });
    return 0;
}
