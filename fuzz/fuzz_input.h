// Shared by the libFuzzer targets (fuzz/fuzz_*.cpp): the readers take paths, so each input is
// handed over as an in-memory file (memfd) named by its /proc/self/fd path, and a reader may
// fail only with vmap::Error. Anything else escaping (another exception type, a crash, a
// sanitizer report) is a finding.
#pragma once

#include <sys/mman.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "vmap/error.h"

namespace vmap::fuzz {

// An in-memory file holding the fuzzer's bytes, open for the target's run.
class MemFile {
  public:
    MemFile(const uint8_t* data, size_t size, const char* name) {
        fd_ = ::memfd_create(name, MFD_CLOEXEC);
        if (fd_ < 0) std::abort();
        for (size_t done = 0; done < size;) {
            const ssize_t n = ::write(fd_, data + done, size - done);
            if (n <= 0) std::abort();
            done += size_t(n);
        }
        path_ = "/proc/self/fd/" + std::to_string(fd_);
    }
    ~MemFile() { ::close(fd_); }
    MemFile(const MemFile&) = delete;
    MemFile& operator=(const MemFile&) = delete;
    const std::string& path() const { return path_; }

  private:
    int fd_ = -1;
    std::string path_;
};

// Runs `f`; a vmap::Error is the expected way to refuse bad input.
template <class F>
void expect_only_vmap_errors(F&& f) {
    try {
        f();
    } catch (const vmap::Error&) {
    }
}

}  // namespace vmap::fuzz
