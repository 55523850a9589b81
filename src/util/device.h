// Where work runs: the one probe of the CUDA device and the one rule that turns a requested
// Backend into the GPU or the CPU (the V-map build and GI both choose through it).
#pragma once

#include <optional>
#include <string>

#include "vmap/options.h"

namespace vmap::detail {

// The name of CUDA device 0 when one is usable; otherwise nothing, with the reason in *why
// (no CUDA in this build, no device, the driver's error).
std::optional<std::string> cuda_device(std::string* why);

// Called when the GPU path is not available for `requested` (why: the reason). Backend cuda:
// throws vmap::Error "<what> cuda: <why> (backend auto falls back to the CPU)"; auto: sets
// *note to "no usable GPU (<why>); using the CPU", and the caller runs on the CPU.
void fall_back_to_cpu(vmap::Backend requested, const std::string& what, const std::string& why,
                      std::string* note);

// Makes CUDA device `device`'s primary context (-1: device 0) now, where there is one: a
// process's first CUDA call takes a few tenths of a second (the driver, the context), which a
// thread calling this while the host reads its input takes off the build. Errors are left for
// the build to report (they stay on this thread); does nothing in a build without CUDA.
void warm_cuda(int device) noexcept;

}  // namespace vmap::detail
