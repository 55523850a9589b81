// Backend selection (the rule is util/device.h's), and the backends' two public entry points
// for benchmarks (vmap/visibility_map.h).
#include "visibility/backend.h"

#include <algorithm>
#include <chrono>
#include <random>
#include <vector>

#include "util/device.h"
#include "vmap/visibility_map.h"

namespace vmap::detail {

#ifndef VMAP_HAVE_CUDA
std::unique_ptr<Backend> make_cuda_backend(std::string* why, int) {
    if (why) *why = "this vmap was built without CUDA (nvcc was not found at build time)";
    return nullptr;
}
int cuda_device_count() { return 0; }
#endif

std::unique_ptr<Backend> make_backend(vmap::Backend requested, std::string* note, int device) {
    if (requested == vmap::Backend::kCpu) return make_cpu_backend();
    std::string why;
    if (auto b = make_cuda_backend(&why, device)) return b;
    fall_back_to_cpu(requested, "backend", why, note);
    return make_cpu_backend();
}

}  // namespace vmap::detail

namespace vmap {

std::string cuda_backend_name(std::string* why) {
    const auto b = detail::make_cuda_backend(why);
    return b ? b->name() : std::string();
}

double sampled_cpu_pair_rate(const Octree& tree, const VisibilityParams& vp, uint64_t samples) {
    const int32_t L = tree.num_leaves();
    if (L < 64) return 1e9;
    std::mt19937_64 rng(12345);
    std::uniform_int_distribution<int32_t> pick(0, L - 40);
    std::vector<detail::PairJob> jobs;
    uint64_t pairs = 0, words = 0;
    while (pairs < samples) {
        int32_t a = pick(rng), b = pick(rng);
        if (a > b) std::swap(a, b);
        if (b - a < 8) continue;
        detail::PairJob j;
        j.row0 = a, j.rows = 8, j.col0 = b, j.cols = std::min(32, L - b), j.word_offset = words;
        words += detail::job_words(j);
        pairs += uint64_t(j.rows) * j.cols;
        jobs.push_back(j);
    }
    auto cpu = detail::make_cpu_backend();
    cpu->prepare(tree, vp, words);
    WorkCounters wc;
    const auto t0 = std::chrono::steady_clock::now();
    cpu->submit(jobs, words, 0);
    cpu->wait(0, wc);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return double(pairs) / s;
}

}  // namespace vmap
