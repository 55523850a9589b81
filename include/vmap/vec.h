// Small 3-vector of floats, usable on the host and (under nvcc) on the device.
//
// Shared host/device code marks functions VMAP_HD. Nothing here allocates or throws.
// Arithmetic is written out plainly; the build turns off floating-point contraction
// (-ffp-contract=off on the host, --fmad=false on the device) so that both give bit-identical
// results for the same expression.
#pragma once

#if defined(__CUDACC__)
#define VMAP_HD __host__ __device__ __forceinline__
#else
#define VMAP_HD inline
#endif

#include <cmath>

namespace vmap {

struct Vec3 {
    float x = 0, y = 0, z = 0;
};

VMAP_HD Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
VMAP_HD Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
VMAP_HD Vec3 operator-(Vec3 a) { return {-a.x, -a.y, -a.z}; }
VMAP_HD Vec3 operator*(Vec3 a, float s) { return {a.x * s, a.y * s, a.z * s}; }
VMAP_HD Vec3 operator*(float s, Vec3 a) { return {a.x * s, a.y * s, a.z * s}; }
VMAP_HD Vec3 operator/(Vec3 a, float s) { return {a.x / s, a.y / s, a.z / s}; }
VMAP_HD Vec3& operator+=(Vec3& a, Vec3 b) {
    a.x += b.x;
    a.y += b.y;
    a.z += b.z;
    return a;
}
VMAP_HD bool operator==(Vec3 a, Vec3 b) { return a.x == b.x && a.y == b.y && a.z == b.z; }
VMAP_HD float dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
VMAP_HD Vec3 cross(Vec3 a, Vec3 b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
VMAP_HD float length2(Vec3 a) { return dot(a, a); }
VMAP_HD float length(Vec3 a) { return sqrtf(dot(a, a)); }
VMAP_HD bool is_finite(Vec3 a) {
#if defined(__CUDA_ARCH__)
    return isfinite(a.x) && isfinite(a.y) && isfinite(a.z);
#else
    return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
#endif
}

}  // namespace vmap
