// vmap_equal A B: exit 0 when the two V-maps (a .vmap or a shard index each) load as the same
// map, array for array; else says the first difference and exits 1. For tests/mpi/run.sh.
#include <fmt/format.h>

#include <exception>

#include "vmap/vmap.h"

namespace {

template <class V>
bool same(const char* what, const V& a, const V& b) {
    if (a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin())) return true;
    fmt::print(stderr, "vmap_equal: {} differ ({} vs {} items)\n", what, a.size(), b.size());
    return false;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 3) {
        fmt::print(stderr, "usage: vmap_equal A.vmap B.vmap\n");
        return 2;
    }
    try {
        const vmap::VisibilityMap a = vmap::load_vmap(argv[1]), b = vmap::load_vmap(argv[2]);
        const bool ok = same("link offsets", a.link_offsets(), b.link_offsets()) &&
                        same("link targets", a.link_targets(), b.link_targets()) &&
                        same("point order", a.order(), b.order()) &&
                        same("skip", a.octree().skip(), b.octree().skip()) &&
                        same("leaf ranges", a.octree().leaf_begin(), b.octree().leaf_begin());
        return ok ? 0 : 1;
    } catch (const std::exception& e) {
        fmt::print(stderr, "vmap_equal: {}\n", e.what());
        return 1;
    }
}
