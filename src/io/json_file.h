// Reading a JSON file (scene files) with errors that name the file and the JSON path.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

namespace vmap::io {

// Parses `path` (comments allowed). Throws vmap::Error naming the file, and the JSON path where
// the text went wrong when it has one: "s.json: sampling.points: number overflow: 1e999 is
// beyond the double range", "s.json: not valid JSON at meshes[0] (line 4, column 9): ...".
// Folders, FIFOs and devices are refused without being opened.
nlohmann::json parse_json_file(const std::string& path);

// The JSON path ("meshes[0].flip_normals") at which parsing `text` fails; empty when it parses
// or fails at the top level.
std::string json_error_path(const std::string& text);

}  // namespace vmap::io
