#include "util/progress.h"

#include <fmt/format.h>
#include <unistd.h>

namespace vmap::detail {

bool stderr_is_terminal() { return isatty(2) == 1; }

Progress::Progress(const char* stage, uint64_t total, const ProgressCallback* callback,
                   std::string backend, std::string note, double estimate_seconds)
    : stage_(stage),
      total_(total),
      cb_(callback && *callback ? callback : nullptr),
      backend_(std::move(backend)),
      note_(std::move(note)),
      estimate_(estimate_seconds),
      start_(std::chrono::steady_clock::now()) {
    report(0, true);
}

void Progress::add(uint64_t units) {
    if (!cb_) return;
    report(done_.fetch_add(units, std::memory_order_relaxed) + units, false);
}

void Progress::set(uint64_t done) {
    if (!cb_) return;
    uint64_t cur = done_.load(std::memory_order_relaxed);
    while (cur < done && !done_.compare_exchange_weak(cur, done)) {
    }
    report(std::max(cur, done), false);
}

void Progress::finish() {
    if (!cb_) return;
    done_.store(total_);
    report(total_, true);
}

void Progress::throw_if_cancelled() const {
    if (cancelled()) throw Cancelled(fmt::format("{}: cancelled by the progress callback", stage_));
}

void Progress::report(uint64_t done, bool force) {
    // Once the callback has said stop, it is not called again: the work winds down to its next
    // throw_if_cancelled() and may report on its way there.
    if (!cb_ || cancelled()) return;
    const auto now = std::chrono::steady_clock::now();
    const int64_t ns = std::chrono::duration_cast<std::chrono::nanoseconds>(now - start_).count();
    int64_t last = last_ns_.load(std::memory_order_relaxed);
    if (!force && ns - last < 100'000'000) return;
    if (!force && !last_ns_.compare_exchange_strong(last, ns)) return;
    std::unique_lock lock(mu_, std::defer_lock);
    if (force)
        lock.lock();
    else if (!lock.try_lock())
        return;
    if (cancelled()) return;
    ProgressInfo info;
    info.stage = stage_;
    info.total = total_;
    info.done = std::min(done, total_);
    info.seconds = double(ns) * 1e-9;
    const double f = total_ ? double(info.done) / double(total_) : 1.0;
    info.eta_seconds = f > 0 ? info.seconds / f - info.seconds : 0;
    info.backend = backend_.c_str();
    info.note = note_.c_str();
    info.estimate_seconds = estimate_;
    if (!(*cb_)(info)) cancelled_.store(true);
}

}  // namespace vmap::detail
