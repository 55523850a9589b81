// Where the input of `vmap build SCENE` goes, at a given thread count: the scene read, the
// sampling's stages (from the instrumented sampling.cpp and elimination.cpp), the build's input
// checks (noise, normal consistency). Usage: input_probe SCENE THREADS
#include "vmap/vmap.h"
#include "vmap/scene.h"
#include "vmap/normals.h"
#include <tbb/global_control.h>
#include <chrono>
#include <cstdio>
#include <cstdlib>
using namespace vmap;
int main(int argc, char** argv) {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, std::atoi(argv[2]));
    auto d = [](auto a, auto b) { return std::chrono::duration<double>(b - a).count(); };
    for (int r = 0; r < 2; ++r) {
        std::fprintf(stderr, "threads %s run %d\n", argv[2], r);
        auto t0 = std::chrono::steady_clock::now();
        Scene sc = load_scene(argv[1]);
        auto t1 = std::chrono::steady_clock::now();
        PointSet ps = sample_scene(sc);
        auto t2 = std::chrono::steady_clock::now();
        const double sigma = estimate_surface_noise(ps).sigma;
        auto t3 = std::chrono::steady_clock::now();
        const double inc = normal_inconsistency(ps);
        auto t4 = std::chrono::steady_clock::now();
        std::fprintf(stderr, "threads %s: read %.3f s, sampled %.3f s, noise %.3f s (%g), consistency %.3f s (%g)\n",
                     argv[2], d(t0, t1), d(t1, t2), d(t2, t3), sigma, d(t3, t4), inc);
    }
}
