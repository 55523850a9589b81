// How long a CUDA process takes to end after its work (issue 15: about 0.34 s of the dragon's
// lp4 wall clock lies after the save). Makes the context, allocates MB MiB on the device (and
// as much pinned host memory when PINNED), runs one kernel, prints the time, then ends by MODE:
//   return  the normal end (static destructors, the CUDA runtime's atexit teardown)
//   quick   std::_Exit after fflush (no destructors; the driver cleans up as the process ends)
//   free    cudaFree/cudaFreeHost first, then return
// Usage: exit_probe MB MODE [PINNED]; time it from outside (bench/internal/exit-probe/run.sh).
#include <cuda_runtime.h>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
__global__ void touch(char* p, size_t n) {
    for (size_t i = blockIdx.x * size_t(blockDim.x) + threadIdx.x; i < n; i += size_t(gridDim.x) * blockDim.x)
        p[i] = char(i);
}
static double now() {
    return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}
int main(int argc, char** argv) {
    if (argc < 3) return 2;
    const size_t bytes = size_t(std::atoll(argv[1])) << 20;
    const char* mode = argv[2];
    const bool pinned = argc > 3;
    char *d = nullptr, *h = nullptr;
    if (cudaMalloc(&d, bytes) != cudaSuccess) return 1;
    if (pinned && cudaMallocHost(&h, bytes) != cudaSuccess) return 1;
    touch<<<1024, 256>>>(d, bytes);
    if (pinned) cudaMemcpy(h, d, bytes, cudaMemcpyDeviceToHost);
    cudaDeviceSynchronize();
    std::printf("%.6f done\n", now());
    std::fflush(stdout);
    if (!std::strcmp(mode, "quick")) std::_Exit(0);
    if (!std::strcmp(mode, "free")) {
        cudaFree(d);
        if (h) cudaFreeHost(h);
        std::printf("%.6f freed\n", now());
    }
    return 0;
}
