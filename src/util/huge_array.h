#pragma once
// Large scratch arrays that page in as transparent huge pages: the GI refinement and the V-map's
// link targets fill hundreds of megabytes once, where 4 KiB pages cost a page fault every few
// writes (on a virtual machine most of the time goes there). Uninitialised: the caller writes
// every element before reading it.

#include <cstddef>
#include <cstdlib>
#include <memory>
#include <type_traits>

namespace vmap::detail {

struct FreeDeleter {
    void operator()(void* p) const { std::free(p); }
};

// `bytes` of memory, released with std::free: 2 MiB aligned and advised as huge pages when
// large (only advice: without transparent huge pages the pages stay small). Throws
// std::bad_alloc.
void* allocate_huge(size_t bytes);

template <class T>
using HugeArray = std::unique_ptr<T[], FreeDeleter>;

template <class T>
HugeArray<T> make_huge_array(size_t n) {
    static_assert(std::is_trivially_default_constructible_v<T> && std::is_trivially_destructible_v<T>);
    return HugeArray<T>(static_cast<T*>(allocate_huge(n * sizeof(T))));
}

}  // namespace vmap::detail
