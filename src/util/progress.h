// A stage's progress, reported through the caller's ProgressCallback (vmap/progress.h):
// thread-safe counting, at most ~10 reports a second, and the callback's cancellation.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

#include "vmap/progress.h"

namespace vmap::detail {

class Progress {
  public:
    // Reports the start (done 0) at once when `callback` is set; a null callback makes every
    // call a no-op (and never cancels).
    Progress(const char* stage, uint64_t total, const ProgressCallback* callback,
             std::string backend = "", std::string note = "", double estimate_seconds = 0);
    void add(uint64_t units);  // from any thread
    void set(uint64_t done);   // done = max(done, this)
    void finish();             // reports done == total
    // True once the callback returned false; the work then winds down and throw_if_cancelled()
    // throws vmap::Cancelled.
    bool cancelled() const { return cancelled_.load(std::memory_order_relaxed); }
    void throw_if_cancelled() const;

  private:
    void report(uint64_t done, bool force);

    const char* stage_;
    uint64_t total_;
    const ProgressCallback* cb_;
    std::string backend_, note_;
    double estimate_;
    std::chrono::steady_clock::time_point start_;
    std::atomic<uint64_t> done_{0};
    std::atomic<int64_t> last_ns_{0};
    std::atomic<bool> cancelled_{false};
    std::mutex mu_;
};

bool stderr_is_terminal();

}  // namespace vmap::detail
