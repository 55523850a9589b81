// Median and spread of repeated timings, for the benchmark programs' tables.
#pragma once

#include <algorithm>
#include <cstddef>
#include <vector>

namespace vmap::bench_stats {

struct Stat {
    double median = 0, lo = 0, hi = 0;
    bool done = false;  // false: no runs (the table shows "-")
};

inline Stat stat(std::vector<double> v) {
    if (v.empty()) return {};
    std::sort(v.begin(), v.end());
    const size_t n = v.size();
    return {n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]), v.front(), v.back(), true};
}

}  // namespace vmap::bench_stats
