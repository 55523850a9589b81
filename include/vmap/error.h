// The one exception type vmap throws at its API boundary.
//
// Messages name the file (or option) and the field that was wrong, e.g.
// "bunny.ply: vertex 12: expected 3 floats, found 2". The CLI prints what() on one line and
// exits non-zero.
#pragma once

#include <stdexcept>
#include <string>

namespace vmap {

class Error : public std::runtime_error {
  public:
    explicit Error(const std::string& what) : std::runtime_error(what) {}
};

}  // namespace vmap
