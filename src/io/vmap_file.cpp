// The .vmap file: everything later commands need (parameters, points, octree, point order,
// links), versioned and checksummed.
//
// Layout (little-endian):
//   header: "VMAPFILE" | u32 version | u32 reserved | u64 payload bytes | u64 payload checksum
//           (payload_hash below)
//   payload: sections, each: 4-char tag | u64 bytes | data
//     PARM: octree and visibility parameters (version 5: the octree's delta_floor; version 6:
//           the predicate's end_window; version 7: its roughness, in the input's units;
//           version 8: its core, last)
//     PNTS: u64 n | u8 mask (1 colours, 2 radii, 4 emission, 8 origin) | positions, normals,
//           [colours], [radii], [emission]  (octree order), [f64 origin[3]: where the input's
//           coordinates had the positions' zero, PointSet::origin; files without it are as before)
//     ORDR: u32 order[n] (octree position -> input index)
//     TREE: node and leaf counts, root cube, then the octree's arrays in the order of
//           include/vmap/octree.h (spheres, boxes, half_size, skip, ...), then f64 scale (input
//           units per octree unit: points and octree are stored in the octree's frame)
//     LINK: u64 offsets[nodes + 1] | the targets, each node's sorted: version 5 as chunks of
//           delta-coded StreamVByte streams (io/link_codec.h: about a third of the raw size),
//           version 4 (still read) as i32 targets[offsets[nodes]]
#include "io/vmap_file.h"
#include "io/link_codec.h"
#include "vmap/parallel.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <fmt/format.h>
#include <tbb/enumerable_thread_specific.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <span>
#include <deque>
#include <filesystem>
#include <fstream>
#include <memory>
#include <new>
#include <thread>
#include <type_traits>

#include "mpi/shard_file.h"
#include "octree/records.h"
#include "vmap/error.h"
#include "vmap/files.h"
#include "vmap/map_access.h"

namespace vmap {
namespace {

constexpr char kMagic[8] = {'V', 'M', 'A', 'P', 'F', 'I', 'L', 'E'};
constexpr uint32_t kVersion = 8;     // 2: 64-bit link offsets; 3: emission in octree order and
                                     // the measured Delta rule (a version-2 file is built wrong);
                                     // 4: the octree's frame (scale); 5: coded link targets,
                                     // the octree's delta_floor; 6: the predicate's end_window;
                                     // 7: the predicate's roughness; 8: its core
constexpr uint32_t kOldestRead = 4;  // version 4 lacks PARM's delta_floor and codes no links
constexpr size_t kHeader = 8 + 4 + 4 + 8 + 8;

// The checksum: a 64-bit multiply-xorshift hash of each 1 MiB block of the payload (8 bytes at a
// step, blocks in parallel), folded in block order. A V-map of a large scene runs to gigabytes;
// a byte-at-a-time hash would take seconds.
uint64_t block_hash(const uint8_t* p, size_t n, uint64_t seed) {
    uint64_t h = 0x9e3779b97f4a7c15ULL ^ (seed * 0xff51afd7ed558ccdULL);
    size_t i = 0;
    for (; i + 8 <= n; i += 8) {
        uint64_t w;
        std::memcpy(&w, p + i, 8);
        h = (h ^ w) * 0xc4ceb9fe1a85ec53ULL;
        h ^= h >> 29;
    }
    for (; i < n; ++i) h = (h ^ p[i]) * 0x100000001b3ULL;
    return h ^ (h >> 32);
}

}  // namespace

namespace {

constexpr size_t kBlock = size_t(1) << 20;  // the checksum's blocks

// The blocks' hashes folded in block order, with the payload's length.
uint64_t fold_hashes(const std::vector<uint64_t>& hs, size_t n) {
    uint64_t h = 0x84222325cbf29ce4ULL ^ n;
    for (uint64_t x : hs) h = (h ^ x) * 0x100000001b3ULL;
    return h;
}

}  // namespace

uint64_t detail::payload_hash(const uint8_t* p, size_t n) {
    const size_t blocks = (n + kBlock - 1) / kBlock;
    std::vector<uint64_t> hs(blocks);
    parallel_for(blocks, [&](size_t b) {
        hs[b] = block_hash(p + b * kBlock, std::min(kBlock, n - b * kBlock), b);
    });
    return fold_hashes(hs, n);
}

namespace {

// memcpy of a large array, in parallel chunks.
void copy_bytes(uint8_t* dst, const uint8_t* src, size_t n) {
    constexpr size_t kChunk = size_t(1) << 22;
    parallel_for((n + kChunk - 1) / kChunk, [&](size_t c) {
        std::memcpy(dst + c * kChunk, src + c * kChunk, std::min(kChunk, n - c * kChunk));
    });
}

// The links' stream, coded chunk by chunk as write_file's writers reach it: a writer codes the
// chunks its bytes lie in, or waits for the thread already coding one (which codes it alone,
// without tasks that could queue behind the waiting one), so the coding runs beside the writing
// instead of before it, and each chunk is hashed and written while it is still in the cache.
// The bytes are encode_links' (vmap_file_test checks the file against them).
struct LazyLinks {
    detail::LinkCoder coder;
    // per chunk: 0 not begun, 1 coding, 2 coded, 3 failed (its coder threw: no waiter may spin)
    std::unique_ptr<std::atomic<uint8_t>[]> state;
    tbb::enumerable_thread_specific<std::vector<uint8_t>> scratch;
    explicit LazyLinks(detail::LinkCoder&& c)
        : coder(std::move(c)), state(new std::atomic<uint8_t>[coder.chunks()]) {
        for (size_t k = 0; k < coder.chunks(); ++k) state[k].store(0, std::memory_order_relaxed);
    }
    // Makes the stream's bytes [lo, hi) (lo < hi).
    void ready(size_t lo, size_t hi) {
        const std::vector<uint64_t>& at = coder.links().chunk_byte;
        size_t k = size_t(std::upper_bound(at.begin(), at.end(), lo) - at.begin()) - 1;
        for (; k < coder.chunks() && at[k] < hi; ++k) {
            uint8_t s = 0;
            if (state[k].compare_exchange_strong(s, 1, std::memory_order_acq_rel)) {
                try {
                    coder.code(k, scratch.local());  // (throws only std::bad_alloc)
                } catch (...) {
                    state[k].store(3, std::memory_order_release);
                    throw;
                }
                state[k].store(2, std::memory_order_release);
                continue;
            }
            while ((s = state[k].load(std::memory_order_acquire)) == 1) std::this_thread::yield();
            if (s == 3) throw std::bad_alloc();
        }
    }
};

// The payload as a list of pieces: small fields in buffers of its own, the large arrays in place
// (no copy of gigabytes of links before writing them), the links' stream coded as it is written.
struct Writer {
    struct Piece {
        const uint8_t* p;
        size_t n;
        LazyLinks* lazy = nullptr;  // bytes to make (lazy->ready) before they are read
    };
    std::deque<std::vector<uint8_t>> owned;  // stable addresses
    std::unique_ptr<LazyLinks> links;
    std::vector<Piece> pieces;
    size_t size = 0;
    bool open = false;  // owned.back() still takes small fields

    std::vector<uint8_t>& small() {
        if (!open) {
            owned.emplace_back();
            owned.back().reserve(4096);
            open = true;
        }
        return owned.back();
    }
    void close_small() {
        if (!open) return;
        pieces.push_back({owned.back().data(), owned.back().size()});
        open = false;
    }
    // The coder's stream, coded as it is written (LazyLinks).
    void take(detail::LinkCoder&& c) {
        links = std::make_unique<LazyLinks>(std::move(c));
        const detail::HugeVector<uint8_t>& v = links->coder.links().stream;
        if (v.empty()) return;
        close_small();
        size += v.size();
        pieces.push_back({v.data(), v.size(), links.get()});
    }
    template <class T>
    void put(const T& v) {
        static_assert(std::is_trivially_copyable_v<T>);
        const auto* p = reinterpret_cast<const uint8_t*>(&v);
        small().insert(small().end(), p, p + sizeof(T));
        size += sizeof(T);
    }
    template <class T, class A>
    void vec(const std::vector<T, A>& v) {
        vec(std::span<const T>(v));
    }
    template <class T>
    void vec(std::span<const T> v) {
        static_assert(std::is_trivially_copyable_v<T>);
        if (v.empty()) return;
        close_small();
        pieces.push_back({reinterpret_cast<const uint8_t*>(v.data()), v.size() * sizeof(T)});
        size += v.size() * sizeof(T);
    }
    // A section: tag, then its length, patched by end().
    struct Mark {
        size_t buffer, offset;  // where the length field is (owned[buffer], offset)
        size_t start;           // payload offset of the section's first byte
    };
    Mark begin(const char (&tag)[5]) {
        for (int k = 0; k < 4; ++k) put(tag[k]);
        put(uint64_t(0));
        return {owned.size() - 1, owned.back().size() - 8, size};
    }
    void end(Mark m) {
        const uint64_t n = size - m.start;
        std::memcpy(owned[m.buffer].data() + m.offset, &n, 8);
    }
    void finish() { close_small(); }
};

struct Reader {
    const uint8_t* p;
    const uint8_t* end;
    std::string file, section;
    [[noreturn]] void fail(const std::string& what) const {
        throw Error(fmt::format("{}: section {}: {}", file, section, what));
    }
    template <class T>
    T get() {
        if (size_t(end - p) < sizeof(T)) fail("truncated");
        T v;
        std::memcpy(&v, p, sizeof(T));
        p += sizeof(T);
        return v;
    }
    template <class T, class A>
    void vec(std::vector<T, A>& v, uint64_t n) {
        if (n > uint64_t(end - p) / sizeof(T)) fail(fmt::format("truncated: {} items expected", n));
        v.resize(n);
        copy_bytes(reinterpret_cast<uint8_t*>(v.data()), p, n * sizeof(T));
        p += n * sizeof(T);
    }
    // Enters the section tagged `tag` (4 characters); returns where it ends.
    const uint8_t* begin_section(const char* tag) {
        section = tag;
        char got[4];
        if (size_t(end - p) < 12) fail("missing");
        std::memcpy(got, p, 4);
        if (std::memcmp(got, tag, 4) != 0)
            fail(fmt::format("expected here, found '{}'", std::string(got, 4)));
        p += 4;
        const uint64_t len = get<uint64_t>();
        if (len > uint64_t(end - p)) fail("truncated");
        return p + len;
    }
    void end_section(const uint8_t* e) const {
        if (p != e) fail("length does not match its contents");
    }
};

}  // namespace

namespace {

// The payload: the five sections, as pieces that point into vm's arrays (or into w's own).
void write_payload(Writer& w, const VisibilityMap& vm) {
    const Octree& t = vm.octree();
    const PointSet& ps = vm.points();
    Writer::Mark s = w.begin("PARM");
    w.put(int32_t(vm.octree_params().max_height));
    w.put(int32_t(vm.octree_params().leaf_points));
    w.put(int32_t(vm.visibility_params().K));
    w.put(vm.visibility_params().eps);
    w.put(vm.visibility_params().facing_tol);
    w.put(vm.visibility_params().parallel_tol);
    w.put(vm.octree_params().delta_floor);
    w.put(vm.visibility_params().end_window);
    w.put(vm.visibility_params().roughness);
    w.put(vm.visibility_params().core);
    w.end(s);
    s = w.begin("PNTS");
    const uint64_t n = ps.size();
    w.put(n);
    const bool shifted = ps.has_origin();
    const uint8_t mask = (ps.has_colors() ? 1 : 0) | (ps.has_radii() ? 2 : 0) |
                         (ps.emission.empty() ? 0 : 4) | (shifted ? 8 : 0);
    w.put(mask);
    w.vec(ps.positions);
    w.vec(ps.normals);
    if (mask & 1) w.vec(ps.colors);
    if (mask & 2) w.vec(ps.radii);
    if (mask & 4) w.vec(ps.emission);
    if (mask & 8) w.put(ps.origin);
    w.end(s);
    s = w.begin("ORDR");
    w.vec(vm.order());
    w.end(s);
    s = w.begin("TREE");
    w.put(int32_t(t.num_nodes()));
    w.put(int32_t(t.num_leaves()));
    w.put(t.root_min());
    w.put(t.root_size());
    w.vec(t.spheres()), w.vec(t.boxes()), w.vec(t.half_size()), w.vec(t.skip()), w.vec(t.parent()),
        w.vec(t.level());
    w.vec(t.node_leaf()), w.vec(t.point_begin()), w.vec(t.point_end()), w.vec(t.leaf_begin());
    w.vec(t.leaf_end()), w.vec(t.leaf_node()), w.vec(leaf_discs(t)), w.vec(t.leaf_splat());
    w.put(t.scale());
    w.end(s);
    s = w.begin("LINK");
    w.vec(vm.link_offsets());
    detail::LinkCoder links(vm.link_offsets(), vm.link_targets());  // sized, coded when written
    w.put(uint64_t(links.chunks()));
    for (uint32_t x : links.links().chunk_node) w.put(x);  // a few per 4M link ends: copied
    for (uint64_t x : links.links().chunk_byte) w.put(x);
    w.take(std::move(links));
    w.end(s);
    w.finish();
}

// The header (magic, version, payload size and checksum), then the payload, through an
// AtomicFile (vmap/files.h). The payload goes out in chunks of 8 MiB at their offsets, in
// parallel (the page cache takes that several times faster than one stream). Each chunk's
// links are coded first where it holds some (LazyLinks), and its 1 MiB blocks are hashed
// just before they are written, while they are in the cache, and the
// chunk's writeback is started at once, so the disk works while later chunks are hashed and
// written and the final fsync waits only for the last few. The header, which holds the hash of
// the whole payload, is written last, at offset 0. Times go to *stats when given.
void write_file(const std::string& path, const Writer& w, SaveStats* stats) {
    using Clock = std::chrono::steady_clock;
    const auto t0 = Clock::now();
    constexpr size_t kChunk = size_t(8) << 20;
    static_assert(kChunk % kBlock == 0);
    std::vector<size_t> at(w.pieces.size() + 1, 0);  // each piece's payload offset
    for (size_t k = 0; k < w.pieces.size(); ++k) at[k + 1] = at[k] + w.pieces[k].n;
    const size_t n = w.size;
    std::vector<uint64_t> hs((n + kBlock - 1) / kBlock);
    io::AtomicFile file(path);
    std::atomic<int> err{0};
    auto note = [&](int e) {
        int zero = 0;
        if (e != 0) err.compare_exchange_strong(zero, e);
    };
    parallel_for((n + kChunk - 1) / kChunk, [&](size_t c) {
        if (err.load() != 0) return;
        const size_t lo = c * kChunk, hi = std::min(n, lo + kChunk);
        // The chunk's pieces: from the one holding lo on.
        const size_t first = size_t(std::upper_bound(at.begin(), at.end(), lo) - at.begin()) - 1;
        for (size_t k = first; k < w.pieces.size() && at[k] < hi; ++k)
            if (w.pieces[k].lazy)
                w.pieces[k].lazy->ready(std::max(lo, at[k]) - at[k], std::min(hi, at[k + 1]) - at[k]);
        std::vector<uint8_t> tmp;
        for (size_t b = lo; b < hi; b += kBlock) {  // the hashes of its blocks
            const size_t len = std::min(kBlock, n - b);
            size_t k = first;
            while (at[k + 1] <= b) ++k;
            if (b + len <= at[k + 1]) {
                hs[b / kBlock] = block_hash(w.pieces[k].p + (b - at[k]), len, b / kBlock);
                continue;
            }
            tmp.resize(len);  // a block that straddles pieces is gathered first
            for (size_t got = 0; got < len; ++k) {
                const size_t from = b + got - at[k];
                const size_t take = std::min(len - got, w.pieces[k].n - from);
                std::memcpy(tmp.data() + got, w.pieces[k].p + from, take);
                got += take;
            }
            hs[b / kBlock] = block_hash(tmp.data(), len, b / kBlock);
        }
        for (size_t k = first; k < w.pieces.size() && at[k] < hi; ++k) {  // its bytes
            const size_t from = std::max(lo, at[k]), to = std::min(hi, at[k + 1]);
            if (from >= to) continue;
            const int e = file.write_at(w.pieces[k].p + (from - at[k]), to - from,
                                        off_t(kHeader + from));
            if (e != 0) return note(e);
        }
        file.start_writeback(off_t(kHeader + lo), hi - lo);
    });
    if (err.load() != 0) file.fail(err.load());
    const uint64_t h = fold_hashes(hs, n);  // payload_hash's
    std::vector<uint8_t> head;
    head.insert(head.end(), kMagic, kMagic + 8);
    auto put = [&](auto v) {
        const auto* p = reinterpret_cast<const uint8_t*>(&v);
        head.insert(head.end(), p, p + sizeof(v));
    };
    put(kVersion);
    put(uint32_t(0));
    put(uint64_t(n));
    put(h);
    if (const int e = file.write_at(head.data(), head.size(), 0)) file.fail(e);
    const auto t1 = Clock::now();
    file.commit();
    if (stats) {
        stats->bytes = kHeader + n;
        stats->write_seconds = std::chrono::duration<double>(t1 - t0).count();
        stats->sync_seconds = std::chrono::duration<double>(Clock::now() - t1).count();
    }
}

}  // namespace

void save_vmap(const std::string& path, const VisibilityMap& vm, SaveStats* stats) {
    const auto t0 = std::chrono::steady_clock::now();
    vm.require_links(path.c_str());
    Writer w;
    write_payload(w, vm);
    if (stats)
        stats->encode_seconds =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    write_file(path, w, stats);
}

namespace {

// A file mapped read-only (no copy into a buffer first: the arrays are copied out of the
// mapping once, in parallel). Throws vmap::Error naming the file.
class MappedFile {
  public:
    explicit MappedFile(const std::string& path) {
        const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
        if (fd < 0) throw Error(fmt::format("{}: cannot open ({})", path, std::strerror(errno)));
        struct stat st {};
        if (::fstat(fd, &st) != 0) {
            ::close(fd);
            throw Error(fmt::format("{}: cannot stat ({})", path, std::strerror(errno)));
        }
        size_ = uint64_t(st.st_size);
        if (size_ > 0) {
            void* p = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE | MAP_POPULATE, fd, 0);
            if (p == MAP_FAILED) {
                ::close(fd);
                throw Error(fmt::format("{}: read error ({})", path, std::strerror(errno)));
            }
            data_ = static_cast<const uint8_t*>(p);
        }
        ::close(fd);
    }
    ~MappedFile() {
        if (data_) ::munmap(const_cast<uint8_t*>(data_), size_);
    }
    MappedFile(const MappedFile&) = delete;
    MappedFile& operator=(const MappedFile&) = delete;
    const uint8_t* data() const { return data_; }
    uint64_t size() const { return size_; }

  private:
    const uint8_t* data_ = nullptr;
    uint64_t size_ = 0;
};

}  // namespace

VisibilityMap load_vmap(const std::string& path) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) throw Error(fmt::format("{}: no such file", path));
    if (!std::filesystem::is_regular_file(path, ec))
        throw Error(fmt::format("{}: not a regular file", path));
    if (mpi::is_shard_index(path)) return mpi::load_sharded(path);  // src/mpi/shard_file.h
    return detail::load_vmap_file(path);
}

namespace {

// The header: magic, version, payload size and checksum against the file's bytes.
uint32_t check_header(const std::string& path, const uint8_t* data, uint64_t size) {
    if (size < kHeader) throw Error(fmt::format("{}: header: truncated ({} bytes)", path, size));
    if (std::memcmp(data, kMagic, 8) != 0)
        throw Error(fmt::format("{}: header: not a .vmap file (bad magic)", path));
    uint32_t version;
    uint64_t payload, sum;
    std::memcpy(&version, data + 8, 4);
    std::memcpy(&payload, data + 16, 8);
    std::memcpy(&sum, data + 24, 8);
    if (version < kOldestRead || version > kVersion)
        throw Error(fmt::format(
            "{}: header: version {} not supported (this vmap reads versions {} to {}); rebuild "
            "it with `vmap build`",
            path, version, kOldestRead, kVersion));
    if (payload != size - kHeader)
        throw Error(fmt::format("{}: truncated: header promises {} payload bytes, file has {}",
                                path, payload, size - kHeader));
    if (detail::payload_hash(data + kHeader, payload) != sum)
        throw Error(fmt::format("{}: checksum mismatch: the file is corrupt", path));
    return version;
}

// PARM, PNTS and ORDR: the parameters, the points and their order (a permutation, checked);
// returns the number of points.
uint64_t read_points(Reader& r, detail::MapData& d, uint32_t version) {
    const uint8_t* e = r.begin_section("PARM");
    d.octree_params.max_height = r.get<int32_t>();
    d.octree_params.leaf_points = r.get<int32_t>();
    d.visibility_params.K = r.get<int32_t>();
    d.visibility_params.eps = r.get<float>();
    d.visibility_params.facing_tol = r.get<float>();
    d.visibility_params.parallel_tol = r.get<float>();
    // Version 4 predates the field: its maps were built with the default floor of the time.
    constexpr float kVersion4DeltaFloor = 2.5f;
    d.octree_params.delta_floor = version >= 5 ? r.get<float>() : kVersion4DeltaFloor;
    if (!(d.octree_params.delta_floor >= 0 &&
          d.octree_params.delta_floor <= OctreeParams::kDeltaFloorLimit))
        r.fail(fmt::format("delta_floor {} out of range", d.octree_params.delta_floor));
    // Versions 4 and 5 predate the end windows: their maps were built without (0).
    d.visibility_params.end_window = version >= 6 ? r.get<float>() : 0.f;
    if (!(d.visibility_params.end_window >= 0 &&
          d.visibility_params.end_window <= VisibilityParams::kEndWindowLimit))
        r.fail(fmt::format("end_window {} out of range", d.visibility_params.end_window));
    // Versions 4 to 6 predate the roughness: their maps were built without (0).
    d.visibility_params.roughness = version >= 7 ? r.get<float>() : 0.f;
    if (!(d.visibility_params.roughness >= 0 && std::isfinite(d.visibility_params.roughness)))
        r.fail(fmt::format("roughness {} out of range", d.visibility_params.roughness));
    // Versions 4 to 7 predate the cores: their maps were built without (0).
    d.visibility_params.core = version >= 8 ? r.get<float>() : 0.f;
    if (!(d.visibility_params.core >= 0 && d.visibility_params.core <= VisibilityParams::kCoreLimit))
        r.fail(fmt::format("core {} out of range", d.visibility_params.core));
    r.end_section(e);

    e = r.begin_section("PNTS");
    const uint64_t n = r.get<uint64_t>();
    const uint8_t mask = r.get<uint8_t>();
    PointSet& ps = d.points;
    r.vec(ps.positions, n);
    r.vec(ps.normals, n);
    if (mask & 1) r.vec(ps.colors, n);
    if (mask & 2) r.vec(ps.radii, n);
    if (mask & 4) r.vec(ps.emission, n);
    if (mask & 8) {
        ps.origin = r.get<std::array<double, 3>>();
        for (double c : ps.origin)
            if (!std::isfinite(c)) r.fail("the points' origin is not finite");
    }
    if (mask & ~15) r.fail(fmt::format("unknown point fields (mask {})", int(mask)));
    r.end_section(e);

    e = r.begin_section("ORDR");
    r.vec(d.order, n);
    r.end_section(e);
    d.inverse.assign(n, UINT32_MAX);
    for (uint32_t k = 0; k < n; ++k) {
        if (d.order[k] >= n || d.inverse[d.order[k]] != UINT32_MAX) r.fail("not a permutation");
        d.inverse[d.order[k]] = k;
    }
    return n;
}

// Structure checks, so that even a well-checksummed but inconsistent file cannot make a query
// index out of bounds.
void check_tree(Reader& r, const detail::OctreeData& t, int32_t nn, int32_t nl, uint64_t n) {
    for (int32_t i = 0; i < nn; ++i) {
        const int want_level =
            i == 0 ? 0 : (t.parent[i] >= 0 && t.parent[i] < i ? t.level[t.parent[i]] + 1 : -1);
        if (t.level[i] != want_level || t.level[i] > 21)
            r.fail(fmt::format("node {} has level {} (its parent's level + 1 expected)", i,
                               int(t.level[i])));
        if (t.skip[i] <= i || t.skip[i] > nn || t.parent[i] >= i || (i > 0 && t.parent[i] < 0) ||
            t.node_leaf[i] >= nl || t.point_begin[i] > t.point_end[i] || t.point_end[i] > n ||
            t.leaf_begin[i] < 0 || t.leaf_begin[i] > t.leaf_end[i] || t.leaf_end[i] > nl)
            r.fail(fmt::format("node {} is inconsistent", i));
    }
    if (t.point_begin[0] != 0 || t.point_end[0] != n) r.fail("the root does not hold every point");
    for (int32_t l = 0; l < nl; ++l)
        if (t.leaf_node[l] < 0 || t.leaf_node[l] >= nn || t.node_leaf[t.leaf_node[l]] != l)
            r.fail(fmt::format("leaf {} is inconsistent", l));
}

// TREE: the octree's arrays, checked; returns the number of nodes.
int32_t read_tree(Reader& r, detail::MapData& d, uint64_t n) {
    const uint8_t* e = r.begin_section("TREE");
    detail::OctreeData& t = detail::OctreeAccess::data(d.octree);
    const int32_t nn = r.get<int32_t>(), nl = r.get<int32_t>();
    if (nn < 1 || nl < 1 || nl > nn) r.fail(fmt::format("bad counts: {} nodes, {} leaves", nn, nl));
    t.params = d.octree_params;
    t.root_min = r.get<Vec3>();
    t.root_size = r.get<float>();
    r.vec(t.spheres, nn), r.vec(t.boxes, nn), r.vec(t.half_size, nn), r.vec(t.skip, nn),
        r.vec(t.parent, nn);
    r.vec(t.level, nn), r.vec(t.node_leaf, nn), r.vec(t.point_begin, nn), r.vec(t.point_end, nn);
    r.vec(t.leaf_begin, nn), r.vec(t.leaf_end, nn), r.vec(t.leaf_node, nl), r.vec(t.leaves, nl);
    r.vec(t.leaf_splat, nl);
    t.scale = r.get<double>();
    int exponent = 0;
    if (!(t.scale > 0) || !std::isfinite(t.scale) || std::frexp(t.scale, &exponent) != 0.5)
        r.fail(fmt::format("scale {} is not a power of two", t.scale));
    r.end_section(e);
    check_tree(r, t, nn, nl, n);
    detail::OctreeAccess::pack_walk(d.octree);
    return nn;
}

// Version 4's targets: raw i32 node ids.
void read_raw_targets(Reader& r, detail::MapData& d, int32_t nn) {
    const uint64_t num_targets = d.link_offsets[size_t(nn)];
    if (num_targets > uint64_t(r.end - r.p) / sizeof(int32_t))
        r.fail(fmt::format("truncated: {} items expected", num_targets));
    int32_t* targets = detail::allocate_link_targets(d, num_targets);
    copy_bytes(reinterpret_cast<uint8_t*>(targets), r.p, num_targets * sizeof(int32_t));
    r.p += num_targets * sizeof(int32_t);
    for (uint64_t i = 0; i < num_targets; ++i)
        if (targets[i] < 0 || targets[i] >= nn) r.fail("link target out of range");
}

// Version 5's targets: the chunk table, checked, then the coded streams (io/link_codec.h).
void read_coded_targets(Reader& r, detail::MapData& d, int32_t nn) {
    const uint64_t chunks = r.get<uint64_t>();
    if (chunks < 1 || chunks > uint64_t(nn)) r.fail(fmt::format("bad chunk count {}", chunks));
    std::vector<uint32_t> chunk_node;
    std::vector<uint64_t> chunk_byte;
    r.vec(chunk_node, chunks + 1);
    r.vec(chunk_byte, chunks + 1);
    if (chunk_node[0] != 0 || chunk_node[chunks] != uint32_t(nn) || chunk_byte[0] != 0)
        r.fail("bad chunk table");
    for (uint64_t k = 0; k < chunks; ++k)
        if (chunk_node[k + 1] <= chunk_node[k] || chunk_byte[k + 1] < chunk_byte[k])
            r.fail("bad chunk table");
    const uint64_t bytes = chunk_byte[chunks];
    if (bytes > uint64_t(r.end - r.p)) r.fail(fmt::format("truncated: {} bytes expected", bytes));
    // Every value takes at least one byte: a count beyond the stream is corrupt (and no
    // allocation follows from it).
    const uint64_t num_targets = d.link_offsets[size_t(nn)];
    if (num_targets > bytes) r.fail(fmt::format("{} link ends in {} bytes", num_targets, bytes));
    int32_t* targets = detail::allocate_link_targets(d, num_targets);
    const std::string err =
        detail::decode_links(d.link_offsets, chunk_node, chunk_byte, r.p, targets);
    if (!err.empty()) r.fail(err);
    r.p += bytes;
}

// LINK: the offsets (non-decreasing from 0) and the targets (node ids, sorted per node).
void read_links(Reader& r, VisibilityMap& vm, int32_t nn, uint32_t version) {
    detail::MapData& d = detail::MapAccess::data(vm);
    const uint8_t* e = r.begin_section("LINK");
    r.vec(d.link_offsets, uint64_t(nn) + 1);
    if (d.link_offsets[0] != 0) r.fail("bad offsets");
    for (int32_t i = 0; i < nn; ++i)
        if (d.link_offsets[i + 1] < d.link_offsets[i]) r.fail("bad offsets");
    if (version >= 5)
        read_coded_targets(r, d, nn);
    else
        read_raw_targets(r, d, nn);
    r.end_section(e);
}

}  // namespace

VisibilityMap detail::load_vmap_file(const std::string& path) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec))
        throw Error(fmt::format("{}: not a regular file (or no such file)", path));
    const MappedFile data(path);
    const uint64_t size = data.size();
    const uint32_t version = check_header(path, data.data(), size);
    VisibilityMap vm;
    detail::MapData& d = detail::MapAccess::data(vm);
    Reader r{data.data() + kHeader, data.data() + size, path, "header"};
    const uint64_t n = read_points(r, d, version);
    const int32_t nn = read_tree(r, d, n);
    read_links(r, vm, nn, version);
    if (r.p != r.end) throw Error(fmt::format("{}: trailing bytes after the last section", path));
    return vm;
}

}  // namespace vmap
