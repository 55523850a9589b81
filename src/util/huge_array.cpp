#include "util/huge_array.h"

#include <sys/mman.h>

#include <algorithm>
#include <new>

namespace vmap::detail {

// Huge pages from 1 GiB on. Measured by whole commands (docs/results.md, "Huge pages from
// 1 GiB"): on the GPU machine they first-touch 4 GB 0.1 s faster, but builds of the dragon were
// no faster either way; on a 2-core virtual machine the default scene's build (200 MB of link
// ends) took 0.3 s longer with them (its hypervisor zeroes a 2 MiB page slowly and unevenly). Below
// 1 GiB the gain is at most about 25 ms on either machine, so small arrays take plain pages.
void* allocate_huge(size_t bytes) {
    constexpr size_t kHuge = size_t(2) << 20;
    constexpr size_t kHugeFrom = size_t(1) << 30;
    void* p = nullptr;
    if (bytes < kHugeFrom) {
        p = std::malloc(std::max<size_t>(bytes, 1));
    } else {
        const size_t size = (bytes + kHuge - 1) / kHuge * kHuge;
        p = std::aligned_alloc(kHuge, size);
        if (p) madvise(p, size, MADV_HUGEPAGE);
    }
    if (!p) throw std::bad_alloc();
    return p;
}

}  // namespace vmap::detail
