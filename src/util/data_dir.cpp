// vmap::data_dir(): the scenes and models, found relative to the program, not to the build.
#include <dlfcn.h>
#include <fmt/format.h>

#include <cstdlib>
#include <filesystem>
#include <system_error>
#include <vector>

#include "vmap/error.h"
#include "vmap/version.h"

namespace vmap {
namespace {

namespace fs = std::filesystem;

bool holds_data(const fs::path& d) {
    std::error_code ec;
    return fs::is_regular_file(d / "scenes" / "cornell-bunny.json", ec);
}

// The file of the executable, and of the shared object this function is linked into (the
// executable itself for a static link).
std::vector<fs::path> program_dirs() {
    std::vector<fs::path> dirs;
    std::error_code ec;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    if (!ec) dirs.push_back(exe.parent_path());
    Dl_info info{};
    if (dladdr(reinterpret_cast<void*>(&holds_data), &info) && info.dli_fname) {
        const fs::path so = fs::weakly_canonical(info.dli_fname, ec);
        if (!ec && (dirs.empty() || so.parent_path() != dirs[0])) dirs.push_back(so.parent_path());
    }
    return dirs;
}

}  // namespace

std::string data_dir() {
    if (const char* env = std::getenv("VMAP_DATA_DIR"); env && *env) {
        if (holds_data(env)) return env;
        throw Error(fmt::format(
            "VMAP_DATA_DIR={}: no scenes/cornell-bunny.json there (point it at the folder "
            "holding scenes/ and models/)",
            env));
    }
    std::string looked;
    for (fs::path d : program_dirs()) {
        for (int up = 0; up <= 4 && !d.empty(); ++up, d = d.parent_path()) {
            for (const fs::path& c : {d / "share" / "vmap", d})
                if (holds_data(c)) return c.string();
            looked += (looked.empty() ? "" : ", ") + d.string();
            if (d == d.root_path()) break;
        }
    }
    throw Error(fmt::format(
        "cannot find vmap's data (scenes/cornell-bunny.json) near the program (looked in {} "
        "and their share/vmap); set VMAP_DATA_DIR to the folder holding scenes/",
        looked));
}

}  // namespace vmap
