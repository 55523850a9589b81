// How fast a large file is written in parallel on the GPU machine's disk (issue 15: the lp1
// save writes 1.96 GB at about 2 GB/s with 16 threads of pwrite). Writes MB MiB of a buffer
// to PATH.tmp with THREADS threads taking 8 MiB chunks, by MODE, then fsyncs and renames:
//   pwrite   pwrite each chunk (today's save, without the hashing)
//   pwsfr    pwrite, then sync_file_range(WRITE) on the chunk (today's save exactly)
//   mmap     fallocate, mmap the file shared, memcpy each chunk into the mapping
//   mmapsfr  mmap, then sync_file_range(WRITE) on the chunk
// Prints "MODE: write s, sync s". Usage: write_probe MB PATH THREADS MODE...
#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>
int main(int argc, char** argv) {
    if (argc < 5) return 2;
    const size_t n = size_t(std::atoll(argv[1])) << 20;
    const std::string path = argv[2];
    const int threads = std::atoi(argv[3]);
    constexpr size_t kChunk = size_t(8) << 20;
    std::vector<unsigned char> buf(n);
    for (size_t i = 0; i < n; i += 4096) buf[i] = (unsigned char)(i * 2654435761u >> 24);
    using C = std::chrono::steady_clock;
    for (int m = 4; m < argc; ++m) {
        const std::string mode = argv[m];
        const std::string tmp = path + ".tmp";
        const auto t0 = C::now();
        const int fd = ::open(tmp.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
        if (fd < 0) return 1;
        const bool mm = mode.rfind("mmap", 0) == 0, sfr = mode.find("sfr") != std::string::npos;
        unsigned char* map = nullptr;
        if (mm) {
            if (::posix_fallocate(fd, 0, off_t(n)) != 0) return 1;
            void* p = ::mmap(nullptr, n, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
            if (p == MAP_FAILED) return 1;
            map = static_cast<unsigned char*>(p);
        }
        std::atomic<size_t> next{0};
        std::vector<std::thread> pool;
        for (int t = 0; t < threads; ++t)
            pool.emplace_back([&] {
                for (size_t c; (c = next++) * kChunk < n;) {
                    const size_t lo = c * kChunk, len = std::min(kChunk, n - lo);
                    if (mm) {
                        std::memcpy(map + lo, buf.data() + lo, len);
                    } else {
                        for (size_t got = 0; got < len;) {
                            const ssize_t w = ::pwrite(fd, buf.data() + lo + got, len - got, off_t(lo + got));
                            if (w <= 0) std::abort();
                            got += size_t(w);
                        }
                    }
                    if (sfr) ::sync_file_range(fd, off_t(lo), off_t(len), SYNC_FILE_RANGE_WRITE);
                }
            });
        for (auto& th : pool) th.join();
        if (map) ::munmap(map, n);
        const auto t1 = C::now();
        ::fsync(fd);
        ::close(fd);
        ::rename(tmp.c_str(), path.c_str());
        const auto t2 = C::now();
        std::printf("%s: write %.3f s, sync %.3f s\n", mode.c_str(),
                    std::chrono::duration<double>(t1 - t0).count(),
                    std::chrono::duration<double>(t2 - t1).count());
        std::fflush(stdout);
        ::unlink(path.c_str());
    }
}
