// The radiosity bounce on a CUDA GPU: the three steps of gi_kernels.h, one thread per element,
// point or node, in the same summation order as the CPU (bit-identical with --fmad=false).
#include <cuda_runtime.h>

#include <optional>
#include <string>

#include "gi/gi_device.h"
#include "util/cuda_check.h"
#include "util/device.h"
#include "vmap/error.h"

namespace vmap::detail {
namespace {

constexpr int kThreads = 256;

__global__ void gather_kernel(GiView v, uint64_t n) {
    const uint64_t e = uint64_t(blockIdx.x) * blockDim.x + threadIdx.x;
    if (e < n) gi_gather(v, e);
}
__global__ void point_kernel(GiView v) {
    const uint64_t i = uint64_t(blockIdx.x) * blockDim.x + threadIdx.x;
    if (i < v.num_points) gi_point_update(v, uint32_t(i));
}
__global__ void pull_kernel(GiView v) {
    const int64_t n = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
    if (n < v.num_nodes) gi_pull_up(v, int32_t(n));
}

unsigned blocks(uint64_t n) { return unsigned((n + kThreads - 1) / kThreads); }

template <class T>
T* upload_array(const T* h, uint64_t n, std::vector<void*>& owned) {
    T* d = nullptr;
    VMAP_CUDA_CHECK(cudaMalloc(&d, sizeof(T) * (n ? n : 1)));
    owned.push_back(d);
    if (n) VMAP_CUDA_CHECK(cudaMemcpy(d, h, sizeof(T) * n, cudaMemcpyHostToDevice));
    return d;
}

class CudaGi final : public GiDevice {
  public:
    explicit CudaGi(std::string name) : name_(std::move(name)) {}
    ~CudaGi() override {
        for (void* p : owned_) cudaFree(p);
    }
    std::string name() const override { return name_; }

    void upload(const GiView& h, uint64_t num_interactions) override {
        const uint64_t N = uint64_t(h.num_nodes), P = h.num_points, E = N + P;
        d_ = h;
        d_.row = upload_array(h.row, E + 1, owned_);
        d_.src = upload_array(h.src, num_interactions, owned_);
        d_.coef = upload_array(h.coef, num_interactions, owned_);
        d_.emission = upload_array(h.emission, P, owned_);
        d_.albedo = upload_array(h.albedo, P, owned_);
        d_.area = upload_array(h.area, P, owned_);
        d_.point_leaf = upload_array(h.point_leaf, P, owned_);
        d_.parent = upload_array(h.parent, N, owned_);
        d_.point_begin = upload_array(h.point_begin, N, owned_);
        d_.point_end = upload_array(h.point_end, N, owned_);
        d_.inv_area = upload_array(h.inv_area, N, owned_);
        d_.B = upload_array(h.B, E, owned_);
        d_.G = upload_array(h.G, E, owned_);
        elements_ = E;
    }
    void set_radiosity(const Vec3* B) override {
        VMAP_CUDA_CHECK(cudaMemcpy(d_.B, B, sizeof(Vec3) * elements_, cudaMemcpyHostToDevice));
    }
    void bounce() override {
        gather_kernel<<<blocks(elements_), kThreads>>>(d_, elements_);
        VMAP_CUDA_CHECK(cudaGetLastError());
        point_kernel<<<blocks(d_.num_points), kThreads>>>(d_);
        VMAP_CUDA_CHECK(cudaGetLastError());
        pull_kernel<<<blocks(uint64_t(d_.num_nodes)), kThreads>>>(d_);
        VMAP_CUDA_CHECK(cudaGetLastError());
        VMAP_CUDA_CHECK(cudaDeviceSynchronize());
    }
    void download_radiosity(Vec3* B) const override {
        VMAP_CUDA_CHECK(cudaMemcpy(B, d_.B, sizeof(Vec3) * elements_, cudaMemcpyDeviceToHost));
    }

  private:
    std::string name_;
    GiView d_;
    uint64_t elements_ = 0;
    std::vector<void*> owned_;
};

}  // namespace

std::unique_ptr<GiDevice> make_gi_cuda(std::string* why) {
    const std::optional<std::string> name = cuda_device(why);
    if (!name) return nullptr;
    return std::make_unique<CudaGi>("cuda (" + *name + ")");
}

}  // namespace vmap::detail
