// The GPU side of the radiosity solver (src/gi/cuda/gi_cuda.cu): the block refinement, the
// three bounce steps and the final gather, with the same bodies as the CPU (gi_hier.h,
// gi_kernels.h) over device copies of the arrays the host prepared.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "gi/gi_hier.h"
#include "gi/gi_kernels.h"
#include "util/huge_array.h"

namespace vmap::detail {

class GiDevice {
  public:
    virtual ~GiDevice() = default;
    virtual std::string name() const = 0;
    // Copies the tree, node geometry, points and links (once; later calls do nothing) and which
    // nodes hold an emitter (per node).
    virtual void upload_tree(const GiTree& host, const uint8_t* emits) = 0;
    // The block refinement of every link (gi_link_blocks), its blocks summed in the CPU's order
    // and turned into the CSR interaction list, kept on the device for the bounces and copied to
    // row/src/coef. check_total(n) is called with the number of interactions before the list is
    // made (it throws to refuse it).
    virtual void refine_blocks(float theta, const std::function<void(uint64_t)>& check_total,
                               HugeVector<uint64_t>& row, HugeVector<uint32_t>& src,
                               HugeVector<float>& coef) = 0;
    // Copies `host` (pointers into host arrays, B holding the starting radiosity) to the device;
    // the interaction list only when refine_blocks did not make it there.
    virtual void upload(const GiView& host, uint64_t num_interactions) = 0;
    virtual void set_radiosity(const Vec3* B) = 0;       // all elements, from the host
    virtual void bounce() = 0;                           // gather, point update, pull up
    virtual void download_radiosity(Vec3* B) const = 0;  // all elements, to the host
    // gi_final_gather_point from the device's radiosity for points[0..n) (all points when
    // !listed), into out[0..n). Needs upload_tree and upload.
    virtual void final_gather(float theta, const uint32_t* points, size_t n, bool listed,
                              Vec3* out) = 0;
};

// nullptr with *why set when CUDA is not built in or no device is present.
std::unique_ptr<GiDevice> make_gi_cuda(std::string* why);

}  // namespace vmap::detail
