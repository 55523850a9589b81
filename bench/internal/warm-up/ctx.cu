#include <cuda_runtime.h>
#include <chrono>
#include <cstdio>
__global__ void k(int* p) { if (p) *p = 1; }
static double now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }
int main() {
    double t0 = now();
    int n = 0; cudaGetDeviceCount(&n);
    double t1 = now();
    cudaDeviceProp pr{}; cudaGetDeviceProperties(&pr, 0);
    double t2 = now();
    cudaSetDevice(0); cudaFree(0);
    double t3 = now();
    int* d; cudaMalloc(&d, 1 << 20);
    double t4 = now();
    k<<<1, 1>>>(d); cudaDeviceSynchronize();
    double t5 = now();
    printf("count %.3f props %.3f context %.3f malloc %.3f first kernel %.3f total %.3f (%s)\n", t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4, t5 - t0, pr.name);
}
