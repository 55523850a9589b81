// The GPU side of the radiosity solver (src/gi/cuda/gi_cuda.cu): the same three steps as the
// CPU (gi_kernels.h) over device copies of the arrays the host prepared.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "gi/gi_kernels.h"

namespace vmap::detail {

class GiDevice {
  public:
    virtual ~GiDevice() = default;
    virtual std::string name() const = 0;
    // Copies `host` (pointers into host arrays, B holding the starting radiosity) to the device.
    virtual void upload(const GiView& host, uint64_t num_interactions) = 0;
    virtual void set_radiosity(const Vec3* B) = 0;       // all elements, from the host
    virtual void bounce() = 0;                           // gather, point update, pull up
    virtual void download_radiosity(Vec3* B) const = 0;  // all elements, to the host
};

// nullptr with *why set when CUDA is not built in or no device is present.
std::unique_ptr<GiDevice> make_gi_cuda(std::string* why);

}  // namespace vmap::detail
