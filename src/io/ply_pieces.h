// The PLY reader with its ascii pieces forced (src/io/ply.cpp): for differential tests and the
// fuzz target, which check that a body parsed in pieces reads as it does line by line.
#pragma once

#include <cstddef>
#include <string>

#include "vmap/io.h"

namespace vmap::detail {

// read_ply (no origin), with an ascii body of any size parsed in pieces of about `piece_bytes`
// bytes each (cut after a line end); 0: line by line, whatever the size.
ModelData read_ply_in_pieces(const std::string& path, size_t piece_bytes);

}  // namespace vmap::detail
