// libFuzzer target: the PLY reader (read_ply), and an ascii body read in pieces of a few bytes
// (detail::read_ply_in_pieces, the parallel path that large bodies take) against the same body
// read line by line: the same model, or the same error message; anything else is a finding.
#include <cstdlib>
#include <string>

#include "fuzz/fuzz_input.h"
#include "io/ply_pieces.h"
#include "vmap/io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    const vmap::fuzz::MemFile file(data, size, "fuzz.ply");
    vmap::fuzz::expect_only_vmap_errors([&] { (void)vmap::read_ply(file.path()); });
    // Around a far origin, as load_point_cloud reads a georeferenced cloud.
    vmap::fuzz::expect_only_vmap_errors([&] {
        (void)vmap::read_ply(file.path(), {{512345.0, 4123456.0, 210.0}});
    });
    vmap::fuzz::expect_only_vmap_errors([&] {
        const std::string lines = vmap::detail::read_outcome(file.path(), 0);
        for (size_t piece : {size_t(1), size_t(13)})
            if (vmap::detail::read_outcome(file.path(), piece) != lines)
                std::abort();  // pieces disagree
    });
    return 0;
}
