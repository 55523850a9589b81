// Progress and cancellation for long library calls: the library never prints; it calls back.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>

#include "vmap/error.h"

namespace vmap {

// One report: `done` of `total` units of a stage ("leaf pairs", "bounces", "heights").
struct ProgressInfo {
    const char* stage = "";
    uint64_t done = 0;
    uint64_t total = 0;
    double seconds = 0;           // since the stage began
    double eta_seconds = 0;       // projected time left (0 until something is done)
    const char* backend = "";     // where the work runs, in words ("cpu (2 threads)")
    const char* note = "";        // e.g. why the GPU is not used (backend auto without a GPU)
    double estimate_seconds = 0;  // the library's guess of the whole stage, before it starts
};

// Called at the start of a stage (done == 0), about ten times a second while it runs (possibly
// from a worker thread, never from two at once) and at its end (done == total). Return false to
// cancel: the call then stops early and throws vmap::Cancelled, without calling back again.
using ProgressCallback = std::function<bool(const ProgressInfo&)>;

// Seconds on the steady clock since t0 (how the library times its stages, for callers that time
// theirs the same way).
inline double seconds_since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Thrown when a ProgressCallback asked to stop.
class Cancelled : public Error {
  public:
    explicit Cancelled(const std::string& what) : Error(what) {}
};

}  // namespace vmap
