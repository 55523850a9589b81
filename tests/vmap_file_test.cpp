// The .vmap file: exact round trips, and truncated, corrupt, wrong-version or missing files, and
// writes that never leave half a file behind.
#include "vmap/map_access.h"
#include "octree/records.h"
#include "io/vmap_file.h"
#include "io/link_codec.h"
#include "vmap/build_parts.h"

#include <gtest/gtest.h>
#include <streamvbytedelta.h>
#include <streamvbyte.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <random>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "test_files.h"
#include "vmap/error.h"
#include "vmap/scene.h"
#include "vmap/vmap.h"

namespace vmap {
namespace {

namespace fs = std::filesystem;

constexpr size_t kHeaderBytes = 8 + 4 + 4 + 8 + 8;  // magic, version, reserved, size, checksum

using test::expect_error;
using test::ScratchDir;
using test::slurp;
using test::spit;

// After editing the payload of a file image: writes it to `name` in `dir` with the header's size
// and checksum set to match, so that only the loader's structure checks stand between the edit
// and a query. Returns the path.
std::string write_resealed(const ScratchDir& dir, const std::string& name, std::string bytes) {
    const uint64_t payload = bytes.size() - kHeaderBytes;
    const uint64_t sum = detail::payload_hash(
        reinterpret_cast<const uint8_t*>(bytes.data()) + kHeaderBytes, payload);
    std::memcpy(bytes.data() + 16, &payload, 8);
    std::memcpy(bytes.data() + 24, &sum, 8);
    const std::string p = dir.path(name);
    spit(p, bytes);
    return p;
}

// Byte offset of section `tag`'s data (just past its tag and length) in a file image.
size_t section_data(const std::string& bytes, const char* tag) {
    size_t p = kHeaderBytes;
    while (p + 12 <= bytes.size()) {
        uint64_t len;
        std::memcpy(&len, bytes.data() + p + 4, 8);
        if (bytes.compare(p, 4, tag) == 0) return p + 12;
        p += 12 + len;
    }
    ADD_FAILURE() << "no section " << tag;
    return 0;
}

// Cuts the last `bytes` bytes of the PARM section of a file image (an older version's PARM).
void drop_parm_tail(std::string& out, size_t bytes) {
    const size_t parm = section_data(out, "PARM");
    uint64_t n;
    std::memcpy(&n, out.data() + parm - 8, 8);
    out.erase(parm + n - bytes, bytes);
    n -= bytes;
    std::memcpy(out.data() + parm - 8, &n, 8);
}

// A file image with its LINK section (the last one) replaced by one holding `offsets` and
// `targets`, coded (version 8) or raw (version 4, the header's version set to match).
std::string with_links(const std::string& bytes, std::span<const uint64_t> offsets,
                       std::span<const int32_t> targets, bool raw) {
    std::string out = bytes.substr(0, section_data(bytes, "LINK") - 12);
    // version 4's PARM ends before delta_floor, end_window, roughness and core (the last 16
    // bytes of version 8's)
    if (raw) drop_parm_tail(out, 16);
    auto put = [&](const void* p, size_t n) { out.append(static_cast<const char*>(p), n); };
    std::string body;
    body.append(reinterpret_cast<const char*>(offsets.data()), offsets.size() * 8);
    if (raw) {
        body.append(reinterpret_cast<const char*>(targets.data()), targets.size() * 4);
    } else {
        const detail::EncodedLinks e = detail::encode_links(offsets, targets);
        const uint64_t chunks = e.chunk_node.size() - 1;
        body.append(reinterpret_cast<const char*>(&chunks), 8);
        body.append(reinterpret_cast<const char*>(e.chunk_node.data()), e.chunk_node.size() * 4);
        body.append(reinterpret_cast<const char*>(e.chunk_byte.data()), e.chunk_byte.size() * 8);
        body.append(reinterpret_cast<const char*>(e.stream.data()), e.stream.size());
    }
    const uint64_t len = body.size();
    put("LINK", 4), put(&len, 8);
    out += body;
    const uint32_t version = raw ? 4 : 8;
    std::memcpy(out.data() + 8, &version, 4);
    return out;
}

#define EXPECT_LOAD_ERROR(path, ...)                                       \
    do {                                                                   \
        SCOPED_TRACE(path);                                                \
        expect_error([&] { (void)load_vmap(path); }, {path, __VA_ARGS__}); \
    } while (0)

// ---- field-by-field comparison -------------------------------------------------------------

template <class T>
void expect_same_bytes(std::span<const T> a, std::span<const T> b, const char* what) {
    ASSERT_EQ(a.size(), b.size()) << what;
    if (a.empty()) return;
    EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(T)), 0) << what << " differ";
}
template <class T>
void expect_same_bytes(const std::vector<T>& a, const std::vector<T>& b, const char* what) {
    expect_same_bytes(std::span<const T>(a), std::span<const T>(b), what);
}

void expect_same_map(const VisibilityMap& a, const VisibilityMap& b) {
    EXPECT_EQ(a.octree_params().max_height, b.octree_params().max_height);
    EXPECT_EQ(a.octree_params().leaf_points, b.octree_params().leaf_points);
    EXPECT_EQ(a.octree_params().delta_floor, b.octree_params().delta_floor);
    EXPECT_EQ(a.visibility_params().K, b.visibility_params().K);
    EXPECT_EQ(a.visibility_params().eps, b.visibility_params().eps);
    EXPECT_EQ(a.visibility_params().facing_tol, b.visibility_params().facing_tol);
    EXPECT_EQ(a.visibility_params().parallel_tol, b.visibility_params().parallel_tol);
    EXPECT_EQ(a.visibility_params().end_window, b.visibility_params().end_window);
    EXPECT_EQ(a.visibility_params().roughness, b.visibility_params().roughness);
    EXPECT_EQ(a.visibility_params().core, b.visibility_params().core);

    expect_same_bytes(a.points().positions, b.points().positions, "positions");
    expect_same_bytes(a.points().normals, b.points().normals, "normals");
    expect_same_bytes(a.points().colors, b.points().colors, "colours");
    expect_same_bytes(a.points().radii, b.points().radii, "radii");
    expect_same_bytes(a.points().emission, b.points().emission, "emission");
    expect_same_bytes(a.order(), b.order(), "order");
    expect_same_bytes(a.inverse(), b.inverse(), "inverse");

    const Octree &s = a.octree(), &t = b.octree();
    EXPECT_EQ(s.params().max_height, t.params().max_height);
    EXPECT_EQ(s.params().leaf_points, t.params().leaf_points);
    EXPECT_EQ(s.params().delta_floor, t.params().delta_floor);
    EXPECT_EQ(s.root_min(), t.root_min());
    EXPECT_EQ(s.root_size(), t.root_size());
    EXPECT_EQ(s.scale(), t.scale());
    EXPECT_EQ(s.num_nodes(), t.num_nodes());
    EXPECT_EQ(s.num_leaves(), t.num_leaves());
    EXPECT_EQ(s.height(), t.height());
    expect_same_bytes(s.spheres(), t.spheres(), "spheres");
    expect_same_bytes(s.half_size(), t.half_size(), "half_size");
    expect_same_bytes(s.skip(), t.skip(), "skip");
    expect_same_bytes(s.parent(), t.parent(), "parent");
    expect_same_bytes(s.level(), t.level(), "level");
    expect_same_bytes(s.node_leaf(), t.node_leaf(), "node_leaf");
    expect_same_bytes(s.point_begin(), t.point_begin(), "point_begin");
    expect_same_bytes(s.point_end(), t.point_end(), "point_end");
    expect_same_bytes(s.leaf_begin(), t.leaf_begin(), "leaf_begin");
    expect_same_bytes(s.leaf_end(), t.leaf_end(), "leaf_end");
    expect_same_bytes(s.leaf_node(), t.leaf_node(), "leaf_node");
    expect_same_bytes(leaf_discs(s), leaf_discs(t), "leaves");
    expect_same_bytes(s.leaf_splat(), t.leaf_splat(), "leaf_splat");

    expect_same_bytes(a.link_offsets(), b.link_offsets(), "link_offsets");
    expect_same_bytes(a.link_targets(), b.link_targets(), "link_targets");
    EXPECT_EQ(a.num_links(), b.num_links());
}

// ---- one small V-map, built once ------------------------------------------------------------

class VmapFile : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        Scene sc = load_scene(std::string(VMAP_SOURCE_DIR) + "/scenes/cornell-empty.json");
        sc.points = 1500;
        BuildParams bp;
        bp.backend = Backend::kCpu;
        bp.octree.max_height = 5;
        bp.octree.leaf_points = 4;
        bp.visibility.K = 3;  // not the default, so a lost parameter shows
        bp.octree.delta_floor = 2.25f;
        bp.visibility.end_window = 1.5f;
        bp.visibility.roughness = 0.002f;  // a scan's, kept through the file
        bp.visibility.core = 0.25f;        // not the default either
        map_ = std::make_unique<VisibilityMap>(build_vmap(sample_scene(sc), bp, nullptr, "test"));
    }
    static void TearDownTestSuite() { map_.reset(); }

    static const VisibilityMap& map() { return *map_; }

    // The map saved under `name` in `dir`; returns the path.
    static std::string saved(const ScratchDir& dir, const std::string& name = "map.vmap") {
        const std::string p = dir.path(name);
        save_vmap(p, map());
        return p;
    }

  private:
    static inline std::unique_ptr<VisibilityMap> map_;
};

TEST_F(VmapFile, TheTestMapIsNotTrivial) {
    EXPECT_EQ(map().points().size(), 1500u);
    EXPECT_GT(map().octree().num_leaves(), 50);
    EXPECT_GT(map().num_links(), 10u);
    EXPECT_EQ(map().octree_params().max_height, 5);
    EXPECT_EQ(map().visibility_params().K, 3);
    EXPECT_FALSE(map().points().colors.empty());
    EXPECT_FALSE(map().points().radii.empty());
    EXPECT_FALSE(map().points().emission.empty());
}

TEST_F(VmapFile, RoundTripKeepsEveryField) {
    ScratchDir dir;
    const VisibilityMap back = load_vmap(saved(dir));
    expect_same_map(map(), back);
}

TEST_F(VmapFile, RoundTripAnswersEveryQueryTheSame) {
    ScratchDir dir;
    const VisibilityMap back = load_vmap(saved(dir));
    const uint32_t n = uint32_t(map().points().size());
    size_t differ = 0, visible = 0, hidden = 0;
    for (uint32_t i = 0; i < n; ++i) {
        for (uint32_t j = 0; j < n; j += 3) {
            const PairVisibility a = map().query(i, j), b = back.query(i, j);
            if (a != b && differ++ < 5) ADD_FAILURE() << "query(" << i << ", " << j << ") differs";
            visible += a == PairVisibility::kVisible;
            hidden += a == PairVisibility::kHidden;
        }
    }
    EXPECT_EQ(differ, 0u);
    EXPECT_GT(visible, 0u);
    EXPECT_GT(hidden, 0u);
    for (uint32_t i = 0; i < n; i += 7) ASSERT_EQ(map().visible_set(i), back.visible_set(i)) << i;
}

TEST_F(VmapFile, SavingTheSameMapTwiceGivesTheSameBytes) {
    ScratchDir dir;
    const std::string a = slurp(saved(dir, "a.vmap")), b = slurp(saved(dir, "b.vmap"));
    EXPECT_EQ(a, b);
    // And a loaded map saves back to the same bytes.
    save_vmap(dir.path("c.vmap"), load_vmap(dir.path("a.vmap")));
    EXPECT_EQ(a, slurp(dir.path("c.vmap")));
}

// A file of several of the writer's 8 MiB chunks, whose 1 MiB checksum blocks straddle the
// pieces it is written from: the header holds the hash of the payload as one buffer
// (payload_hash), the stats give the file's size, and it loads back whole.
TEST(VmapFileChunks, AFileOfManyChunksHoldsTheChecksumOfItsWholePayload) {
    Scene sc = load_scene(std::string(VMAP_SOURCE_DIR) + "/scenes/cornell-empty.json");
    sc.points = 600000;
    sc.pattern = SamplePattern::kUniform;  // quick; the file's size is what matters here
    BuildParams bp;
    bp.backend = Backend::kCpu;
    bp.octree.max_height = 3;
    bp.octree.leaf_points = 64;
    const VisibilityMap vm = build_vmap(sample_scene(sc), bp, nullptr, "test");
    ScratchDir dir;
    const std::string p = dir.path("big.vmap");
    SaveStats ss;
    save_vmap(p, vm, &ss);
    const std::string bytes = slurp(p);
    EXPECT_EQ(ss.bytes, bytes.size());
    ASSERT_GT(bytes.size(), size_t(3) << 23);  // more than three chunks
    EXPECT_GE(ss.encode_seconds, 0.0);
    EXPECT_GT(ss.write_seconds, 0.0);
    EXPECT_GE(ss.sync_seconds, 0.0);
    uint64_t size = 0, sum = 0;
    std::memcpy(&size, bytes.data() + 16, 8);
    std::memcpy(&sum, bytes.data() + 24, 8);
    EXPECT_EQ(size, bytes.size() - kHeaderBytes);
    EXPECT_EQ(sum, detail::payload_hash(reinterpret_cast<const uint8_t*>(bytes.data()) + kHeaderBytes,
                                        bytes.size() - kHeaderBytes));
    expect_same_map(vm, load_vmap(p));
}

TEST_F(VmapFile, AMapWithoutColoursRadiiOrEmissionRoundTrips) {
    // Points with normals only: the optional arrays must stay absent, not come back empty-sized
    // or filled in.
    PointSet ps;
    for (int i = 0; i < 200; ++i) {
        const float x = float(i % 20) * 0.01f, z = float(i / 20) * 0.01f;
        ps.positions.push_back({x, 0, z});
        ps.normals.push_back({0, 1, 0});
        ps.positions.push_back({x, 0.3f, z});
        ps.normals.push_back({0, -1, 0});
    }
    BuildParams bp;
    bp.backend = Backend::kCpu;
    bp.octree.max_height = 4;
    const VisibilityMap vm = build_vmap(ps, bp, nullptr, "plates");
    ScratchDir dir;
    save_vmap(dir.path("plates.vmap"), vm);
    const VisibilityMap back = load_vmap(dir.path("plates.vmap"));
    expect_same_map(vm, back);
    EXPECT_EQ(back.points().colors.empty(), vm.points().colors.empty());
    EXPECT_EQ(back.points().radii.empty(), vm.points().radii.empty());
    EXPECT_TRUE(back.points().emission.empty());
}

// ---- bad files -----------------------------------------------------------------------------

TEST_F(VmapFile, TruncatedFilesAreRejectedNamingTheFile) {
    ScratchDir dir;
    const std::string whole = slurp(saved(dir));
    ASSERT_GT(whole.size(), 1000u);
    for (size_t cut : {size_t(0), size_t(10), kHeaderBytes, whole.size() / 2, whole.size() - 1}) {
        SCOPED_TRACE(::testing::Message() << "cut at " << cut << " of " << whole.size());
        const std::string p = dir.path("cut_" + std::to_string(cut) + ".vmap");
        spit(p, std::string_view(whole).substr(0, cut));
        EXPECT_LOAD_ERROR(p, "truncated");
    }
}

TEST_F(VmapFile, ATruncatedFileWithAMatchingHeaderIsRejected) {
    // Cut in the middle of the last section, with the header's size and checksum made to
    // match: the section reader must notice.
    ScratchDir dir;
    std::string bytes = slurp(saved(dir));
    bytes.resize(bytes.size() - 6);
    const std::string p = write_resealed(dir, "resealed.vmap", bytes);
    EXPECT_LOAD_ERROR(p, "LINK");
}

TEST_F(VmapFile, AFlippedPayloadByteFailsTheChecksum) {
    ScratchDir dir;
    const std::string whole = slurp(saved(dir));
    for (size_t at : {kHeaderBytes, kHeaderBytes + 1000, whole.size() / 2, whole.size() - 1}) {
        SCOPED_TRACE(::testing::Message() << "byte " << at);
        std::string bytes = whole;
        bytes[at] = char(bytes[at] ^ 0x10);
        const std::string p = dir.path("flipped_" + std::to_string(at) + ".vmap");
        spit(p, bytes);
        EXPECT_LOAD_ERROR(p, "checksum");
    }
}

TEST_F(VmapFile, AFlippedChecksumByteFailsTheChecksum) {
    ScratchDir dir;
    std::string bytes = slurp(saved(dir));
    bytes[24] = char(bytes[24] ^ 0x01);
    const std::string p = dir.path("sum.vmap");
    spit(p, bytes);
    EXPECT_LOAD_ERROR(p, "checksum");
}

TEST_F(VmapFile, BadMagicIsRejected) {
    ScratchDir dir;
    std::string bytes = slurp(saved(dir));
    bytes[0] = 'X';
    const std::string p = dir.path("magic.vmap");
    spit(p, bytes);
    EXPECT_LOAD_ERROR(p, "magic");

    // A different kind of file altogether.
    const std::string ply = dir.path("cloud.vmap");
    spit(ply, "ply\nformat ascii 1.0\nelement vertex 0\nend_header\n");
    EXPECT_LOAD_ERROR(ply, "magic");
}

TEST_F(VmapFile, AnotherVersionIsRejectedNamingTheVersion) {
    ScratchDir dir;
    const std::string whole = slurp(saved(dir));
    for (uint32_t version : {0u, 1u, 2u, 3u, 9u, 0xffffffffu}) {
        SCOPED_TRACE(version);
        std::string bytes = whole;
        std::memcpy(bytes.data() + 8, &version, 4);
        const std::string p = dir.path("v" + std::to_string(version) + ".vmap");
        spit(p, bytes);
        EXPECT_LOAD_ERROR(p, "version", std::to_string(version));
    }
}

TEST_F(VmapFile, AMissingFileIsNamed) {
    ScratchDir dir;
    const std::string p = dir.path("there_is_no.vmap");
    EXPECT_LOAD_ERROR(p);
}

TEST_F(VmapFile, ADirectoryIsNotAVmapFile) {
    ScratchDir dir;
    fs::create_directories(dir.path("a_directory.vmap"));
    const std::string p = dir.path("a_directory.vmap");
    EXPECT_LOAD_ERROR(p);
}

TEST_F(VmapFile, TrailingBytesAreRejected) {
    ScratchDir dir;
    std::string bytes = slurp(saved(dir));
    bytes += std::string(8, '\0');
    const std::string p = write_resealed(dir, "trailing.vmap", bytes);
    EXPECT_LOAD_ERROR(p, "trailing");
}

TEST_F(VmapFile, AHugePointCountIsRejectedNotAllocated) {
    ScratchDir dir;
    std::string bytes = slurp(saved(dir));
    const size_t at = section_data(bytes, "PNTS");
    for (uint64_t n : {uint64_t(1) << 40, ~uint64_t(0)}) {
        SCOPED_TRACE(n);
        std::memcpy(bytes.data() + at, &n, 8);
        const std::string p = write_resealed(dir, "huge.vmap", bytes);
        EXPECT_LOAD_ERROR(p, "PNTS");
    }
}

TEST_F(VmapFile, AnOrderThatIsNotAPermutationIsRejected) {
    ScratchDir dir;
    std::string bytes = slurp(saved(dir));
    const size_t at = section_data(bytes, "ORDR");
    std::memcpy(bytes.data() + at + 4, bytes.data() + at, 4);  // order[1] = order[0]
    const std::string p = write_resealed(dir, "order.vmap", bytes);
    EXPECT_LOAD_ERROR(p, "ORDR", "permutation");
}

TEST_F(VmapFile, ALinkTargetOutOfRangeIsRejected) {
    ScratchDir dir;
    const std::string bytes = slurp(saved(dir));
    const auto& off = map().link_offsets();
    ASSERT_GT(map().link_targets().size(), 0u);
    for (bool raw : {false, true}) {
        for (int32_t bad : {-1, map().octree().num_nodes(), INT32_MAX}) {
            SCOPED_TRACE(::testing::Message() << "raw " << raw << ", target " << bad);
            std::vector<int32_t> t(map().link_targets().begin(), map().link_targets().end());
            t.back() = bad;  // the last node with links: still sorted, as unsigned values
            const std::string p = write_resealed(dir, "link.vmap", with_links(bytes, off, t, raw));
            EXPECT_LOAD_ERROR(p, "LINK", "out of range");
        }
    }
}

TEST_F(VmapFile, UnsortedLinksAreRejected) {
    ScratchDir dir;
    const auto& off = map().link_offsets();
    std::vector<int32_t> t(map().link_targets().begin(), map().link_targets().end());
    size_t n = 0;
    while (n + 1 < off.size() && off[n + 1] - off[n] < 2) ++n;
    ASSERT_LT(n + 1, off.size()) << "no node with two links";
    std::swap(t[off[n]], t[off[n] + 1]);
    const std::string p =
        write_resealed(dir, "unsorted.vmap", with_links(slurp(saved(dir)), off, t, false));
    EXPECT_LOAD_ERROR(p, "LINK", "not sorted");
}

TEST_F(VmapFile, ACorruptLinkStreamIsRejected) {
    // Control bytes that promise more (or fewer) data bytes than the node's stream holds, with
    // the checksum resealed: the decoder must notice before it reads past the section.
    ScratchDir dir;
    const std::string whole = slurp(saved(dir));
    const size_t at = section_data(whole, "LINK") + (map().octree().num_nodes() + 1) * 8;
    uint64_t chunks;
    std::memcpy(&chunks, whole.data() + at, 8);
    const size_t stream = at + 8 + (chunks + 1) * 12;
    for (uint8_t key : {uint8_t(0x00), uint8_t(0xff)}) {
        SCOPED_TRACE(int(key));
        std::string bytes = whole;
        ASSERT_NE(uint8_t(bytes[stream]), key) << "pick another control byte";
        bytes[stream] = char(key);
        const std::string p = write_resealed(dir, "stream.vmap", bytes);
        EXPECT_LOAD_ERROR(p, "LINK");
    }
    std::string bytes = whole;
    const uint64_t too_many = UINT64_MAX / 2;  // the chunk count
    std::memcpy(bytes.data() + at, &too_many, 8);
    EXPECT_LOAD_ERROR(write_resealed(dir, "chunks.vmap", bytes), "LINK", "chunk");
}

TEST_F(VmapFile, AVersion4FileWithRawLinksStillLoads) {
    ScratchDir dir;
    const auto& off = map().link_offsets();
    const auto t = map().link_targets();
    const std::string p = write_resealed(
        dir, "v4.vmap", with_links(slurp(saved(dir)), off, std::vector<int32_t>(t.begin(), t.end()), true));
    const VisibilityMap back = load_vmap(p);
    EXPECT_EQ(back.link_offsets(), off);
    expect_same_bytes(back.link_targets(), t, "link targets");
    // Version 4 had no delta_floor: its maps were built with the default of the time, 2.5
    // (today's kDefaultDeltaFloor is 2.25).
    EXPECT_EQ(back.octree_params().delta_floor, 2.5f);
    EXPECT_EQ(back.octree_params().leaf_points, map().octree_params().leaf_points);
}

// The saved map as an older version would have written it: PARM cut by `tail` bytes and the
// header's version set, loaded back.
VisibilityMap as_older_version(const ScratchDir& dir, const std::string& whole, size_t tail,
                               uint32_t version) {
    std::string bytes = whole;
    drop_parm_tail(bytes, tail);
    std::memcpy(bytes.data() + 8, &version, 4);
    return load_vmap(write_resealed(dir, "v" + std::to_string(version) + ".vmap", bytes));
}

// Each bad value written into the PARM float `from_end` bytes before the section's end is
// refused naming PARM and `field`.
void expect_parm_float_rejected(const ScratchDir& dir, const std::string& whole, size_t from_end,
                                const char* field, std::initializer_list<float> bad_values) {
    std::string bytes = whole;
    const size_t parm = section_data(bytes, "PARM");
    uint64_t n;
    std::memcpy(&n, bytes.data() + parm - 8, 8);
    for (float bad : bad_values) {
        SCOPED_TRACE(bad);
        std::memcpy(bytes.data() + parm + n - from_end, &bad, 4);
        EXPECT_LOAD_ERROR(write_resealed(dir, std::string(field) + ".vmap", bytes), "PARM", field);
    }
}

// PARM ends with delta_floor (version 5), end_window (6), roughness (7) and core (8), 4 bytes
// each.
TEST_F(VmapFile, AVersion5FileLoadsWithoutEndWindows) {
    ScratchDir dir;
    const VisibilityMap back = as_older_version(dir, slurp(saved(dir)), 12, 5);
    EXPECT_EQ(back.visibility_params().end_window, 0.f);
    EXPECT_EQ(back.octree_params().delta_floor, map().octree_params().delta_floor);
    EXPECT_EQ(back.link_offsets(), map().link_offsets());
}

TEST_F(VmapFile, AVersion6FileLoadsWithoutRoughness) {
    ScratchDir dir;
    const VisibilityMap back = as_older_version(dir, slurp(saved(dir)), 8, 6);
    EXPECT_EQ(back.visibility_params().roughness, 0.f);
    EXPECT_EQ(back.visibility_params().end_window, map().visibility_params().end_window);
    EXPECT_EQ(back.link_offsets(), map().link_offsets());
}

TEST_F(VmapFile, AVersion7FileLoadsWithoutCores) {
    ScratchDir dir;
    const VisibilityMap back = as_older_version(dir, slurp(saved(dir)), 4, 7);
    EXPECT_EQ(back.visibility_params().core, 0.f);
    EXPECT_EQ(back.visibility_params().roughness, map().visibility_params().roughness);
    EXPECT_EQ(back.link_offsets(), map().link_offsets());
}

TEST_F(VmapFile, PredicateParametersOutOfRangeAreRejected) {
    ScratchDir dir;
    const std::string whole = slurp(saved(dir));
    constexpr float kNaN = std::numeric_limits<float>::quiet_NaN(),
                    kInf = std::numeric_limits<float>::infinity();
    expect_parm_float_rejected(dir, whole, 12, "end_window", {-1.f, 1e6f, kNaN});
    expect_parm_float_rejected(dir, whole, 8, "roughness", {-1.f, kInf, kNaN});
    expect_parm_float_rejected(dir, whole, 4, "core", {-0.5f, 1.5f, kNaN});
}

// PNTS: the byte after the point count is the fields' mask (1 colours, 2 radii, 4 emission,
// 8 origin); an unknown bit, or an origin that is not finite, is refused naming PNTS.
TEST_F(VmapFile, UnknownPointFieldsOrANonFiniteOriginAreRejected) {
    ScratchDir dir;
    const std::string bytes = slurp(saved(dir));
    const size_t pnts = section_data(bytes, "PNTS");
    std::string bad = bytes;
    bad[pnts + 8] = char(uint8_t(bad[pnts + 8]) | 16);
    EXPECT_LOAD_ERROR(write_resealed(dir, "mask.vmap", bad), "PNTS", "unknown point fields");
    // A map with an origin (a far cloud's): its last 24 bytes of PNTS are the origin.
    Scene sc = load_scene(std::string(VMAP_SOURCE_DIR) + "/scenes/cornell-empty.json");
    sc.points = 300;
    BuildParams bp;
    bp.backend = Backend::kCpu;
    bp.octree.max_height = 4;
    VisibilityMap far = build_vmap(sample_scene(sc), bp, nullptr, "test");
    detail::MapAccess::data(far).points.origin = {512345, 4123456, 210};
    const std::string p = dir.path("far.vmap");
    save_vmap(p, far);
    EXPECT_EQ(load_vmap(p).points().origin, far.points().origin);
    std::string nan = slurp(p);
    const size_t at = section_data(nan, "PNTS");
    uint64_t len;
    std::memcpy(&len, nan.data() + at - 8, 8);
    const double inf = std::numeric_limits<double>::infinity();
    std::memcpy(nan.data() + at + len - 24, &inf, 8);
    EXPECT_LOAD_ERROR(write_resealed(dir, "nan.vmap", nan), "PNTS", "origin is not finite");
}

TEST_F(VmapFile, LinksAreStoredInUnderHalfTheirRawSize) {
    ScratchDir dir;
    const std::string bytes = slurp(saved(dir));
    const size_t link = section_data(bytes, "LINK");
    const size_t coded = bytes.size() - link - map().link_offsets().size() * 8;
    const size_t raw = map().link_targets().size() * 4;
    EXPECT_LT(coded, raw / 2) << coded << " bytes coded, " << raw << " raw";
}

TEST(LinkCodec, StreamLengthsMatchTheEncoder) {
    std::mt19937 rng(7);
    for (uint32_t count : {1u, 2u, 3u, 4u, 5u, 7u, 8u, 9u, 100u, 1027u}) {
        for (uint32_t width : {8u, 16u, 24u, 31u}) {
            SCOPED_TRACE(::testing::Message() << count << " values below 2^" << width);
            std::vector<uint32_t> v(count);
            for (auto& x : v) x = rng() & ((1u << width) - 1);
            std::vector<uint8_t> buf(streamvbyte_max_compressedbytes(count));
            const size_t n = streamvbyte_encode(v.data(), count, buf.data());
            EXPECT_EQ(detail::stream_bytes(buf.data(), n, count), n);
            EXPECT_EQ(detail::stream_bytes(buf.data(), n - 1, count), SIZE_MAX);
        }
    }
}

// encode_links counts each chunk's bytes before coding it with its own coder: the count and the
// bytes must be the library's; decode_links' decoder must read the library's streams.
TEST(LinkCodec, CountedLengthsAndOurCodersBytesMatchTheLibrary) {
    std::mt19937 rng(9);
    for (uint32_t count : {0u, 1u, 2u, 3u, 4u, 5u, 8u, 9u, 100u, 1027u}) {
        for (uint32_t width : {1u, 8u, 9u, 16u, 17u, 24u, 25u, 31u}) {
            SCOPED_TRACE(::testing::Message() << count << " gaps below 2^" << width);
            std::vector<uint32_t> v(count);
            uint32_t at = 0;
            for (auto& x : v) {  // increasing; gaps at and around the byte boundaries too
                const uint32_t r = rng() % 4;
                const uint32_t gap = r == 0   ? (1u << (width - 1))
                                     : r == 1 ? (1u << (width - 1)) - 1
                                              : rng() & ((1u << (width - 1)) - 1);
                if (uint64_t(at) + gap < 0x7fffffffu) at += gap;  // a node id stays an int32
                x = at;
            }
            std::vector<uint8_t> lib(streamvbyte_max_compressedbytes(count) + 1);
            const size_t n = streamvbyte_delta_encode(v.data(), count, lib.data(), 0);
            EXPECT_EQ(detail::delta_stream_bytes(v.data(), count), n);
            // Our coder: the library's bytes, and nothing written past the stream's 3 spare bytes.
            std::vector<uint8_t> ours(n + 3 + 16, 0xa5);
            EXPECT_EQ(detail::encode_delta_stream(v.data(), count, ours.data()), n);
            EXPECT_TRUE(std::equal(lib.begin(), lib.begin() + ptrdiff_t(n), ours.begin()));
            for (size_t i = n + 3; i < ours.size(); ++i) ASSERT_EQ(ours[i], 0xa5) << i;
            // Our decoder gives the values back, the stream at the very end of its buffer (so
            // its last gaps are read byte by byte) and with room after it.
            std::vector<uint8_t> tight(lib.begin(), lib.begin() + ptrdiff_t(n));
            std::vector<uint32_t> back(count, 7), back2(count, 7);
            detail::decode_delta_stream(tight.data(), tight.data() + n, count, back.data());
            EXPECT_EQ(back, v);
            detail::decode_delta_stream(lib.data(), lib.data() + lib.size(), count, back2.data());
            EXPECT_EQ(back2, v);
        }
    }
}

TEST(LinkCodec, RandomListsRoundTrip) {
    // Empty nodes, one huge node, many chunks (over 2^22 ends), gaps of every width.
    std::mt19937 rng(11);
    const int32_t nn = 300000;
    std::vector<uint64_t> off{0};
    std::vector<int32_t> t;
    for (int32_t n = 0; n < nn; ++n) {
        const uint32_t deg = n == 777 ? 150000 : (rng() % 4 == 0 ? 0 : rng() % 60);
        std::vector<int32_t> mine(deg);
        for (auto& x : mine) x = int32_t(rng() % uint32_t(nn));
        std::sort(mine.begin(), mine.end());
        mine.erase(std::unique(mine.begin(), mine.end()), mine.end());
        t.insert(t.end(), mine.begin(), mine.end());
        off.push_back(t.size());
    }
    const detail::EncodedLinks e = detail::encode_links(off, t);
    EXPECT_GT(e.chunk_node.size(), 2u);
    const std::vector<uint8_t> stream(e.stream.begin(), e.stream.end());
    ASSERT_EQ(stream.size(), e.chunk_byte.back());
    std::vector<int32_t> back(t.size(), -1);
    EXPECT_EQ(detail::decode_links(off, e.chunk_node, e.chunk_byte, stream.data(), back.data()), "");
    EXPECT_EQ(back, t);
}

// save_vmap codes the links' stream as it writes the file, each chunk by whichever writer reaches
// it first while the others wait (LazyLinks in io/vmap_file.cpp). Many coded chunks, each 8 MiB
// piece of the file holding parts of several and some chunks cut by a piece's end, must give
// exactly encode_links' bytes, and load back as they were.
TEST(VmapFileLinks, LinksCodedWhileTheFileIsWrittenAreEncodeLinksBytes) {
    Scene sc = load_scene(std::string(VMAP_SOURCE_DIR) + "/scenes/cornell-empty.json");
    sc.points = 20000;
    BuildParams bp;
    bp.backend = Backend::kCpu;
    bp.octree.max_height = 8;
    bp.octree.leaf_points = 1;
    BuildStats st;
    VisibilityMap vm = detail::build_octree(sample_scene(sc), bp, st, "test");
    const int32_t nn = vm.octree().num_nodes();
    ASSERT_GT(nn, 20000);
    std::mt19937 rng(5);
    std::vector<std::pair<int32_t, int32_t>> pairs;
    std::vector<int32_t> to;
    for (int32_t a = 0; a + 1 < nn; ++a) {  // distinct partners above a, 0 to 900 of them
        to.clear();
        const uint32_t deg = rng() % 901;
        for (uint32_t k = 0; k < deg; ++k) to.push_back(a + 1 + int32_t(rng() % uint32_t(nn - a - 1)));
        std::sort(to.begin(), to.end());
        to.erase(std::unique(to.begin(), to.end()), to.end());
        for (int32_t b : to) pairs.emplace_back(a, b);
    }
    set_links(vm, std::move(pairs));
    const detail::EncodedLinks e = detail::encode_links(vm.link_offsets(), vm.link_targets());
    ASSERT_GT(e.chunk_node.size(), 6u);  // several chunks of 2^22 link ends
    ScratchDir dir;
    const std::string p = dir.path("many.vmap");
    save_vmap(p, vm);
    const std::string bytes = slurp(p);
    ASSERT_GT(bytes.size(), size_t(3) << 23);  // several 8 MiB pieces of the file
    const size_t link = section_data(bytes, "LINK");
    const size_t stream = link + vm.link_offsets().size() * 8 + 8 + e.chunk_node.size() * 4 +
                          e.chunk_byte.size() * 8;
    ASSERT_EQ(bytes.size(), stream + e.stream.size());
    EXPECT_TRUE(std::equal(e.stream.begin(), e.stream.end(),
                           reinterpret_cast<const uint8_t*>(bytes.data()) + stream));
    const VisibilityMap back = load_vmap(p);
    ASSERT_EQ(back.num_links(), vm.num_links());
    for (int32_t n = 0; n < nn; ++n) {
        const auto x = vm.links(n), y = back.links(n);
        ASSERT_TRUE(std::equal(x.begin(), x.end(), y.begin(), y.end())) << n;
    }
}

TEST_F(VmapFile, AnInconsistentTreeIsRejected) {
    ScratchDir dir;
    const std::string whole = slurp(saved(dir));
    const size_t at = section_data(whole, "TREE");
    const int32_t nn = map().octree().num_nodes();
    // TREE: i32 nodes, i32 leaves, Vec3 root_min, f32 root_size, spheres, boxes, half_size,
    // skip, ...
    const size_t skip = at + 4 + 4 + 12 + 4 + size_t(nn) * (sizeof(Sphere) + sizeof(Box) + 4);
    {
        std::string bytes = whole;
        const int32_t bad = nn + 5;  // the root's subtree runs past the last node
        std::memcpy(bytes.data() + skip, &bad, 4);
        const std::string p = write_resealed(dir, "skip.vmap", bytes);
        EXPECT_LOAD_ERROR(p, "TREE");
    }
    {
        std::string bytes = whole;
        const int32_t bad = -7;  // leaf count
        std::memcpy(bytes.data() + at + 4, &bad, 4);
        const std::string p = write_resealed(dir, "leaves.vmap", bytes);
        EXPECT_LOAD_ERROR(p, "TREE");
    }
    {
        // A root deeper than its leaves once overran `vmap info`'s per-level table.
        std::string bytes = whole;
        const size_t level = skip + size_t(nn) * 8;  // after skip and parent
        bytes[level] = char(200);
        const std::string p = write_resealed(dir, "level.vmap", bytes);
        EXPECT_LOAD_ERROR(p, "TREE", "level");
    }
}

// ---- writing -------------------------------------------------------------------------------

TEST_F(VmapFile, SavingIntoAMissingDirectoryThrowsAndLeavesNothing) {
    ScratchDir dir;
    const fs::path missing = dir.dir() / "no_such_dir";
    const std::string p = (missing / "map.vmap").string();
    expect_error([&] { save_vmap(p, map()); }, {p});
    EXPECT_FALSE(fs::exists(missing));
    EXPECT_TRUE(dir.files().empty());
}

TEST_F(VmapFile, SavingOverAnExistingFileReplacesItAndLeavesNoTemporary) {
    ScratchDir dir;
    const std::string p = dir.path("map.vmap");
    spit(p, "an old file that is not a V-map at all");
    save_vmap(p, map());
    EXPECT_EQ(dir.files(), std::vector<std::string>{"map.vmap"});
    expect_same_map(map(), load_vmap(p));

    // A stale temporary of an interrupted run (a process that no longer exists) is removed.
    spit(dir.path(".map.vmap.999999999.0.0.tmp"), "left over");
    save_vmap(p, map());
    EXPECT_EQ(dir.files(), std::vector<std::string>{"map.vmap"});
    expect_same_map(map(), load_vmap(p));
}

// Two saves of different maps to one path at the same time, many times over: the file is
// always one complete map (with a shared temporary name the loser's bytes went into the
// winner's file: "checksum mismatch").
TEST_F(VmapFile, ConcurrentSavesToOnePathLeaveOneCompleteMap) {
    ScratchDir dir;
    const std::string p = dir.path("map.vmap");
    VisibilityMap other = map();
    detail::MapAccess::data(other).visibility_params.K = 7;
    for (int round = 0; round < 6; ++round) {
        std::thread a([&] { save_vmap(p, map()); });
        std::thread b([&] { save_vmap(p, other); });
        a.join();
        b.join();
        VisibilityMap back = load_vmap(p);
        EXPECT_TRUE(back.visibility_params().K == 3 || back.visibility_params().K == 7);
        detail::MapAccess::data(back).visibility_params.K = 3;
        expect_same_map(map(), back);
    }
    EXPECT_EQ(dir.files(), std::vector<std::string>{"map.vmap"});
}

TEST_F(VmapFile, SavingOntoADirectoryThrowsAndLeavesNoTemporary) {
    ScratchDir dir;
    const std::string p = dir.path("taken");
    fs::create_directories(dir.path("taken/inside"));
    expect_error([&] { save_vmap(p, map()); }, {p});
    EXPECT_TRUE(fs::is_directory(p));
    EXPECT_TRUE(fs::exists(dir.path("taken/inside")));
    EXPECT_EQ(dir.files(), std::vector<std::string>{"taken"});
}

}  // namespace
}  // namespace vmap
