// The V-map build across MPI processes (vmap/mpi.h).
#include "vmap/mpi.h"

#include <cstdlib>

#include "vmap/error.h"
#include "vmap/map_access.h"

#ifndef VMAP_HAVE_MPI

namespace vmap::mpi {
bool launched() { return false; }
Result build(const ReadInput&, BuildParams, const Options&, const std::string&) {
    throw Error("this vmap was built without MPI (libopenmpi-dev was not found at build time)");
}
}  // namespace vmap::mpi

#else

#include <fmt/format.h>
#include <mpi.h>
#include <sched.h>
#include <time.h>
#include <unistd.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <memory>
#include <numeric>
#include <thread>

#include "io/vmap_file.h"
#include "mpi/shard_file.h"
#include "visibility/backend.h"
#include "vmap/build_checks.h"
#include "vmap/build_parts.h"

namespace vmap::mpi {
namespace {

using Clock = std::chrono::steady_clock;

constexpr int kTagAsk = 11, kTagGive = 12, kTagData = 13;
constexpr size_t kChunkBytes = size_t(256) << 20;  // one message at most (int counts)

// MPI for the length of one build: initialised (threads: one at a time, which the dispatcher of
// the dynamic schedule needs) and finalised on every path out.
struct Comm {
    int rank = 0, size = 1, local_rank = 0, local_size = 1;
    bool finalize = false;
    Comm() {
        int inited = 0;
        MPI_Initialized(&inited);
        if (!inited) {
            int provided = 0;
            MPI_Init_thread(nullptr, nullptr, MPI_THREAD_SERIALIZED, &provided);
            finalize = true;
        }
        MPI_Comm_rank(MPI_COMM_WORLD, &rank);
        MPI_Comm_size(MPI_COMM_WORLD, &size);
        MPI_Comm local;
        MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, rank, MPI_INFO_NULL, &local);
        MPI_Comm_rank(local, &local_rank);
        MPI_Comm_size(local, &local_size);
        MPI_Comm_free(&local);
    }
    ~Comm() {
        if (finalize) MPI_Finalize();
    }
    // Everyone's error, agreed: "" when every rank succeeded, else the lowest failing rank's
    // message, prefixed with its rank, on every rank.
    std::string agree(const std::string& err) const {
        int mine = err.empty() ? size : rank, first = size;
        MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
        if (first == size) return "";
        std::string msg = rank == first ? err : std::string();
        uint64_t n = msg.size();
        MPI_Bcast(&n, 1, MPI_UINT64_T, first, MPI_COMM_WORLD);
        msg.resize(n);
        MPI_Bcast(msg.data(), int(n), MPI_CHAR, first, MPI_COMM_WORLD);
        return size > 1 ? fmt::format("rank {} of {}: {}", first, size, msg) : msg;
    }
};

// Runs f, returning its error message ("" when it succeeded).
template <class F>
std::string attempt(F&& f) {
    try {
        f();
        return "";
    } catch (const std::bad_alloc&) {
        return "out of memory";
    } catch (const std::exception& e) {
        return e.what();
    }
}

// f() in an arena of n threads (the rank's: apps/main.cpp sets no process-wide limit under
// mpirun, so that rank 0's save may use more).
template <class F>
auto in_arena(int n, F&& f) {
    tbb::task_arena arena(std::max(1, n));
    return arena.execute(f);
}

// Large buffers in messages of at most kChunkBytes, with a partner that does the same.
void exchange_bytes(const void* send, size_t ns, int to, void* recv, size_t nr, int from,
                    uint64_t& moved) {
    const auto* s = static_cast<const uint8_t*>(send);
    auto* r = static_cast<uint8_t*>(recv);
    for (size_t is = 0, ir = 0; is < ns || ir < nr;) {
        const size_t cs = std::min(kChunkBytes, ns - is), cr = std::min(kChunkBytes, nr - ir);
        MPI_Sendrecv(s + is, int(cs), MPI_BYTE, cs ? to : MPI_PROC_NULL, kTagData, r + ir, int(cr),
                     MPI_BYTE, cr ? from : MPI_PROC_NULL, kTagData, MPI_COMM_WORLD,
                     MPI_STATUS_IGNORE);
        is += cs, ir += cr;
        moved += cs;
    }
}

// Every rank's links to the ranks that own either end (bounds: node ranges per rank), each
// link once per owner: `mine` gets the links this rank owns an end of, `links` is emptied.
// Returns the agreed error ("" when every rank succeeded).
std::string redistribute(const Comm& c, std::vector<NodePair>& links,
                         const std::vector<int32_t>& bounds, uint64_t& moved,
                         std::vector<NodePair>& mine) {
    // Every allocation is agreed before the data moves: a rank out of memory ends the job
    // instead of leaving the others in an exchange it never joins.
    std::vector<std::vector<NodePair>> out;
    std::string err = c.agree(attempt([&] { out = by_owner(links, bounds); }));
    if (!err.empty()) return err;
    std::vector<NodePair>().swap(links);  // all of it is in `out` now
    std::vector<uint64_t> ns(size_t(c.size)), nr(size_t(c.size));
    for (size_t k = 0; k < out.size(); ++k) ns[k] = out[k].size();
    MPI_Alltoall(ns.data(), 1, MPI_UINT64_T, nr.data(), 1, MPI_UINT64_T, MPI_COMM_WORLD);
    // Everything this rank gets, in one allocation: its own first, then from each rank.
    err =
        c.agree(attempt([&] { mine.resize(std::accumulate(nr.begin(), nr.end(), uint64_t(0))); }));
    if (!err.empty()) return err;
    std::copy(out[c.rank].begin(), out[c.rank].end(), mine.begin());
    std::vector<NodePair>().swap(out[c.rank]);
    size_t at = ns[c.rank];
    for (int s = 1; s < c.size; ++s) {
        const int to = (c.rank + s) % c.size, from = (c.rank - s + c.size) % c.size;
        exchange_bytes(out[to].data(), ns[to] * sizeof(NodePair), to, mine.data() + at,
                       nr[from] * sizeof(NodePair), from, moved);
        at += nr[from];
        std::vector<NodePair>().swap(out[to]);
    }
    return "";
}

// Rank 0 receives every rank's range into vm's link arrays (in rank order, which is node order).
std::string gather_ranges(const Comm& c, const LinkRange& r, VisibilityMap& vm, uint64_t& moved) {
    uint64_t n = r.targets.size();
    std::vector<uint64_t> sizes(size_t(c.size));
    MPI_Gather(&n, 1, MPI_UINT64_T, sizes.data(), 1, MPI_UINT64_T, 0, MPI_COMM_WORLD);
    // Rank 0 makes room for the whole map first, agreed (as in redistribute).
    detail::MapData& d = detail::MapAccess::data(vm);
    int32_t* out = nullptr;
    const std::string err = c.agree(attempt([&] {
        if (c.rank != 0) return;
        d.link_offsets.assign(size_t(vm.octree().num_nodes()) + 1, 0);
        out = detail::allocate_link_targets(
            d, std::accumulate(sizes.begin(), sizes.end(), uint64_t(0)));
    }));
    if (!err.empty()) return err;
    if (c.rank != 0) {
        const int32_t range[2] = {r.n0, r.n1};
        MPI_Send(range, 2, MPI_INT32_T, 0, kTagData, MPI_COMM_WORLD);
        exchange_bytes(r.offsets.data(), r.offsets.size() * 8, 0, nullptr, 0, 0, moved);
        exchange_bytes(r.targets.data(), n * 4, 0, nullptr, 0, 0, moved);
        return "";
    }
    std::copy(r.targets.begin(), r.targets.end(), out);
    uint64_t base = 0;
    for (int k = 0; k < c.size; ++k) {
        LinkRange got;
        if (k != 0) {
            int32_t range[2];
            MPI_Recv(range, 2, MPI_INT32_T, k, kTagData, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
            got.n0 = range[0], got.n1 = range[1];
            got.offsets.resize(size_t(got.n1 - got.n0) + 1);
            exchange_bytes(nullptr, 0, k, got.offsets.data(), got.offsets.size() * 8, k, moved);
            exchange_bytes(nullptr, 0, k, out + base, sizes[k] * 4, k, moved);
        }
        const LinkRange& g = k == 0 ? r : got;
        for (size_t i = 1; i < g.offsets.size(); ++i)
            d.link_offsets[size_t(g.n0) + i] = base + g.offsets[i];
        base += sizes[k];
    }
    return "";
}

// One rank's state through the build.
struct Run {
    const Comm& c;
    const Options& opt;
    BuildParams params;
    std::string source;
    VisibilityMap vm;  // the probe's: points and octree (rank 0 adds the links)
    BuildStats probe_stats;
    TopPairs tp;
    ShareResult share;
    uint64_t links = 0, moved = 0, gathered = 0;  // bytes sent: the exchange, the gather
    int threads = 0, chunks = 0;
    std::string schedule, note;
    std::vector<std::vector<uint32_t>> parts;  // static: a share per rank; dynamic: the chunks
    Run(const Comm& comm, const Options& o, BuildParams p, std::string src)
        : c(comm), opt(o), params(std::move(p)), source(std::move(src)) {}
};

// This rank's seconds in each phase of the build, in order; Result::phases gets the slowest
// rank's of each. Input and octree run on a thread during start (Early); probe is what is left
// of them after MPI_Init, with the agreement and the input check.
enum PhaseId { kStart, kInput, kOctree, kProbe, kJobs, kConstruction, kSettle, kExchange,
               kGather, kSave, kPhases };
constexpr const char* kPhaseNames[kPhases] = {
    "start",        "input",  "octree",   "probe",  "job list",
    "construction", "settle", "exchange", "gather", "save"};
struct Phases {
    double s[kPhases] = {};
    Clock::time_point at = Clock::now();
    void lap(PhaseId k) {
        const auto now = Clock::now();
        s[k] += std::chrono::duration<double>(now - at).count();
        at = now;
    }
};

// Seconds since this process started (Linux: its start time in /proc/self/stat against the
// boot clock, to 1/100 s), 0 where that cannot be read.
double process_age() {
    std::ifstream in("/proc/self/stat");
    std::string line;
    std::getline(in, line);
    const size_t close = line.rfind(')');
    if (close == std::string::npos) return 0;
    std::istringstream rest(line.substr(close + 2));
    std::string field;
    for (int k = 3; k <= 22 && rest >> field; ++k)  // field 22: starttime, in clock ticks
        if (k == 22) {
            timespec now{};
            clock_gettime(CLOCK_BOOTTIME, &now);
            const double started = std::stod(field) / double(sysconf(_SC_CLK_TCK));
            return std::max(0.0, double(now.tv_sec) + now.tv_nsec * 1e-9 - started);
        }
    return 0;
}

// CPU threads for this rank: as asked, else the host's cores shared by its ranks (within the
// cores mpirun bound the rank to).
int threads_for(int rank, int local_size, int requested, std::string& note) {
    const int hw = std::max(1u, std::thread::hardware_concurrency());
    cpu_set_t set;
    const int bound = sched_getaffinity(0, sizeof set, &set) == 0 ? CPU_COUNT(&set) : hw;
    if (requested > 0) return requested;
    const int share = std::max(1, hw / std::max(1, local_size));
    if (bound < share)
        note = fmt::format(
            "mpirun bound rank {} to {} cores of the {} its share would be: it runs {} threads "
            "(mpirun --bind-to none, or --map-by slot:PE={}, gives it its share)",
            rank, bound, share, bound, share);
    return std::min(share, bound);
}

// The host's cores less one for each other rank of the host: what rank 0 may take while the
// others only wait on it (for the input before MPI starts, for the save at the end).
int root_cores(int threads, int local_size) {
    const int hw = int(std::max(1u, std::thread::hardware_concurrency()));
    cpu_set_t set;
    const int bound = sched_getaffinity(0, sizeof set, &set) == 0 ? CPU_COUNT(&set) : hw;
    // Within the cores mpirun bound the rank to (Open MPI binds to a core for up to 2 ranks).
    return std::max(threads, std::min(bound, hw - (std::max(1, local_size) - 1)));
}

// A fingerprint of the input as the probe read it: every rank must build the same map.
uint64_t input_hash(const VisibilityMap& vm) {
    auto h = [](const auto& v) {
        return detail::payload_hash(reinterpret_cast<const uint8_t*>(v.data()),
                                    v.size() * sizeof(v[0]));
    };
    const VisibilityParams& vp = vm.visibility_params();
    const std::vector<float> params{float(vm.octree_params().max_height),
                                    float(vm.octree_params().leaf_points),
                                    vm.octree_params().delta_floor,
                                    float(vp.K),
                                    vp.eps,
                                    vp.facing_tol,
                                    vp.parallel_tol,
                                    vp.end_window,
                                    vp.roughness,
                                    vp.core};
    uint64_t x = h(vm.points().positions) ^ h(vm.points().normals) * 3 ^ h(vm.points().radii) * 5 ^
                 h(vm.order()) * 7 ^ h(params) * 11;
    return x ^ uint64_t(vm.octree().num_nodes()) * 0x9e3779b97f4a7c15ULL;
}

// "" when every rank's value equals rank 0's; else what each differing rank says, agreed.
std::string check_same(const Comm& c, uint64_t mine, const std::string& differs) {
    uint64_t lo = 0, hi = 0;
    MPI_Allreduce(&mine, &lo, 1, MPI_UINT64_T, MPI_MIN, MPI_COMM_WORLD);
    MPI_Allreduce(&mine, &hi, 1, MPI_UINT64_T, MPI_MAX, MPI_COMM_WORLD);
    if (lo == hi) return "";
    uint64_t first = mine;
    MPI_Bcast(&first, 1, MPI_UINT64_T, 0, MPI_COMM_WORLD);
    return c.agree(mine == first ? "" : differs);
}

std::string check_same_input(const Comm& c, const VisibilityMap& vm) {
    return check_same(c, input_hash(vm),
                      "its input (points, octree or parameters) differs from rank 0's: every "
                      "rank must read the same scene with the same options");
}

std::string run_static(Run& r) {
    return attempt([&] {
        build_round(r.vm, r.params, r.tp, r.parts[size_t(r.c.rank)], !r.opt.count_links,
                    r.source, r.share);
    });
}

// Rank 0's thread of the dynamic schedule: answers each rank's ask with the next chunk (-1:
// none left, or a rank failed), until every other rank has had its -1 or said it failed.
void dispatch(const Comm& c, int chunks, std::atomic<int>& next, std::atomic<bool>& failed) {
    for (int remote = c.size - 1; remote > 0;) {
        int flag = 0;
        MPI_Status st;
        MPI_Iprobe(MPI_ANY_SOURCE, kTagAsk, MPI_COMM_WORLD, &flag, &st);
        if (!flag) {  // asks come seconds apart: poll lightly instead of spinning a core
            std::this_thread::sleep_for(std::chrono::microseconds(200));
            continue;
        }
        int msg = 0;
        MPI_Recv(&msg, 1, MPI_INT, st.MPI_SOURCE, kTagAsk, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
        if (msg != 0) {
            failed = true;
            --remote;
            continue;
        }
        int k = failed ? chunks : next.fetch_add(1);
        if (k >= chunks) k = -1, --remote;
        MPI_Send(&k, 1, MPI_INT, st.MPI_SOURCE, kTagGive, MPI_COMM_WORLD);
    }
}

std::string run_dynamic(Run& r) {
    const auto& chunks = r.parts;
    const int n = r.chunks;
    // One build_vmap a rank: the chunks it is handed are resolved over one octree.
    auto rounds = [&](const std::function<int()>& take) {
        build_rounds(
            r.vm, r.params, r.tp,
            [&]() -> const std::vector<uint32_t>* {
                const int k = take();
                return k < 0 ? nullptr : &chunks[size_t(k)];
            },
            !r.opt.count_links, r.source, r.share);
    };
    if (r.c.rank == 0) {
        std::atomic<int> next{0};
        std::atomic<bool> failed{false};
        std::thread t([&] { dispatch(r.c, n, next, failed); });
        std::string err = attempt([&] {
            rounds([&] {
                const int k = failed ? n : next.fetch_add(1);
                return k < n ? k : -1;
            });
        });
        if (!err.empty()) failed = true;
        t.join();
        return err;
    }
    std::string err = attempt([&] {
        rounds([&] {
            int ask = 0, k = -1;
            MPI_Send(&ask, 1, MPI_INT, 0, kTagAsk, MPI_COMM_WORLD);
            MPI_Recv(&k, 1, MPI_INT, 0, kTagGive, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
            return k;
        });
    });
    if (!err.empty()) {
        int quit = 1;
        MPI_Send(&quit, 1, MPI_INT, 0, kTagAsk, MPI_COMM_WORLD);
    }
    return err;
}

// Which jobs came back whole, from every rank; their merges; the links this rank keeps.
void settle(Run& r) {
    const size_t n = r.tp.pairs.size();
    std::vector<uint8_t> mine = r.share.full, all(n, 0);
    mine.resize(n, 0);
    MPI_Allreduce(mine.data(), all.data(), int(n), MPI_UNSIGNED_CHAR, MPI_MAX, MPI_COMM_WORLD);
    const Merge m = merge_full(r.tp, all);
    uint64_t dropped = 0;
    for (size_t i = 0; i < n; ++i) dropped += m.drop[i] && mine[i];
    if (!r.opt.count_links) {
        drop_merged(r.tp, m, r.share.links);
        if (r.c.rank == 0) r.share.links.insert(r.share.links.end(), m.add.begin(), m.add.end());
    }
    const uint64_t local = r.share.links_counted - dropped + (r.c.rank == 0 ? m.add.size() : 0);
    MPI_Allreduce(&local, &r.links, 1, MPI_UINT64_T, MPI_SUM, MPI_COMM_WORLD);
}

// The counters of all ranks summed into rank 0's stats (times: the slowest rank's).
BuildStats reduce_stats(Run& r) {
    const Octree& t = r.vm.octree();
    const size_t levels = size_t(t.height()) + 1, leaves = size_t(t.num_leaves());
    const std::vector<uint64_t> mine = counters_of(r.share.stats, levels, leaves);
    std::vector<uint64_t> sum(mine.size(), 0);
    MPI_Reduce(mine.data(), sum.data(), int(mine.size()), MPI_UINT64_T, MPI_SUM, 0, MPI_COMM_WORLD);
    const BuildStats& s = r.share.stats;
    const double t_mine[6] = {s.seconds_plan,    s.seconds_wait,  s.seconds_backend,
                              s.seconds_extract, s.seconds_links, double(s.peak_device_bytes)};
    double t_max[6] = {};
    MPI_Reduce(t_mine, t_max, 6, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
    BuildStats st = r.probe_stats;
    if (r.c.rank != 0) return st;
    add_counters(st, sum, levels, leaves);
    st.leaf_pairs = uint64_t(leaves) * (leaves - 1) / 2;  // the whole job's (the probe's is 0)
    if (!r.share.stats.construction.empty()) st.construction = r.share.stats.construction;
    st.backend = r.share.stats.backend;  // the probe built the octree only
    if (st.note.empty()) st.note = r.share.stats.note;
    st.seconds_plan = st.seconds_decide = t_max[0], st.seconds_wait = t_max[1];
    st.seconds_backend = t_max[2], st.seconds_extract = t_max[3], st.seconds_links = t_max[4];
    st.peak_device_bytes = uint64_t(t_max[5]);
    st.links = r.links;
    detail::check_facing(st, r.vm.octree(), r.params.visibility);
    return st;
}

// The links of this rank's node range, every link sent to the owners of its ends.
std::string own_range(Run& r, LinkRange& range, std::vector<int32_t>& bounds) {
    const int32_t nodes = r.vm.octree().num_nodes();
    std::vector<uint32_t> deg(size_t(nodes), 0), all(size_t(nodes), 0);
    for (const auto& [a, b] : r.share.links) deg[a]++, deg[b]++;
    MPI_Allreduce(deg.data(), all.data(), nodes, MPI_UINT32_T, MPI_SUM, MPI_COMM_WORLD);
    bounds = split_nodes(all, r.c.size);
    std::vector<NodePair> got;
    const std::string err = redistribute(r.c, r.share.links, bounds, r.moved, got);
    if (!err.empty()) return err;
    return r.c.agree(
        attempt([&] { range = link_range(got, bounds[r.c.rank], bounds[r.c.rank + 1]); }));
}

std::string write_single(Run& r, LinkRange& range, Phases& ph) {
    const std::string err = gather_ranges(r.c, range, r.vm, r.gathered);
    range = LinkRange{};
    ph.lap(kGather);
    if (!err.empty()) return err;
    // The other ranks of this host only wait now (a core each, polling): rank 0 takes the rest.
    const int cores = root_cores(r.threads, r.c.local_size);
    return r.c.agree(attempt([&] {
        if (r.c.rank == 0) in_arena(cores, [&] { save_vmap(r.opt.output, r.vm); });
    }));
}

// Shards: every rank writes its file; all are committed once all are written, then rank 0
// writes the index (last: an index on disk means its shards are whole). A failure removes what
// this build committed.
std::string write_shards(Run& r, const LinkRange& range) {
    const std::string& out = r.opt.output;
    const std::string mine = shard_name(out, r.c.rank, r.c.size), base = base_name(out);
    ShardInfo info;
    std::unique_ptr<io::AtomicFile> f;
    auto undo = [&] {
        std::error_code ec;
        std::filesystem::remove(mine, ec);
        if (r.c.rank == 0) std::filesystem::remove(base, ec);
    };
    std::string err = r.c.agree(attempt([&] {
        f = write_shard(mine, r.c.rank, range, info);
        if (r.c.rank == 0) save_base(base, r.vm);
    }));
    if (err.empty()) err = r.c.agree(attempt([&] { f->commit(); }));
    if (!err.empty()) return undo(), err;
    const uint64_t row[5] = {uint64_t(info.n0), uint64_t(info.n1), info.ends, info.bytes,
                             info.checksum};
    std::vector<uint64_t> rows(size_t(r.c.size) * 5);
    MPI_Gather(row, 5, MPI_UINT64_T, rows.data(), 5, MPI_UINT64_T, 0, MPI_COMM_WORLD);
    err = r.c.agree(attempt([&] {
        if (r.c.rank != 0) return;
        std::vector<ShardInfo> shards(size_t(r.c.size));
        for (int k = 0; k < r.c.size; ++k) {
            const uint64_t* x = rows.data() + 5 * k;
            shards[k] = {std::filesystem::path(shard_name(out, k, r.c.size)).filename().string(),
                         int32_t(x[0]),
                         int32_t(x[1]),
                         x[2],
                         x[3],
                         x[4]};
        }
        write_index(out, shards, r.links, r.vm.octree().num_nodes());
    }));
    if (!err.empty()) undo();
    return err;
}

// The slowest rank's seconds of each phase, on rank 0 (named as in kPhaseNames).
std::vector<std::pair<std::string, double>> slowest_phases(const Comm& c, const Phases& ph) {
    double hi[kPhases] = {};
    MPI_Reduce(ph.s, hi, kPhases, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
    std::vector<std::pair<std::string, double>> out;
    if (c.rank == 0)
        for (int k = 0; k < kPhases; ++k) out.emplace_back(kPhaseNames[k], hi[k]);
    return out;
}

// The phases line of the summary: the slowest rank's seconds, bytes where bytes move.
std::string phases_line(const Run& r, const std::vector<std::pair<std::string, double>>& ph) {
    std::string line = "phases:     slowest rank's s:";
    for (size_t k = 0; k < ph.size(); ++k) {
        if (k == kInput || k == kOctree) continue;
        line += fmt::format("{} {} {:.3f}", k ? "," : "", ph[k].first, ph[k].second);
        if (k == kStart)
            line += fmt::format(" (meanwhile on a thread: input {:.3f}, octree {:.3f})",
                                ph[kInput].second, ph[kOctree].second);
        if (k == kExchange) line += fmt::format(" ({:.1f} MiB)", double(r.moved) / 1048576.0);
        if (k == kGather) line += fmt::format(" ({:.1f} MiB)", double(r.gathered) / 1048576.0);
    }
    return line;
}

// Per-rank construction times and rounds, gathered into lines for rank 0's summary.
std::vector<std::string> summary(Run& r, double output_s,
                                 const std::vector<std::pair<std::string, double>>& ph) {
    constexpr int kN = 5;
    const double mine[kN] = {r.share.seconds, double(r.share.rounds),
                             double(r.c.local_rank == 0), double(r.moved), double(r.gathered)};
    std::vector<double> all(size_t(r.c.size) * kN);
    MPI_Gather(mine, kN, MPI_DOUBLE, all.data(), kN, MPI_DOUBLE, 0, MPI_COMM_WORLD);
    if (r.c.rank != 0) return {};
    double lo = 1e300, hi = 0, sum = 0, rlo = 1e300, rhi = 0, hosts = 0, moved = 0, gathered = 0;
    for (int k = 0; k < r.c.size; ++k) {
        const double* x = all.data() + kN * k;
        lo = std::min(lo, x[0]), hi = std::max(hi, x[0]), sum += x[0];
        rlo = std::min(rlo, x[1]), rhi = std::max(rhi, x[1]), hosts += x[2];
        moved += x[3], gathered += x[4];
    }
    r.moved = uint64_t(moved), r.gathered = uint64_t(gathered);  // every rank's
    const double mean = sum / r.c.size;
    std::vector<std::string> lines{
        fmt::format("mpi:        {} ranks on {} host(s), {} threads each{}, schedule {} ({} "
                    "chunks of {} jobs)",
                    r.c.size, int(hosts), r.threads,
                    r.params.backend == Backend::kCpu ? std::string()
                                                      : fmt::format(", device {}", r.params.device),
                    r.schedule, r.chunks, r.tp.jobs.size()),
        fmt::format("            construction per rank {:.3f}-{:.3f} s (mean {:.3f}, slowest / "
                    "mean {:.3f}), {}-{} rounds",
                    lo, hi, mean, hi / std::max(1e-9, mean), int(rlo), int(rhi)),
        fmt::format("            links moved between ranks {:.1f} MiB; output {:.3f} s{}",
                    double(r.moved + r.gathered) / 1048576.0, output_s,
                    r.opt.shards ? fmt::format(" ({} shards + index)", r.c.size) : ""),
        phases_line(r, ph)};
    if (!r.note.empty()) lines.push_back("note:       " + r.note);
    return lines;
}

// Rank 0 reports for the job: its own leaf pairs are about 1/ranks of them (the chunks go to
// whoever asks), so its count is scaled up and the estimate shared out, instead of a bar that
// stops near 1/ranks and an estimate for one rank doing everything.
ProgressCallback whole_job_progress(ProgressCallback inner, int ranks) {
    auto where = std::make_shared<std::string>();
    return [inner = std::move(inner), ranks, where](const ProgressInfo& p) {
        ProgressInfo q = p;
        q.done = std::min(p.total, p.done * uint64_t(ranks));
        q.estimate_seconds = p.estimate_seconds / ranks;
        q.eta_seconds = q.done ? p.seconds * double(q.total - q.done) / double(q.done) : 0;
        if (*p.backend) {
            *where = fmt::format("{} ranks, {} each", ranks, p.backend);
            q.backend = where->c_str();
        }
        return inner(q);
    };
}

// Threads, device and progress of this rank.
void configure(Run& r) {
    r.threads = threads_for(r.c.rank, r.c.local_size, r.opt.threads, r.note);
    r.params.threads = r.threads;
    if (r.params.device < 0 && r.params.backend != Backend::kCpu) {
        const int gpus = detail::cuda_device_count();
        r.params.device = gpus > 0 ? r.c.local_rank % gpus : 0;
    }
    if (r.c.rank != 0) r.params.progress = nullptr;
    if (r.c.rank == 0 && r.params.progress && r.c.size > 1)
        r.params.progress = whole_job_progress(std::move(r.params.progress), r.c.size);
    r.schedule = r.opt.schedule;
    if (r.schedule != "static" && r.schedule != "dynamic")
        throw Error(
            fmt::format("--schedule: unknown schedule '{}' (static or dynamic)", r.schedule));
    int level = 0;
    MPI_Query_thread(&level);
    if (r.schedule == "dynamic" && level < MPI_THREAD_SERIALIZED && r.c.size > 1) {
        r.schedule = "static";
        r.note = "this MPI gives no thread support: the static schedule instead of dynamic";
    }
}

// What rank 0 does before it needs the others, on a thread of its own while MPI starts
// (MPI_Init waits on every rank): it reads the input, on the host's cores (the other ranks of
// the host have nothing to do until they get the points: share_input), and builds the octree.
// Its failure is agreed once MPI is up (prepare). The other ranks read nothing.
struct Early {
    BuildParams params;
    VisibilityMap vm;
    BuildStats stats;
    std::string err;
    PointSet raw;  // the points as read, before the octree orders them: for the other ranks
    double input_s = 0, octree_s = 0;
    bool reader = false;
    std::thread thread;
    Early(const ReadInput& read, BuildParams p, const Options& opt, const std::string& source)
        : params(std::move(p)) {
        auto env = [](const char* name) {
            const char* v = std::getenv(name);
            return v ? std::atoi(v) : 0;
        };
        std::string note;  // configure() gives it, with MPI's figures
        const int rank =
            std::getenv("OMPI_COMM_WORLD_RANK") ? env("OMPI_COMM_WORLD_RANK") : env("PMIX_RANK");
        const int local_size = env("OMPI_COMM_WORLD_LOCAL_SIZE");
        const bool alone = env("OMPI_COMM_WORLD_SIZE") == 1;
        params.threads = threads_for(rank, local_size, opt.threads, note);
        reader = rank == 0;
        if (!reader) return;
        thread = std::thread([this, &read, &source, local_size, alone] {
            err = attempt([&] {
                const int cores = root_cores(params.threads, local_size);
                auto t = Clock::now();
                PointSet points = in_arena(cores, [&] { return read(params); });
                input_s = seconds_since(t);
                if (!alone) raw = points;
                t = Clock::now();
                BuildParams wide = params;
                wide.threads = cores;
                vm = detail::build_octree(std::move(points), wide, stats, source);
                octree_s = seconds_since(t);
            });
        });
    }
    ~Early() {
        if (thread.joinable()) thread.join();
    }
};

// Rank 0's bytes to every rank, in messages of at most kChunkBytes.
void share_bytes(void* data, size_t bytes) {
    auto* p = static_cast<uint8_t*>(data);
    for (size_t at = 0; at < bytes; at += kChunkBytes)
        MPI_Bcast(p + at, int(std::min(kChunkBytes, bytes - at)), MPI_BYTE, 0, MPI_COMM_WORLD);
}

// Rank 0's points (as read), octree parameters and roughness to the other ranks, which build the
// octree from them (the same octree: check_same_input checks it with the rest). The sizes go first
// and every rank makes room for all of it before any data moves, agreed: a rank that cannot (out of
// memory) ends the job instead of leaving the others in a broadcast it never joins.
std::string share_input(Run& r, Early& e) {
    static_assert(std::is_trivially_copyable_v<OctreeParams>);
    PointSet& p = e.raw;
    uint64_t n[5] = {p.positions.size(), p.normals.size(), p.colors.size(), p.radii.size(),
                     p.emission.size()};
    MPI_Bcast(n, 5, MPI_UINT64_T, 0, MPI_COMM_WORLD);
    MPI_Bcast(&e.params.octree, int(sizeof(OctreeParams)), MPI_BYTE, 0, MPI_COMM_WORLD);
    // The predicate's roughness too: rank 0's reading measures it on a cloud (the other
    // parameters are each rank's own, and check_same_input compares them).
    MPI_Bcast(&e.params.visibility.roughness, 1, MPI_FLOAT, 0, MPI_COMM_WORLD);
    MPI_Bcast(p.origin.data(), 3, MPI_DOUBLE, 0, MPI_COMM_WORLD);
    std::string err = r.c.agree(attempt([&] {
        p.positions.resize(n[0]), p.normals.resize(n[1]), p.colors.resize(n[2]);
        p.radii.resize(n[3]), p.emission.resize(n[4]);
    }));
    if (!err.empty()) return err;
    share_bytes(p.positions.data(), n[0] * sizeof(Vec3));
    share_bytes(p.normals.data(), n[1] * sizeof(Vec3));
    share_bytes(p.colors.data(), n[2] * sizeof(Vec3));
    share_bytes(p.radii.data(), n[3] * sizeof(float));
    share_bytes(p.emission.data(), n[4] * sizeof(Vec3));
    if (r.c.rank == 0) e.raw = PointSet{};               // its octree is built (Early)
    return r.c.agree(r.c.rank == 0 ? "" : attempt([&] {  // its time is the probe's
        in_arena(e.params.threads,
                 [&] { e.vm = detail::build_octree(std::move(p), e.params, e.stats, r.source); });
    }));
}

// The input and octree (every rank the same; checked) and the job list, each phase agreed.
std::string prepare(Run& r, Early& e, Phases& ph) {
    if (e.thread.joinable()) e.thread.join();
    std::string err =
        r.c.agree(e.reader == (r.c.rank == 0)
                      ? e.err
                      : "its rank could not be told before MPI started (OMPI_COMM_WORLD_RANK or "
                        "PMIX_RANK)");
    // Only rank 0 read the input: the others' options must name the same.
    if (err.empty()) {
        const std::string& key = r.opt.input_key;
        err = check_same(
            r.c, detail::payload_hash(reinterpret_cast<const uint8_t*>(key.data()), key.size()),
            fmt::format("its input ({}) differs from rank 0's: every rank must read the same "
                        "scene with the same options",
                        key));
    }
    if (err.empty()) err = share_input(r, e);
    if (err.empty()) {
        r.params = std::move(e.params);
        r.vm = std::move(e.vm);
        r.probe_stats = std::move(e.stats);
        err = r.c.agree(attempt([&] { configure(r); }));
    }
    if (err.empty()) err = in_arena(r.threads, [&] { return check_same_input(r.c, r.vm); });
    ph.s[kInput] = e.input_s;
    ph.s[kOctree] = e.octree_s;
    ph.lap(kProbe);
    if (!err.empty()) return err;
    r.tp = make_top_pairs_for(r.vm.octree(), r.c.size);
    r.parts = r.schedule == "static" ? static_shares(r.tp, r.c.size)
                                     : dynamic_chunks(r.tp, r.c.size, r.opt.chunks_per_rank);
    r.chunks = int(r.parts.size());
    ph.lap(kJobs);
    return "";
}

// The links to their owners, then to rank 0's file or to every rank's shard.
std::string output(Run& r, Phases& ph) {
    LinkRange range;
    std::vector<int32_t> bounds;
    std::string err = in_arena(r.threads, [&] { return own_range(r, range, bounds); });
    ph.lap(kExchange);
    if (err.empty())
        err = r.opt.shards ? in_arena(r.threads, [&] { return write_shards(r, range); })
                           : write_single(r, range, ph);
    ph.lap(kSave);
    return err;
}

}  // namespace

bool launched() { return std::getenv("OMPI_COMM_WORLD_SIZE") || std::getenv("PMIX_RANK"); }

Result build(const ReadInput& read, BuildParams params, const Options& opt,
             const std::string& source) {
    const auto t0 = Clock::now();
    Early e(read, std::move(params), opt, source);
    Comm c;
    Phases ph;
    ph.s[kStart] = process_age();
    Run r(c, opt, BuildParams{}, source);
    Result res;
    res.root = c.rank == 0;
    // Rank 0 reports an agreed failure and exits non-zero, which makes mpirun's status; the
    // others return normally: a rank exiting non-zero makes mpirun end the job at once, which
    // could kill rank 0 before it has printed the error (seen under load).
    auto fail = [&](const std::string& e) {
        if (c.rank == 0) throw Error(e);
        return std::move(res);
    };
    std::string err = prepare(r, e, ph);
    if (err.empty()) err = c.agree(r.schedule == "static" ? run_static(r) : run_dynamic(r));
    ph.lap(kConstruction);
    if (!err.empty()) return fail(err);
    settle(r);
    res.stats = reduce_stats(r);
    ph.lap(kSettle);
    const auto tw = Clock::now();
    if (!opt.count_links && !(err = output(r, ph)).empty()) return fail(err);
    res.save_seconds = seconds_since(tw);
    res.phases = slowest_phases(c, ph);
    res.summary = summary(r, res.save_seconds, res.phases);
    if (c.rank != 0) return res;
    res.stats.seconds_total = seconds_since(t0) - res.save_seconds - ph.s[kInput];
    res.stats.seconds_visibility = res.stats.seconds_total - res.stats.seconds_octree;
    if (opt.count_links || opt.shards) detail::MapAccess::data(r.vm).link_offsets.clear();
    res.vm = std::move(r.vm);
    return res;
}

}  // namespace vmap::mpi

#endif
