// The device probe and the CPU fallback rule (util/device.h).
#include "util/device.h"

#include <fmt/format.h>

#ifdef VMAP_HAVE_CUDA
#include <cuda_runtime.h>
#endif

#include "vmap/error.h"

namespace vmap::detail {

std::optional<std::string> cuda_device(std::string* why) {
#ifdef VMAP_HAVE_CUDA
    int count = 0;
    const cudaError_t err = cudaGetDeviceCount(&count);
    if (err != cudaSuccess || count == 0) {
        if (why)
            *why = err != cudaSuccess
                       ? std::string("no CUDA device (") + cudaGetErrorString(err) + ")"
                       : std::string("no CUDA device found");
        cudaGetLastError();  // clear the sticky error
        return std::nullopt;
    }
    cudaDeviceProp prop{};
    if (cudaGetDeviceProperties(&prop, 0) != cudaSuccess) {
        if (why) *why = "cudaGetDeviceProperties failed";
        cudaGetLastError();
        return std::nullopt;
    }
    return std::string(prop.name);
#else
    if (why) *why = "this vmap was built without CUDA (nvcc was not found at build time)";
    return std::nullopt;
#endif
}

void warm_cuda(int device) noexcept {
#ifdef VMAP_HAVE_CUDA
    int count = 0;
    if (cudaGetDeviceCount(&count) == cudaSuccess && count > 0) {
        const int d = device < 0 ? 0 : device;
        if (d < count && cudaSetDevice(d) == cudaSuccess) cudaFree(nullptr);
    }
    cudaGetLastError();  // nothing sticky is left on this thread
#else
    (void)device;
#endif
}

void fall_back_to_cpu(vmap::Backend requested, const std::string& what, const std::string& why,
                      std::string* note) {
    if (requested == vmap::Backend::kCuda)
        throw Error(fmt::format("{} cuda: {} (backend auto falls back to the CPU)", what, why));
    if (note) *note = fmt::format("no usable GPU ({}); using the CPU", why);
}

}  // namespace vmap::detail
