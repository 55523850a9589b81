// Sharded V-maps: shards, index, base and their reading (src/mpi/shard_file.h).
#include "mpi/shard_file.h"

#include <fmt/format.h>

#include <charconv>
#include <climits>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "io/json_file.h"
#include "io/vmap_file.h"
#include "vmap/error.h"
#include "vmap/map_access.h"

namespace vmap::mpi {
namespace {

namespace fs = std::filesystem;
constexpr char kMagic[8] = {'V', 'M', 'A', 'P', 'L', 'I', 'N', 'K'};
constexpr uint32_t kVersion = 1;
constexpr size_t kHead = 8 + 4 + 4 + 4 + 4 + 8 + 8;

template <class V>
uint64_t hash_of(const V& v) {
    return detail::payload_hash(reinterpret_cast<const uint8_t*>(v.data()),
                                v.size() * sizeof(v[0]));
}

std::string folder_of(const std::string& path) {
    const fs::path d = fs::path(path).parent_path();
    return d.empty() ? "." : d.string();
}

template <class T>
void put(std::vector<uint8_t>& b, T v) {
    const auto* p = reinterpret_cast<const uint8_t*>(&v);
    b.insert(b.end(), p, p + sizeof(T));
}
template <class T>
T get(const uint8_t*& p) {
    T v;
    std::memcpy(&v, p, sizeof(T));
    p += sizeof(T);
    return v;
}

std::vector<uint8_t> read_all(const std::string& path, const std::string& what) {
    std::error_code ec;
    if (!fs::is_regular_file(path, ec))
        throw Error(fmt::format("{}: cannot open {} (no such regular file)", path, what));
    std::ifstream in(path, std::ios::binary | std::ios::ate);
    const std::streamoff size = in ? std::streamoff(in.tellg()) : -1;
    if (size < 0) throw Error(fmt::format("{}: cannot open {}", path, what));
    std::vector<uint8_t> data(static_cast<size_t>(size));
    in.seekg(0);
    if (!in.read(reinterpret_cast<char*>(data.data()), std::streamsize(data.size())))
        throw Error(fmt::format("{}: read error", path));
    return data;
}

// One shard's arrays, checked against its entry in the index (whose range load_sharded has
// checked to lie in 0..nodes), appended to the map's.
void read_shard(const std::string& path, const ShardInfo& want, int k, detail::MapData& map,
                std::vector<int32_t>& all) {
    const std::vector<uint8_t> d = read_all(path, fmt::format("shard {}", k));
    if (d.size() != want.bytes)
        throw Error(
            fmt::format("{}: {} bytes, the index says {} (truncated, or from another "
                        "build)",
                        path, d.size(), want.bytes));
    if (d.size() < kHead || std::memcmp(d.data(), kMagic, 8) != 0)
        throw Error(fmt::format("{}: not a vmap shard (bad magic)", path));
    const uint8_t* p = d.data() + 8;
    const uint32_t version = get<uint32_t>(p), kk = get<uint32_t>(p);
    const int32_t n0 = get<int32_t>(p), n1 = get<int32_t>(p);
    const uint64_t ends = get<uint64_t>(p), sum = get<uint64_t>(p);
    if (version != kVersion)
        throw Error(fmt::format("{}: shard version {} not supported", path, version));
    if (kk != uint32_t(k) || n0 != want.n0 || n1 != want.n1 || ends != want.ends ||
        sum != want.checksum)
        throw Error(fmt::format("{}: header does not match the index (from another build?)", path));
    // n0 <= n1 here (the index's range); the sizes are compared without overflow.
    const size_t offsets = size_t(n1 - n0) + 1, rest = d.size() - kHead;
    if (rest / 8 < offsets || (rest - offsets * 8) % 4 != 0 || (rest - offsets * 8) / 4 != ends)
        throw Error(fmt::format("{}: length does not match its header", path));
    std::vector<uint64_t> off(offsets);
    std::vector<int32_t> tg(ends);
    std::memcpy(off.data(), p, off.size() * 8);
    if (ends) std::memcpy(tg.data(), p + off.size() * 8, ends * 4);  // no links: tg.data() null
    if (shard_checksum(off, tg) != sum)
        throw Error(fmt::format("{}: checksum mismatch: the shard is corrupt", path));
    const uint64_t base = all.size();
    bool ok = off[0] == 0 && off.back() == ends;
    for (size_t i = 0; ok && i + 1 < off.size(); ++i) ok = off[i] <= off[i + 1];
    if (!ok) throw Error(fmt::format("{}: bad offsets", path));
    for (size_t i = 1; i < off.size(); ++i) map.link_offsets[size_t(n0) + i] = base + off[i];
    all.insert(all.end(), tg.begin(), tg.end());
}

// A non-negative integer of the index in [lo, hi] (a float, a string or a value out of range
// is an error naming the field).
uint64_t int_value(const nlohmann::json& v, const std::string& name, uint64_t lo, uint64_t hi,
                   const std::string& where) {
    if (!v.is_number_integer())
        throw Error(fmt::format("{}: \"{}\": an integer expected, found {}", where, name, v.dump()));
    const bool negative = !v.is_number_unsigned() && v.get<int64_t>() < 0;
    if (negative || v.get<uint64_t>() < lo || v.get<uint64_t>() > hi)
        throw Error(
            fmt::format("{}: \"{}\": {} is outside [{}, {}]", where, name, v.dump(), lo, hi));
    return v.get<uint64_t>();
}
uint64_t int_field(const nlohmann::json& j, const char* key, uint64_t lo, uint64_t hi,
                   const std::string& where) {
    return int_value(j.at(key), key, lo, hi, where);
}

// A file named in the index: a plain name in the index's folder (what write_index writes).
std::string file_field(const nlohmann::json& j, const char* key, const std::string& where) {
    const std::string name = j.at(key).get<std::string>();
    if (name.empty() || name == "." || name == ".." || name.find('/') != std::string::npos ||
        name.find('\0') != std::string::npos)
        throw Error(fmt::format("{}: \"{}\": \"{}\" is not a file name in the index's folder",
                                where, key, name));
    return name;
}

uint64_t checksum_field(const nlohmann::json& j, const std::string& where) {
    const std::string text = j.at("checksum").get<std::string>();
    uint64_t v = 0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v, 16);
    if (text.size() != 16 || ec != std::errc() || end != text.data() + text.size())
        throw Error(fmt::format("{}: \"checksum\": \"{}\" is not 16 hex digits", where, text));
    return v;
}

struct Index {
    std::string base;
    int32_t nodes = 0;
    std::vector<ShardInfo> shards;
};

// The index's fields, each checked: the shards' ranges follow each other from 0 to `nodes`.
Index read_index(const std::string& path) {
    const nlohmann::json j = io::parse_json_file(path);
    Index x;
    try {
        if (int_field(j, "version", 0, UINT32_MAX, path) != kVersion)
            throw Error(fmt::format("{}: shard index version {} not supported", path,
                                    j.at("version").dump()));
        x.base = file_field(j, "base", path);
        x.nodes = int32_t(int_field(j, "nodes", 1, INT32_MAX, path));
        int32_t next = 0;
        for (const auto& s : j.at("shards")) {
            const std::string where = fmt::format("{}: shard {}", path, x.shards.size());
            const nlohmann::json& r = s.at("nodes");
            if (!r.is_array() || r.size() != 2)
                throw Error(fmt::format("{}: \"nodes\": [first, end] expected", where));
            const uint64_t nodes = uint64_t(x.nodes);
            ShardInfo info{file_field(s, "file", where),
                           int32_t(int_value(r.at(0), "nodes", 0, nodes, where)),
                           int32_t(int_value(r.at(1), "nodes", 0, nodes, where)),
                           int_field(s, "ends", 0, UINT64_MAX, where),
                           int_field(s, "bytes", 0, UINT64_MAX, where), checksum_field(s, where)};
            if (info.n0 != next || info.n1 < info.n0)
                throw Error(fmt::format("{}: nodes [{}, {}]: [{}, n) expected", where, info.n0,
                                        info.n1, next));
            next = info.n1;
            x.shards.push_back(std::move(info));
        }
        if (next != x.nodes)
            throw Error(fmt::format("{}: the shards cover nodes 0..{} of {}", path, next, x.nodes));
    } catch (const nlohmann::json::exception& e) {
        throw Error(fmt::format("{}: shard index: {}", path, e.what()));
    }
    return x;
}

}  // namespace

uint64_t shard_checksum(const std::vector<uint64_t>& offsets, const std::vector<int32_t>& targets) {
    return hash_of(offsets) * 0x9e3779b97f4a7c15ULL ^ hash_of(targets);
}

std::string shard_name(const std::string& index, int k, int shards) {
    return fmt::format("{}.shard-{}-of-{}", index, k, shards);
}
std::string base_name(const std::string& index) { return index + ".base"; }

std::unique_ptr<io::AtomicFile> write_shard(const std::string& path, int k, const LinkRange& r,
                                            ShardInfo& info) {
    std::vector<uint8_t> head(kMagic, kMagic + 8);
    info.file = fs::path(path).filename().string();
    info.n0 = r.n0, info.n1 = r.n1, info.ends = r.targets.size();
    info.checksum = shard_checksum(r.offsets, r.targets);
    put(head, kVersion), put(head, uint32_t(k)), put(head, r.n0), put(head, r.n1);
    put(head, info.ends), put(head, info.checksum);
    auto f = std::make_unique<io::AtomicFile>(path);
    f->write(head.data(), head.size());
    f->write(r.offsets.data(), r.offsets.size() * 8);
    f->write(r.targets.data(), r.targets.size() * 4);
    info.bytes = head.size() + r.offsets.size() * 8 + r.targets.size() * 4;
    return f;
}

void write_index(const std::string& path, const std::vector<ShardInfo>& shards, uint64_t links,
                 int32_t nodes) {
    // "format" first: is_shard_index() looks for it at the start.
    nlohmann::ordered_json j{{"format", "vmap-shards"},
                             {"version", kVersion},
                             {"base", fs::path(base_name(path)).filename().string()},
                             {"nodes", nodes},
                             {"links", links}};
    for (const ShardInfo& s : shards)
        j["shards"].push_back({{"file", s.file},
                               {"nodes", {s.n0, s.n1}},
                               {"ends", s.ends},
                               {"bytes", s.bytes},
                               {"checksum", fmt::format("{:016x}", s.checksum)}});
    io::write_file_atomic(path, j.dump(1) + "\n");
}

void save_base(const std::string& path, const VisibilityMap& vm) {
    VisibilityMap base;
    detail::MapData& b = detail::MapAccess::data(base);
    b.octree_params = vm.octree_params();
    b.visibility_params = vm.visibility_params();
    b.points = vm.points();
    b.order = vm.order();
    b.inverse = vm.inverse();
    b.octree = vm.octree();
    b.link_offsets.assign(size_t(vm.octree().num_nodes()) + 1, 0);
    save_vmap(path, base);
}

bool is_shard_index(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    char head[64] = {};
    in.read(head, sizeof head - 1);
    const std::string s(head, size_t(in.gcount()));
    return s.rfind('{', 0) == 0 && s.find("\"vmap-shards\"") != std::string::npos;
}

VisibilityMap load_sharded(const std::string& path) {
    const Index x = read_index(path);
    const std::string dir = folder_of(path);
    VisibilityMap vm = detail::load_vmap_file((fs::path(dir) / x.base).string());
    if (vm.octree().num_nodes() != x.nodes || vm.num_links() != 0)
        throw Error(fmt::format("{}: base {} does not match the index ({} nodes, {} links)", path,
                                x.base, vm.octree().num_nodes(), vm.num_links()));
    detail::MapData& d = detail::MapAccess::data(vm);
    std::vector<int32_t> all;
    for (size_t k = 0; k < x.shards.size(); ++k)
        read_shard((fs::path(dir) / x.shards[k].file).string(), x.shards[k], int(k), d, all);
    std::copy(all.begin(), all.end(), detail::allocate_link_targets(d, all.size()));
    for (int32_t t : vm.link_targets())
        if (t < 0 || t >= x.nodes)
            throw Error(fmt::format("{}: a link target is out of range", path));
    return vm;
}

}  // namespace vmap::mpi
