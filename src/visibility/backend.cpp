// Backend selection (the rule is util/device.h's).
#include "visibility/backend.h"

#include "util/device.h"

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
