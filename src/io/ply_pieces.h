// The PLY reader with its ascii pieces forced (src/io/ply.cpp): for differential tests and the
// fuzz target, which check that a body parsed in pieces reads as it does line by line.
#pragma once

#include <cstddef>
#include <string>

#include "vmap/error.h"
#include "vmap/io.h"

namespace vmap::detail {

// read_ply (no origin), with an ascii body of any size parsed in pieces of about `piece_bytes`
// bytes each (cut after a line end); 0: line by line, whatever the size.
ModelData read_ply_in_pieces(const std::string& path, size_t piece_bytes);

// What read_ply_in_pieces gives, as one string to compare: the model's arrays, byte for byte,
// and its notes; or "error: " and the error's message.
inline std::string read_outcome(const std::string& path, size_t piece_bytes) {
    try {
        const ModelData m = read_ply_in_pieces(path, piece_bytes);
        std::string s;
        auto put = [&](const auto& v) {
            s += std::to_string(v.size()) + ':';
            s.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(v[0]));
        };
        put(m.points.positions), put(m.points.normals), put(m.points.colors), put(m.points.radii);
        put(m.points.emission), put(m.sensors), put(m.triangles);
        for (const std::string& n : m.notes) s += n + '\n';
        return s;
    } catch (const Error& e) {
        return std::string("error: ") + e.what();
    }
}

}  // namespace vmap::detail
