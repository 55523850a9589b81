// Choosing a reader by file extension.
// vec.h calls isfinite unqualified, which <cmath> alone does not declare globally (libstdc++);
// <math.h> does, so it must come first. Remove once vec.h includes what it uses.
// clang-format off
#include <math.h>
// clang-format on

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <string>

#include "io/atomic_file.h"
#include "vmap/error.h"
#include "vmap/io.h"

namespace vmap {

ModelData read_model(const std::string& path) {
    io::check_input_path(path);  // a FIFO would block the reader, a folder fail obscurely
    std::string ext = std::filesystem::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (ext == ".ply") return read_ply(path);
    if (ext == ".off") return read_off(path);
    if (ext.empty()) {
        throw Error(path + ": unknown model format (no extension; expected .ply or .off)");
    }
    throw Error(path + ": unknown model format '" + ext + "' (expected .ply or .off)");
}

}  // namespace vmap
