// Backend selection: --backend auto|cpu|cuda.
#include "visibility/backend.h"

#include <fmt/format.h>

#include "vmap/error.h"

namespace vmap::detail {

#ifndef VMAP_HAVE_CUDA
std::unique_ptr<Backend> make_cuda_backend(std::string* why, int) {
    if (why) *why = "this vmap was built without CUDA (nvcc was not found at build time)";
    return nullptr;
}
int cuda_device_count() { return 0; }
#endif

std::unique_ptr<Backend> make_backend(const std::string& name, std::string* note, int device) {
    if (name == "cpu") return make_cpu_backend();
    if (name == "auto" || name == "cuda") {
        std::string why;
        if (auto b = make_cuda_backend(&why, device)) return b;
        if (name == "cuda")
            throw Error(fmt::format("backend cuda: {} (backend auto falls back to the CPU)", why));
        if (note) *note = fmt::format("no usable GPU ({}); using the CPU", why);
        return make_cpu_backend();
    }
    throw Error(fmt::format("backend: unknown backend '{}' (expected auto, cpu or cuda)", name));
}

}  // namespace vmap::detail
