// A probe (bench/internal/save-ab/run.sh): a V-map loaded, then saved 7 times; the median.
#include "vmap/vmap.h"
#include <chrono>
#include <cstdio>
#include <algorithm>
#include <vector>
#ifdef OLD
namespace vmap { void save_vmap(const std::string& path, const VisibilityMap& vm); }
#define SAVE(p, m) static_cast<void (*)(const std::string&, const vmap::VisibilityMap&)>(&vmap::save_vmap)(p, m)
#else
#define SAVE(p, m) vmap::save_vmap(p, m)
#endif
using namespace vmap;
int main(int argc, char** argv) {
    VisibilityMap vm = load_vmap(argv[1]);
    std::vector<double> t;
    for (int r = 0; r < 7; ++r) {
        auto a = std::chrono::steady_clock::now();
        SAVE(argv[2], vm);
        t.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - a).count());
    }
    std::sort(t.begin(), t.end());
    std::printf("%s: save median %.3f s [%.3f-%.3f]\n", argv[3], t[3], t[0], t[6]);
}
