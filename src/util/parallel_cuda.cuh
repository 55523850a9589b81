// The library's one element-wise loop on a CUDA GPU, the counterpart of parallel_for in
// vmap/parallel.h: parallel_for_device(n, body) calls body(i) on the device for every i in
// [0, n), i a uint64_t, in a grid-stride loop of kParallelForThreads-thread blocks (one thread
// an index up to kParallelForMaxBlocks blocks, then each thread takes every stride-th index).
// body is a functor with a __device__ operator()(uint64_t) const, copied by value into the
// launch, so it holds device pointers and plain views, not host containers. The launch is
// asynchronous on `stream` (the default stream if none) and checked (a launch error becomes a
// vmap::Error); the caller synchronises. Nothing is launched for n == 0.
//
// For loops whose iterations are independent: the order in which the indices run is not
// defined, so a body that must give bit-identical results writes its own outputs only (every
// caller in src/ does; gi_gpu_test checks the GI's against the CPU bit for bit).
#pragma once

#include <cuda_runtime.h>

#include <algorithm>
#include <cstdint>

#include "util/cuda_check.h"

namespace vmap::detail {

constexpr unsigned kParallelForThreads = 256;
constexpr uint64_t kParallelForMaxBlocks = uint64_t(1) << 20;

template <class Body>
__global__ void __launch_bounds__(kParallelForThreads)
    parallel_for_kernel(uint64_t n, const Body body) {
    const uint64_t stride = uint64_t(gridDim.x) * blockDim.x;
    for (uint64_t i = uint64_t(blockIdx.x) * blockDim.x + threadIdx.x; i < n; i += stride)
        body(i);
}

template <class Body>
void parallel_for_device(uint64_t n, const Body& body, cudaStream_t stream = nullptr) {
    if (n == 0) return;
    const uint64_t blocks =
        std::min((n + kParallelForThreads - 1) / kParallelForThreads, kParallelForMaxBlocks);
    parallel_for_kernel<<<unsigned(blocks), kParallelForThreads, 0, stream>>>(n, body);
    VMAP_CUDA_CHECK(cudaGetLastError());
}

}  // namespace vmap::detail
