// libFuzzer target: the PLY reader (read_ply).
#include "fuzz/fuzz_input.h"
#include "vmap/io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    const vmap::fuzz::MemFile file(data, size, "fuzz.ply");
    vmap::fuzz::expect_only_vmap_errors([&] { (void)vmap::read_ply(file.path()); });
    // Around a far origin, as load_point_cloud reads a georeferenced cloud.
    vmap::fuzz::expect_only_vmap_errors(
        [&] { (void)vmap::read_ply(file.path(), {{512345.0, 4123456.0, 210.0}}); });
    return 0;
}
