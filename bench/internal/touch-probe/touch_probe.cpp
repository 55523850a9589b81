// What the first touch of fresh memory costs on a machine (issue 15: the link arrays and the
// coded stream of the lp1 save are gigabytes of fresh memory, written once). Allocates MB MiB as
// allocate_huge does (2 MiB aligned, MADV_HUGEPAGE) or with plain malloc (4 KiB pages), writes
// it with THREADS threads, then writes it again; prints both times and GB/s.
// Usage: touch_probe MB THREADS [small]
#include <sys/mman.h>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <thread>
#include <vector>
int main(int argc, char** argv) {
    if (argc < 3) return 2;
    const size_t n = size_t(std::atoll(argv[1])) << 20;
    const int threads = std::atoi(argv[2]);
    const bool small = argc > 3;
    char* p = nullptr;
    if (small) {
        p = static_cast<char*>(std::malloc(n));
    } else {
        p = static_cast<char*>(std::aligned_alloc(size_t(2) << 20, n));
        madvise(p, n, MADV_HUGEPAGE);
    }
    if (!p) return 1;
    auto pass = [&](int v) {
        const auto t0 = std::chrono::steady_clock::now();
        std::vector<std::thread> pool;
        for (int t = 0; t < threads; ++t)
            pool.emplace_back([&, t] {
                const size_t lo = n / threads * t, hi = t + 1 == threads ? n : n / threads * (t + 1);
                std::memset(p + lo, v, hi - lo);
            });
        for (auto& th : pool) th.join();
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    };
    const double first = pass(1), second = pass(2);
    std::printf("%s %zu MiB, %d threads: first touch %.3f s (%.1f GB/s), again %.3f s (%.1f GB/s)\n",
                small ? "4K pages" : "huge", n >> 20, threads, first, n / first / 1e9, second,
                n / second / 1e9);
    std::free(p);
}
