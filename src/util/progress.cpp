#include "util/progress.h"

#include <fmt/format.h>
#include <unistd.h>

#include <cstdio>

namespace vmap::detail {

bool stderr_is_terminal() { return isatty(2) == 1; }

Progress::Progress(std::string label, uint64_t total, bool enabled)
    : label_(std::move(label)),
      total_(total),
      enabled_(enabled && stderr_is_terminal()),
      start_(std::chrono::steady_clock::now()),
      last_(start_) {}

Progress::~Progress() {
    if (enabled_) fmt::print(stderr, "\r\033[K");
}

void Progress::update(uint64_t done) {
    if (!enabled_) return;
    const auto now = std::chrono::steady_clock::now();
    if (now - last_ < std::chrono::milliseconds(100) && done < total_) return;
    last_ = now;
    const double s = std::chrono::duration<double>(now - start_).count();
    const double f = total_ ? double(done) / double(total_) : 1.0;
    const double eta = f > 0 ? s / f - s : 0;
    fmt::print(stderr, "\r\033[K{}: {:5.1f}%  {:.1f}s elapsed, ~{:.0f}s left", label_, 100 * f, s,
               eta);
    std::fflush(stderr);
}

}  // namespace vmap::detail
