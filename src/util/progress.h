// A progress line on stderr, shown only when stderr is a terminal.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

namespace vmap::detail {

class Progress {
  public:
    Progress(std::string label, uint64_t total, bool enabled);
    ~Progress();
    void update(uint64_t done);  // redraws at most ~10 times a second

  private:
    std::string label_;
    uint64_t total_;
    bool enabled_;
    std::chrono::steady_clock::time_point start_, last_;
};

bool stderr_is_terminal();

}  // namespace vmap::detail
