// The scene sampler's time (sample_scene: candidates, neighbour lists, elimination): a scene
// file's samples `runs` times, with the median and spread (min..max) of the seconds and the
// threads used. --out FILE writes the samples' positions (x y z a line, %.9g) for comparing two
// versions' samples point by point.
//   sample_bench SCENE.json [--runs N (default 3)] [--threads T (default: all cores)]
//                [--points N (default: the scene's)] [--out FILE]
#include <fmt/format.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "vmap/error.h"
#include "vmap/options.h"
#include "vmap/progress.h"
#include "vmap/scene.h"

int main(int argc, char** argv) {
    try {
        std::string path, out;
        int runs = 3, threads = 0;
        uint64_t points = 0;
        for (int i = 1; i < argc; ++i) {
            const std::string a = argv[i];
            auto next = [&]() -> std::string {
                if (i + 1 >= argc) throw vmap::Error(a + ": needs a value");
                return argv[++i];
            };
            if (a == "--runs")
                runs = std::atoi(next().c_str());
            else if (a == "--threads")
                threads = std::atoi(next().c_str());
            else if (a == "--points")
                points = std::strtoull(next().c_str(), nullptr, 10);
            else if (a == "--out")
                out = next();
            else if (path.empty())
                path = a;
            else
                throw vmap::Error("unexpected argument " + a);
        }
        if (path.empty() || runs < 1)
            throw vmap::Error(
                "usage: sample_bench SCENE.json [--runs N] "
                "[--threads T] [--points N] [--out FILE]");
        std::unique_ptr<tbb::global_control> limit;
        if (threads > 0)
            limit = std::make_unique<tbb::global_control>(
                tbb::global_control::max_allowed_parallelism, size_t(threads));
        vmap::Scene sc = vmap::load_scene(path);
        if (points) sc.points = points;
        std::vector<double> secs;
        vmap::PointSet ps;
        for (int r = 0; r < runs; ++r) {
            const auto t0 = std::chrono::steady_clock::now();
            ps = vmap::sample_scene(sc);
            secs.push_back(vmap::seconds_since(t0));
        }
        std::vector<double> s = secs;
        std::sort(s.begin(), s.end());
        fmt::print("{}: {} points ({}), {} threads: median {:.3f} s ({:.3f}..{:.3f}) of {} runs\n",
                   path, ps.size(), vmap::name_of(sc.pattern),
                   tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism),
                   s[s.size() / 2], s.front(), s.back(), runs);
        if (!out.empty()) {
            FILE* f = std::fopen(out.c_str(), "w");
            if (!f) throw vmap::Error(out + ": cannot write");
            for (const vmap::Vec3& p : ps.positions)
                fmt::print(f, "{:.9g} {:.9g} {:.9g}\n", p.x, p.y, p.z);
            std::fclose(f);
        }
        return 0;
    } catch (const std::exception& e) {
        fmt::print(stderr, "sample_bench: {}\n", e.what());
        return 1;
    }
}
