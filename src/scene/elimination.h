// Blue noise by sample elimination (src/scene/sampling.cpp): the candidates' same-side
// neighbour lists, and the greedy elimination on them, run in parallel rounds that give exactly
// the one-at-a-time result (tests/sampling_test.cpp checks it against a serial oracle).
#pragma once

#include <cstdint>
#include <vector>

#include "util/huge_array.h"
#include "util/progress.h"
#include "vmap/vec.h"

namespace vmap::detail {

// Each candidate's nearest neighbours (at most kMax, nearest first, ties by index) and the
// weight each adds to its crowding. A list cut at kMax is one-sided: j may list i while i's list
// lacks j. The candidates sit in slots, in an order that keeps near ones near in memory (the
// elimination reads lists at random otherwise); id gives each slot's candidate index, and the
// lists hold slots.
struct NeighbourLists {
    static constexpr int kMax = 32;  // about 14.5 same-side candidates lie within reach at 4x
    std::vector<uint32_t> id;        // slot -> candidate index (a permutation of 0 .. size-1)
    std::vector<uint64_t> start;     // slot s's list at [start[s], start[s + 1]); size + 1 long
    std::vector<uint32_t, UninitAllocator<uint32_t>>
        nb;  // the neighbours' slots (filled in parallel)
    std::vector<float, UninitAllocator<float>>
        weight;  // their weights, (1 - max(d, floor_d) / reach)^8

    uint64_t size() const { return id.size(); }
};

// The neighbours of each candidate within `reach` whose normals lie less than 90 degrees from
// its own (the same side of a surface), weighted with d clamped below at floor_d. The same
// lists for any thread count.
NeighbourLists same_side_neighbours(const std::vector<Vec3>& pos, const std::vector<Vec3>& nrm,
                                    double reach, double floor_d);

// Removes candidates until `keep` remain; returns the kept ones' indices (id), ascending. The
// rule (the serial greedy that this reproduces bit for bit, for any thread count): a
// candidate's crowding W is the sum, in list order and in double, of the weights of the
// still-present candidates of its own list; the present candidate with the largest (W, id)
// goes next, and the crowding of every candidate that lists it is summed again. `progress`
// (may be null) counts the candidates removed, lists.size() - keep in all; it is checked for
// cancellation between rounds.
std::vector<uint64_t> eliminate(const NeighbourLists& lists, uint64_t keep,
                                Progress* progress = nullptr);

}  // namespace vmap::detail
