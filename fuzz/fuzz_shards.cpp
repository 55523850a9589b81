// libFuzzer target: the sharded V-map that `vmap build --shards -o m.vmap` writes under mpirun
// (src/mpi/shard_file.h), read by load_vmap: the index (JSON), the base (.vmap) and the
// per-rank link files. One input holds them all, parts cut at kPart: the index, the base, then
// shard 0, 1, ... Each part is an in-memory file (fuzz_input.h), so the index names the others
// by their /proc/self/fd numbers (the index's folder). Checksums and sizes would stop almost
// every mutation, so the target reseals them first: the base's header like fuzz_vmap's, each
// shard's checksum in its header, and in the index (when it parses) each shard's "bytes" and
// "checksum", and the files' names: the structure checks are what is fuzzed. A map that loads
// answers a pair query and a visible set.
#include <fmt/format.h>

#include <cstring>
#include <deque>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "fuzz/fuzz_input.h"
#include "io/vmap_file.h"
#include "mpi/shard_file.h"
#include "vmap/vmap.h"

namespace {

constexpr std::string_view kPart = "\n#vmap-shard-part\n";
constexpr size_t kVmapHeader = 8 + 4 + 4 + 8 + 8;       // magic, version, reserved, size, sum
constexpr size_t kShardHeader = 8 + 4 + 4 + 4 + 4 + 8;  // ... up to the checksum at 32

std::vector<std::string> split(std::string_view in) {
    std::vector<std::string> parts;
    for (size_t at = 0;;) {
        const size_t cut = in.find(kPart, at);
        parts.emplace_back(in.substr(at, cut == std::string_view::npos ? cut : cut - at));
        if (cut == std::string_view::npos) return parts;
        at = cut + kPart.size();
    }
}

void reseal_base(std::string& b) {
    if (b.size() < kVmapHeader) return;
    const uint64_t payload = b.size() - kVmapHeader;
    const uint64_t sum = vmap::detail::payload_hash(
        reinterpret_cast<const uint8_t*>(b.data()) + kVmapHeader, payload);
    std::memcpy(b.data() + 16, &payload, 8);
    std::memcpy(b.data() + 24, &sum, 8);
}

// The shard's checksum over the arrays its header's range implies; false when it has none.
bool reseal_shard(std::string& s, uint64_t& sum) {
    if (s.size() < kShardHeader + 8) return false;
    int32_t n0, n1;
    std::memcpy(&n0, s.data() + 16, 4);
    std::memcpy(&n1, s.data() + 20, 4);
    const size_t rest = s.size() - kShardHeader - 8;
    if (n1 < n0 || uint64_t(int64_t(n1) - n0 + 1) > rest / 8) return false;
    std::vector<uint64_t> off(size_t(int64_t(n1) - n0 + 1));
    std::vector<int32_t> tg((rest - off.size() * 8) / 4);
    std::memcpy(off.data(), s.data() + kShardHeader + 8, off.size() * 8);
    if (!tg.empty())
        std::memcpy(tg.data(), s.data() + kShardHeader + 8 + off.size() * 8, tg.size() * 4);
    sum = vmap::mpi::shard_checksum(off, tg);
    std::memcpy(s.data() + kShardHeader, &sum, 8);
    return true;
}

// The index with each shard's size, checksum and file name, and the base's name, as the files
// written hold them.
void reseal_index(std::string& index, const std::vector<std::string>& parts,
                  const std::vector<uint64_t>& sums, const std::vector<bool>& sealed,
                  const std::vector<std::string>& names) {
    nlohmann::json j = nlohmann::json::parse(index, nullptr, false);
    if (j.is_discarded() || !j.is_object()) return;
    j["base"] = names[0];
    if (j.contains("shards") && j["shards"].is_array())
        for (size_t k = 0; k < j["shards"].size() && k + 2 < parts.size(); ++k) {
            nlohmann::json& e = j["shards"][k];
            if (!e.is_object()) continue;
            e["file"] = names[k + 1];
            e["bytes"] = parts[k + 2].size();
            if (sealed[k]) e["checksum"] = fmt::format("{:016x}", sums[k]);
        }
    index = j.dump(1);
}

// An in-memory file's name in /proc/self/fd.
std::string fd_name(const vmap::fuzz::MemFile& f) {
    return f.path().substr(f.path().rfind('/') + 1);
}

const uint8_t* bytes_of(const std::string& s) { return reinterpret_cast<const uint8_t*>(s.data()); }

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    std::vector<std::string> parts = split({reinterpret_cast<const char*>(data), size});
    if (parts.size() < 2) parts.resize(2);
    const size_t shards = parts.size() - 2;
    std::vector<uint64_t> sums(shards, 0);
    std::vector<bool> sealed(shards, false);
    reseal_base(parts[1]);
    for (size_t k = 0; k < shards; ++k) {
        uint64_t sum = 0;
        sealed[k] = reseal_shard(parts[k + 2], sum);
        sums[k] = sum;
    }
    std::deque<vmap::fuzz::MemFile> files;  // the base, then the shards
    std::vector<std::string> names;
    for (size_t i = 1; i < parts.size(); ++i) {
        files.emplace_back(bytes_of(parts[i]), parts[i].size(), "fuzz.vmap.part");
        names.push_back(fd_name(files.back()));
    }
    reseal_index(parts[0], parts, sums, sealed, names);
    const vmap::fuzz::MemFile index(bytes_of(parts[0]), parts[0].size(), "fuzz.vmap");

    vmap::fuzz::expect_only_vmap_errors([&] {
        const vmap::VisibilityMap vm = vmap::load_vmap(index.path());
        const uint32_t n = uint32_t(vm.points().size());
        if (n == 0) return;
        (void)vm.query(0, n - 1);
        (void)vm.visible_set(n / 2);
    });
    return 0;
}
