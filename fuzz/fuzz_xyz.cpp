// libFuzzer target for the xyz/pts point-list reader: the input bytes as a .xyz file, read with
// read_xyz; a vmap::Error is the expected answer to bad input, anything else (a crash, a sanitizer
// report, another exception) is a bug. Seeds: fuzz/corpus/xyz/.
// vec.h calls isfinite unqualified; <math.h> must come first.
// clang-format off
#include <math.h>
// clang-format on

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>

#include "vmap/error.h"
#include "vmap/io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    static const std::string path = "/tmp/vmap_fuzz_xyz_" + std::to_string(::getpid()) + ".xyz";
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (f == nullptr) return 0;
    std::fwrite(data, 1, size, f);
    std::fclose(f);
    try {
        const vmap::ModelData m = vmap::read_xyz(path);
        (void)m;
    } catch (const vmap::Error&) {
    }
    try {  // read around a far origin, as load_point_cloud reads a georeferenced cloud
        const vmap::ModelData m = vmap::read_xyz(path, {{512345.0, 4123456.0, 210.0}});
        (void)m;
    } catch (const vmap::Error&) {
    }
    return 0;
}
