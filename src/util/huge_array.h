#pragma once
// Large scratch arrays that page in as transparent huge pages from 1 GiB on (huge_array.cpp says
// why not below): the GI refinement and the V-map's link targets fill gigabytes once on large
// scenes, where 4 KiB pages cost a page fault every few writes. Uninitialised: the caller writes
// every element before reading it.

#include <cstddef>
#include <cstdlib>
#include <memory>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

namespace vmap::detail {

struct FreeDeleter {
    void operator()(void* p) const { std::free(p); }
};

// `bytes` of memory, released with std::free: 2 MiB aligned and advised as huge pages from
// 1 GiB (only advice: without transparent huge pages the pages stay small). Throws
// std::bad_alloc.
void* allocate_huge(size_t bytes);

template <class T>
using HugeArray = std::unique_ptr<T[], FreeDeleter>;

template <class T>
HugeArray<T> make_huge_array(size_t n) {
    static_assert(std::is_trivially_default_constructible_v<T> &&
                  std::is_trivially_destructible_v<T>);
    return HugeArray<T>(static_cast<T*>(allocate_huge(n * sizeof(T))));
}

// construct() default-initialises, so a std::vector's resize leaves new elements uninitialised
// (nothing for trivial types), for arrays the caller fills completely (in parallel: a zero-fill
// first is one thread touching every page); construction with a value (assign(n, 0),
// push_back) is as usual.
template <class T>
struct DefaultInit {
    using value_type = T;
    template <class U>
    void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
        ::new (static_cast<void*>(p)) U;
    }
    template <class U, class... Args>
    void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
};

// Over allocate_huge (huge pages when large).
template <class T>
struct HugeAllocator : DefaultInit<T> {
    HugeAllocator() = default;
    template <class U>
    HugeAllocator(const HugeAllocator<U>&) noexcept {}
    T* allocate(size_t n) { return static_cast<T*>(allocate_huge(n * sizeof(T))); }
    void deallocate(T* p, size_t) noexcept { std::free(p); }
    template <class U>
    bool operator==(const HugeAllocator<U>&) const noexcept {
        return true;
    }
};

// Over the standard allocator (small pages).
template <class T>
struct UninitAllocator : DefaultInit<T> {
    UninitAllocator() = default;
    template <class U>
    UninitAllocator(const UninitAllocator<U>&) noexcept {}
    T* allocate(size_t n) { return std::allocator<T>().allocate(n); }
    void deallocate(T* p, size_t n) noexcept { std::allocator<T>().deallocate(p, n); }
    template <class U>
    bool operator==(const UninitAllocator<U>&) const noexcept {
        return true;
    }
};

template <class T>
using HugeVector = std::vector<T, HugeAllocator<T>>;

}  // namespace vmap::detail
