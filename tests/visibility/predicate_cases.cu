// The predicate cases (predicate_cases.h) in a kernel: one index a case, through the library's
// device loop (util/parallel_cuda.cuh).
#include "predicate_cases.h"

#include <cuda_runtime.h>

#include "util/cuda_check.h"
#include "util/parallel_cuda.cuh"

namespace vmap::test {
namespace {

struct Answer {
    const PredicateCase* cases;
    uint8_t* out;
    __device__ void operator()(uint64_t i) const { out[i] = uint8_t(answer(cases[i])); }
};

}  // namespace

std::vector<uint8_t> answers_on_cuda(std::span<const PredicateCase> cases) {
    std::vector<uint8_t> out(cases.size());
    if (cases.empty()) return out;
    PredicateCase* d_cases = nullptr;
    uint8_t* d_out = nullptr;
    VMAP_CUDA_CHECK(cudaMalloc(&d_cases, cases.size_bytes()));
    VMAP_CUDA_CHECK(cudaMalloc(&d_out, out.size()));
    VMAP_CUDA_CHECK(
        cudaMemcpy(d_cases, cases.data(), cases.size_bytes(), cudaMemcpyHostToDevice));
    detail::parallel_for_device(cases.size(), Answer{d_cases, d_out});
    VMAP_CUDA_CHECK(cudaDeviceSynchronize());
    VMAP_CUDA_CHECK(cudaMemcpy(out.data(), d_out, out.size(), cudaMemcpyDeviceToHost));
    cudaFree(d_cases);
    cudaFree(d_out);
    return out;
}

}  // namespace vmap::test
