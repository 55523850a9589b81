// Reading pairs and writing answers in bulk for `vmap query --pairs` (apps/query_cmd.cpp).
#pragma once

#include <cstdint>
#include <cstdio>
#include <span>
#include <string>
#include <vector>

#include "vmap/query.h"

namespace vmap::cli {

// Point-id pairs (i0, j0, i1, j1, ...) from `path` ("-": stdin): an .npy of M x 2 integers
// (recognised by its magic), or text with one pair "I J" (or "I,J") a line, blank lines and
// lines starting with '#' skipped. Throws vmap::Error naming the file and the line.
std::vector<uint32_t> read_pairs(const std::string& path);

// One "I J word" line per answer, formatted in parallel and written in large blocks.
void write_answers(std::FILE* out, std::span<const uint32_t> ids, std::span<const uint8_t> ans,
                   const char* (*word)(uint8_t));

// The visible ids: one a line for one point; for several, one line per point with its ids
// separated by spaces (an empty line for an empty set).
void write_id_lists(std::FILE* out, const VisibleSets& sets, bool one_line_each);

}  // namespace vmap::cli
