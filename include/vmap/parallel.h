// The library's one parallel loop on the CPU (oneTBB underneath; public for callers that run
// their own loops the same way, the CLI among them): parallel_for(n, f) calls f(i)
// for every i in [0, n), parallel_for(begin, end, f) for every i in [begin, end), and
// parallel_for_range(n, grain, f) calls f(begin, end) on chunks of about `grain` indices (for
// bodies that keep per-chunk state). parallel_reduce_range(n, grain, identity, f, join) folds
// chunks the same way (f(begin, end, acc) returns acc with the chunk added; join(a, b) merges
// two partial results: give it an associative, exact one, integers, for a result that does not
// depend on the chunks), and parallel_sort sorts. Threads: the caller's oneTBB limit
// (BuildParams::threads sets one for a build). The GPU's counterpart, of the same
// shape, is parallel_for_device(n, body) in util/parallel_cuda.cuh.
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_arena.h>

#include <cstddef>
#include <string>
#include <type_traits>

namespace vmap {

template <class Index, class F>
void parallel_for(Index begin, Index end, F&& f) {
    static_assert(std::is_integral_v<Index>);
    if (end <= begin) return;
    tbb::parallel_for(begin, end, [&](Index i) { f(i); });
}

template <class Index, class F>
void parallel_for(Index n, F&& f) {
    parallel_for(Index(0), n, std::forward<F>(f));
}

template <class Index, class F>
void parallel_for_range(Index n, Index grain, F&& f) {
    static_assert(std::is_integral_v<Index>);
    if (n <= 0) return;
    tbb::parallel_for(tbb::blocked_range<Index>(Index(0), n, grain > 0 ? grain : Index(1)),
                      [&](const tbb::blocked_range<Index>& r) { f(r.begin(), r.end()); });
}

template <class Index, class T, class F, class Join>
T parallel_reduce_range(Index n, Index grain, T identity, F&& f, Join&& join) {
    static_assert(std::is_integral_v<Index>);
    if (n <= 0) return identity;
    return tbb::parallel_reduce(
        tbb::blocked_range<Index>(Index(0), n, grain > 0 ? grain : Index(1)), identity,
        [&](const tbb::blocked_range<Index>& r, T acc) { return f(r.begin(), r.end(), acc); },
        join);
}

template <class It, class Less>
void parallel_sort(It first, It last, Less&& less) {
    tbb::parallel_sort(first, last, std::forward<Less>(less));
}

template <class It>
void parallel_sort(It first, It last) {
    tbb::parallel_sort(first, last);
}

// The threads these loops use here, in words: "1 thread", "16 threads" (for "cpu (16 threads)").
inline std::string cpu_threads() {
    const int n = tbb::this_task_arena::max_concurrency();
    return std::to_string(n) + (n == 1 ? " thread" : " threads");
}

}  // namespace vmap
