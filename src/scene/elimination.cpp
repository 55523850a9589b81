// Sample elimination for blue noise: neighbour lists and the parallel greedy (elimination.h).
#include "scene/elimination.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <memory>
#include <tuple>
#include <utility>

#include "util/splitmix.h"
#include "vmap/parallel.h"

namespace vmap::detail {
namespace {

// A cell key's slot in the hash table (SplitMix64: any good mix will do; the lists do not
// depend on it).
uint64_t cell_hash(uint64_t x) { return splitmix64(x); }

// Chunks of a fixed size (so that the split does not depend on the threads) for parallel
// compactions: chunk c covers [c kChunk, min(n, (c + 1) kChunk)).
constexpr uint64_t kChunk = uint64_t(1) << 14;
uint64_t chunk_end(uint64_t c, uint64_t n) { return std::min(n, (c + 1) * kChunk); }

// Where each chunk's output starts: the sums of count(i) over the chunks before it (chunks + 1
// values, the last the total), counted in parallel.
template <class Count>
std::vector<uint64_t> chunk_starts(uint64_t n, Count count) {
    const uint64_t chunks = (n + kChunk - 1) / kChunk;
    std::vector<uint64_t> start(chunks + 1, 0);
    parallel_for(chunks, [&](uint64_t c) {
        uint64_t k = 0;
        for (uint64_t i = c * kChunk; i < chunk_end(c, n); ++i) k += count(i);
        start[c + 1] = k;
    });
    for (uint64_t c = 0; c < chunks; ++c) start[c + 1] += start[c];
    return start;
}

}  // namespace

NeighbourLists same_side_neighbours(const std::vector<Vec3>& pos, const std::vector<Vec3>& nrm,
                                    double reach, double floor_d) {
    constexpr int kNb = NeighbourLists::kMax;
    const uint64_t M = pos.size();
    NeighbourLists out;
    out.id.resize(M);
    if (M == 0) {
        out.start.assign(1, 0);
        return out;
    }
    const double reach2 = reach * reach;
    // Neighbours from a grid of cells `reach` wide: a candidate's lie in the 27 cells around it.
    // Cells are keyed by their integer coordinates; the candidates sorted by key (then index).
    Vec3 lo = pos[0], hi = pos[0];
    for (const Vec3& p : pos) {
        lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
        hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
    }
    // At least `reach` wide, and at most 2^20 cells an axis (21-bit coordinates in the key).
    const double extent = std::max({double(hi.x - lo.x), double(hi.y - lo.y), double(hi.z - lo.z)});
    const double cell = std::max(reach, extent / double(1 << 20));
    auto cell_of = [&](Vec3 p, int axis) {
        const float v = axis == 0 ? p.x - lo.x : axis == 1 ? p.y - lo.y : p.z - lo.z;
        return int64_t(std::floor(double(v) / cell));
    };
    auto key_of = [](int64_t x, int64_t y, int64_t z) {
        return (uint64_t(x) << 42) | (uint64_t(y) << 21) | uint64_t(z);
    };
    std::vector<std::pair<uint64_t, uint32_t>> by_cell(M);
    parallel_for(M, [&](uint64_t i) {
        by_cell[i] = {key_of(cell_of(pos[i], 0), cell_of(pos[i], 1), cell_of(pos[i], 2)),
                      uint32_t(i)};
    });
    parallel_sort(by_cell.begin(), by_cell.end(), std::less<>());
    std::vector<uint64_t> cell_start;
    // The cells in an open-addressing table (key -> cell), and the candidates' positions and
    // normals in cell order, so that a cell's are read in one run.
    std::vector<Vec3> cpos(M), cnrm(M);
    parallel_for(M, [&](uint64_t k) {
        cpos[k] = pos[by_cell[k].second];
        cnrm[k] = nrm[by_cell[k].second];
    });
    for (uint64_t k = 0; k < M; ++k)
        if (k == 0 || by_cell[k].first != by_cell[k - 1].first) cell_start.push_back(k);
    const size_t cells = cell_start.size();
    cell_start.push_back(M);
    size_t cap = 16;
    while (cap < 2 * cells) cap <<= 1;
    constexpr uint64_t kEmpty = ~0ull;  // no key reaches it (63 bits at most)
    std::vector<uint64_t> table_key(cap, kEmpty);
    std::vector<uint32_t> table_cell(cap);
    for (size_t c = 0; c < cells; ++c) {
        const uint64_t key = by_cell[cell_start[c]].first;
        size_t at = cell_hash(key) & (cap - 1);
        while (table_key[at] != kEmpty) at = (at + 1) & (cap - 1);
        table_key[at] = key;
        table_cell[at] = uint32_t(c);
    }
    auto find_cell = [&](uint64_t key) -> int64_t {
        for (size_t at = cell_hash(key) & (cap - 1); table_key[at] != kEmpty;
             at = (at + 1) & (cap - 1))
            if (table_key[at] == key) return table_cell[at];
        return -1;
    };
    // A cell at a time: its 27 neighbouring cells are looked up once for all its candidates.
    // Slot q (candidate by_cell[q].second) writes its list to a stride of kNb, packed after.
    std::unique_ptr<uint32_t[]> wide_nb(new uint32_t[M * kNb]);
    std::unique_ptr<float[]> wide_weight(new float[M * kNb]);
    std::vector<uint8_t> count(M);
    parallel_for_range<size_t>(cells, 256, [&](size_t cb, size_t ce) {
        // (distance, candidate index, slot): sorted, the nearest first, ties by index.
        std::vector<std::tuple<double, uint32_t, uint32_t>> found;
        std::vector<std::pair<uint64_t, uint64_t>> ranges;
        for (size_t cell_index = cb; cell_index < ce; ++cell_index) {
            const uint64_t first = cell_start[cell_index];
            const Vec3 p0 = cpos[first];
            const int64_t cx = cell_of(p0, 0), cy = cell_of(p0, 1), cz = cell_of(p0, 2);
            ranges.clear();
            for (int64_t dx = -1; dx <= 1; ++dx)
                for (int64_t dy = -1; dy <= 1; ++dy)
                    for (int64_t dz = -1; dz <= 1; ++dz) {
                        if (cx + dx < 0 || cy + dy < 0 || cz + dz < 0) continue;
                        const int64_t c = find_cell(key_of(cx + dx, cy + dy, cz + dz));
                        if (c >= 0) ranges.push_back({cell_start[c], cell_start[c + 1]});
                    }
            for (uint64_t q = first; q < cell_start[cell_index + 1]; ++q) {
                const Vec3 pi = cpos[q], ni = cnrm[q];
                found.clear();
                for (const auto& [kb, ke] : ranges)
                    for (uint64_t k = kb; k < ke; ++k) {
                        if (k == q || !(dot(ni, cnrm[k]) > 0)) continue;
                        const Vec3 d = cpos[k] - pi;
                        const double d2 = double(d.x) * d.x + double(d.y) * d.y + double(d.z) * d.z;
                        if (d2 < reach2)
                            found.push_back({std::sqrt(d2), by_cell[k].second, uint32_t(k)});
                    }
                std::sort(found.begin(), found.end());
                const int n = int(std::min<size_t>(found.size(), kNb));
                for (int c = 0; c < n; ++c) {
                    const double t = 1 - std::max(std::get<0>(found[c]), floor_d) / reach;
                    const double t2 = t * t, t4 = t2 * t2;
                    wide_nb[q * kNb + c] = std::get<2>(found[c]);
                    wide_weight[q * kNb + c] = float(t4 * t4);
                }
                count[q] = uint8_t(n);
            }
        }
    });
    // Packed: the lists' starts by a prefix over chunks, then each chunk's lists copied.
    const std::vector<uint64_t> chunk_start = chunk_starts(M, [&](uint64_t q) { return count[q]; });
    const uint64_t total = chunk_start.back();
    out.start.resize(M + 1);
    out.start[M] = total;
    out.nb.resize(total);
    out.weight.resize(total);
    parallel_for(chunk_start.size() - 1, [&](uint64_t c) {
        uint64_t at = chunk_start[c];
        for (uint64_t q = c * kChunk; q < chunk_end(c, M); ++q) {
            out.start[q] = at;
            out.id[q] = by_cell[q].second;
            std::copy_n(&wide_nb[q * kNb], count[q], out.nb.begin() + int64_t(at));
            std::copy_n(&wide_weight[q * kNb], count[q], out.weight.begin() + int64_t(at));
            at += count[q];
        }
    });
    return out;
}

namespace {

// The state of the elimination: which candidates are gone, each one's crowding, and the
// reverse lists (for each i, the candidates whose lists hold i: those whose crowding changes
// when i goes).
class Eliminator {
  public:
    explicit Eliminator(const NeighbourLists& lists)
        : L_(lists), M_(lists.size()), id_(lists.id.data()) {
        build_reverse_lists();
        gone_.assign(M_, 0);
        touched_.assign(M_, 0);
        W_.resize(M_);
        parallel_for(M_, [&](uint64_t i) { W_[i] = crowding(i); });
    }

    std::vector<uint64_t> run(uint64_t keep, Progress* progress);

  private:
    // The slot of rank r (0: the first to go) among the slots v by `above`, as nth_element
    // would find it but without one thread's pass over all of v (it took 0.1 s of the
    // dragon's sampling on 16 cores): histograms of W's bits, 16 at a time from the top, made
    // in parallel, narrow v to the digit that holds rank r, and nth_element orders the few
    // left. W >= 0, so its bits order as the doubles do.
    uint32_t rank_above(const std::vector<uint32_t>& v, uint64_t r) const;

    // The slots that list slot i, ascending: rev_[rev_start_[i] .. rev_start_[i + 1]).
    void build_reverse_lists() {
        std::vector<uint32_t> n(M_ + 1, 0);
        parallel_for(M_, [&](uint64_t j) {
            for (uint64_t e = L_.start[j]; e < L_.start[j + 1]; ++e)
                std::atomic_ref<uint32_t>(n[L_.nb[e]]).fetch_add(1, std::memory_order_relaxed);
        });
        rev_start_.assign(M_ + 1, 0);
        for (uint64_t i = 0; i < M_; ++i) rev_start_[i + 1] = rev_start_[i] + n[i];
        rev_.resize(rev_start_[M_]);
        parallel_for(M_, [&](uint64_t i) { n[i] = 0; });
        parallel_for(M_, [&](uint64_t j) {
            for (uint64_t e = L_.start[j]; e < L_.start[j + 1]; ++e) {
                const uint32_t i = L_.nb[e];
                const uint32_t at =
                    std::atomic_ref<uint32_t>(n[i]).fetch_add(1, std::memory_order_relaxed);
                rev_[rev_start_[i] + at] = uint32_t(j);
            }
        });
        // The fill order depends on the threads; sorted, the lists do not.
        parallel_for(M_, [&](uint64_t i) {
            std::sort(rev_.begin() + int64_t(rev_start_[i]),
                      rev_.begin() + int64_t(rev_start_[i + 1]));
        });
    }

    // W[i] by its definition: the weights of the present members of i's list, summed in list
    // order. Recomputed rather than decremented, it depends only on which candidates are
    // present, not on the order they went in; and a sum of fewer non-negative terms in the same
    // order is never larger (rounded addition is monotone), so W only falls.
    double crowding(uint64_t i) const {
        double sum = 0;
        for (uint64_t e = L_.start[i]; e < L_.start[i + 1]; ++e)
            if (!gone_[L_.nb[e]]) sum += L_.weight[e];
        return sum;
    }

    // The order of removal: larger crowding first, ties to the larger candidate index (a total
    // order; slots a and b).
    bool above(uint32_t a, uint32_t b) const {
        return W_[a] > W_[b] || (W_[a] == W_[b] && id_[a] > id_[b]);
    }

    // Whether i is above every present candidate of its list and of its reverse list. Such a
    // candidate goes before all of them in the serial greedy (none of their keys can rise above
    // its while it is present, and its own key changes only when a member of its list goes),
    // and removing it earlier changes no other key than theirs: so it can go now.
    bool dominant(uint32_t i) const {
        for (uint64_t e = L_.start[i]; e < L_.start[i + 1]; ++e)
            if (!gone_[L_.nb[e]] && !above(i, L_.nb[e])) return false;
        for (uint64_t k = rev_start_[i]; k < rev_start_[i + 1]; ++k)
            if (!gone_[rev_[k]] && !above(i, rev_[k])) return false;
        return true;
    }

    const NeighbourLists& L_;
    const uint64_t M_;
    const uint32_t* id_;
    std::vector<uint64_t> rev_start_;
    std::vector<uint32_t> rev_;
    std::vector<double> W_;
    std::vector<uint8_t> gone_, touched_;
};

// The entries of v whose flag is set, in v's order; chunks of a fixed size, so that the work
// split does not depend on the threads (the result never does).
std::vector<uint32_t> select(const std::vector<uint32_t>& v, const std::vector<uint8_t>& flag) {
    const uint64_t n = v.size();
    const std::vector<uint64_t> start = chunk_starts(n, [&](uint64_t i) { return flag[i]; });
    std::vector<uint32_t> out(start.back());
    parallel_for(start.size() - 1, [&](uint64_t c) {
        uint64_t at = start[c];
        for (uint64_t i = c * kChunk; i < chunk_end(c, n); ++i)
            if (flag[i]) out[at++] = v[i];
    });
    return out;
}

uint32_t Eliminator::rank_above(const std::vector<uint32_t>& v, uint64_t r) const {
    constexpr int kDigit = 16;
    constexpr uint64_t kBins = uint64_t(1) << kDigit, kHistChunk = uint64_t(1) << 16;
    auto digit = [&](uint32_t a, int shift) {
        return (std::bit_cast<uint64_t>(W_[a]) >> shift) & (kBins - 1);
    };
    std::vector<uint32_t> rest;
    const std::vector<uint32_t>* cur = &v;
    std::vector<uint8_t> flag;
    for (int shift = 64 - kDigit; shift >= 0 && cur->size() > kHistChunk; shift -= kDigit) {
        const uint64_t n = cur->size(), chunks = (n + kHistChunk - 1) / kHistChunk;
        std::vector<uint32_t> hist(chunks * kBins, 0);
        parallel_for(chunks, [&](uint64_t c) {
            uint32_t* h = hist.data() + c * kBins;
            for (uint64_t i = c * kHistChunk; i < std::min(n, (c + 1) * kHistChunk); ++i)
                ++h[digit((*cur)[i], shift)];
        });
        std::vector<uint64_t> total(kBins, 0);
        parallel_for(kBins, [&](uint64_t b) {
            for (uint64_t c = 0; c < chunks; ++c) total[b] += hist[c * kBins + b];
        });
        uint64_t bin = kBins - 1;  // from the largest digit down, to the one holding rank r
        while (total[bin] <= r) r -= total[bin--];
        flag.resize(n);
        parallel_for(n, [&](uint64_t k) { flag[k] = digit((*cur)[k], shift) == bin; });
        rest = select(*cur, flag);
        cur = &rest;
    }
    if (cur == &v) rest = v;
    std::nth_element(rest.begin(), rest.begin() + int64_t(r), rest.end(),
                     [&](uint32_t a, uint32_t b) { return above(a, b); });
    return rest[r];
}

// The serial greedy removes the present candidate of largest key, one at a time; its keys only
// fall (W only falls, and the largest of falling keys cannot rise), so the removal keys never
// increase. In a phase with `to_remove` candidates still to go, let T be the (to_remove+1)-th
// largest present key: exactly to_remove keys lie above T, so the serial greedy's removals
// with keys above T (a candidate's key at its removal is at most its key now) are a prefix of
// at most to_remove of its removals. Rounds then remove every dominant candidate above T at
// once (each is one of that prefix, and removing it first leaves the rest of the serial order
// as it was), until none is left above T; each round removes at least the largest present key.
// Then the next phase, with a new T, until `keep` remain.
std::vector<uint64_t> Eliminator::run(uint64_t keep, Progress* progress) {
    std::vector<uint32_t> live(M_);
    parallel_for(M_, [&](uint64_t i) { live[i] = uint32_t(i); });
    std::vector<uint8_t> flag;
    while (live.size() > keep) {
        const uint64_t to_remove = live.size() - keep;
        // T, and the candidates above it (exactly to_remove, in live's order: ascending).
        const uint32_t t = rank_above(live, to_remove);
        // T is this key, fixed, though W[t] may fall in the phase.
        const double Wt = W_[t];
        const uint32_t idt = id_[t];
        auto above_t = [&](uint32_t a) { return W_[a] > Wt || (W_[a] == Wt && id_[a] > idt); };
        flag.resize(live.size());
        parallel_for(live.size(), [&](size_t k) { flag[k] = above_t(live[k]); });
        std::vector<uint32_t> active = select(live, flag);
        while (!active.empty()) {
            flag.resize(active.size());
            parallel_for(active.size(), [&](size_t k) { flag[k] = dominant(active[k]); });
            const std::vector<uint32_t> removed = select(active, flag);
            parallel_for(removed.size(), [&](size_t k) { gone_[removed[k]] = 1; });
            // The crowding of the candidates that listed them, each summed once (a flag claims
            // it); every sum reads only `gone`, which no longer changes in this round.
            parallel_for(removed.size(), [&](size_t k) {
                const uint32_t r = removed[k];
                for (uint64_t e = rev_start_[r]; e < rev_start_[r + 1]; ++e) {
                    const uint32_t j = rev_[e];
                    if (gone_[j]) continue;
                    if (std::atomic_ref<uint8_t>(touched_[j]).exchange(1) == 0) W_[j] = crowding(j);
                }
            });
            parallel_for(removed.size(), [&](size_t k) {
                const uint32_t r = removed[k];
                for (uint64_t e = rev_start_[r]; e < rev_start_[r + 1]; ++e)
                    std::atomic_ref<uint8_t>(touched_[rev_[e]]).store(0, std::memory_order_relaxed);
            });
            parallel_for(active.size(),
                         [&](size_t k) { flag[k] = !gone_[active[k]] && above_t(active[k]); });
            active = select(active, flag);
            if (progress) {
                progress->add(removed.size());
                progress->throw_if_cancelled();
            }
        }
        flag.resize(live.size());
        parallel_for(live.size(), [&](size_t k) { flag[k] = !gone_[live[k]]; });
        live = select(live, flag);
    }
    std::vector<uint64_t> kept(live.size());
    parallel_for(live.size(), [&](size_t k) { kept[k] = id_[live[k]]; });
    parallel_sort(kept.begin(), kept.end());
    return kept;
}

}  // namespace

std::vector<uint64_t> eliminate(const NeighbourLists& lists, uint64_t keep, Progress* progress) {
    const uint64_t M = lists.size();
    if (keep >= M) {
        std::vector<uint64_t> all(M);
        for (uint64_t i = 0; i < M; ++i) all[i] = i;
        return all;
    }
    if (keep == 0) return {};
    Eliminator e(lists);
    return e.run(keep, progress);
}

}  // namespace vmap::detail
