// Checks a CUDA runtime call; a failure becomes a vmap::Error naming the call and the place.
#pragma once

#include <cuda_runtime.h>

#include <string>

#include "vmap/error.h"

#define VMAP_CUDA_CHECK(call)                                                                    \
    do {                                                                                         \
        cudaError_t err_ = (call);                                                               \
        if (err_ != cudaSuccess)                                                                 \
            throw ::vmap::Error(std::string("CUDA error: ") + #call +                            \
                                " failed: " + cudaGetErrorString(err_) + " (" + __FILE__ + ":" + \
                                std::to_string(__LINE__) + ")");                                 \
    } while (0)
