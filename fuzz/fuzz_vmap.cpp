// libFuzzer target: the .vmap reader (load_vmap). Mutated bytes would almost never get past the
// header's payload checksum, so the target reseals the header (size and checksum to match the
// payload) first: the loader's structure checks are what is fuzzed. A map that loads answers a
// pair query and a visible set, which walk the structure the checks let through.
#include <cstring>
#include <vector>

#include "fuzz/fuzz_input.h"
#include "io/vmap_file.h"
#include "vmap/vmap.h"

namespace {

constexpr size_t kHeader = 8 + 4 + 4 + 8 + 8;  // magic, version, reserved, size, checksum

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    std::vector<uint8_t> bytes(data, data + size);
    if (size >= kHeader) {
        const uint64_t payload = size - kHeader;
        const uint64_t sum = vmap::detail::payload_hash(bytes.data() + kHeader, payload);
        std::memcpy(bytes.data() + 16, &payload, 8);
        std::memcpy(bytes.data() + 24, &sum, 8);
    }
    const vmap::fuzz::MemFile file(bytes.data(), bytes.size(), "fuzz.vmap");
    vmap::fuzz::expect_only_vmap_errors([&] {
        const vmap::VisibilityMap vm = vmap::load_vmap(file.path());
        const uint32_t n = uint32_t(vm.points().size());
        if (n == 0) return;
        (void)vm.query(0, n - 1);
        (void)vm.visible_set(n / 2);
    });
    return 0;
}
