// What this copy of vmap is, and where it finds its data.
#pragma once

#include <string>

namespace vmap {

// The library's version ("0.1.0").
const char* version();
// The git commit it was configured from (short hash, "-dirty" when the tree had changes), or
// "unknown" outside a git checkout. Fixed when CMake configures the build.
const char* commit();
// True when the CUDA backend was compiled in (a device may still be absent at run time).
bool built_with_cuda();

// The folder holding vmap's data (scenes/ and models/), found at run time, in this order: the
// environment variable VMAP_DATA_DIR; then, from the folder of the running executable and from
// the folder of the shared object holding vmap (the Python module), that folder and up to four
// parents, each tried as `D/share/vmap` (an installed tree) and as `D` (a source checkout).
// A candidate counts when it holds scenes/cornell-bunny.json. Throws vmap::Error saying where
// it looked when none does.
std::string data_dir();

}  // namespace vmap
