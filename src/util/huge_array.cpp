#include "util/huge_array.h"

#include <sys/mman.h>

#include <algorithm>
#include <new>

namespace vmap::detail {

void* allocate_huge(size_t bytes) {
    constexpr size_t kHuge = size_t(2) << 20;
    void* p = nullptr;
    if (bytes < 4 * kHuge) {
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
