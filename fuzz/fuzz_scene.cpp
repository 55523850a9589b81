// libFuzzer target: scene files (load_scene), then sampling a few points of what loaded, so the
// room, light and mesh placement see the parsed values too.
#include <algorithm>

#include "fuzz/fuzz_input.h"
#include "vmap/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    const vmap::fuzz::MemFile file(data, size, "fuzz.json");
    vmap::fuzz::expect_only_vmap_errors([&] {
        vmap::Scene sc = vmap::load_scene(file.path());
        sc.points = std::min<uint64_t>(sc.points, 64);
        (void)vmap::sample_scene(sc);
    });
    return 0;
}
