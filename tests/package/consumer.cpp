// Uses the installed vmap::vmap: builds a V-map from points made in code, checks its answers
// against what the geometry says, and finds the installed scenes (VMAP_DATA_DIR or the prefix).
#include <vmap/query.h>
#include <vmap/scene.h>
#include <vmap/version.h>
#include <vmap/vmap.h>

#include <cstdio>
#include <cstring>

namespace {

int failures = 0;

void check(bool ok, const char* what) {
    std::printf("%s: %s\n", ok ? "ok  " : "FAIL", what);
    failures += !ok;
}

// Two facing 10 x 10 grids of points (z = 0 facing +z and z = 1 facing -z), one splat each.
vmap::PointSet two_plates() {
    vmap::PointSet ps;
    for (int side = 0; side < 2; ++side)
        for (int i = 0; i < 10; ++i)
            for (int j = 0; j < 10; ++j) {
                ps.positions.push_back({0.05f + 0.1f * i, 0.05f + 0.1f * j, float(side)});
                ps.normals.push_back({0, 0, side ? -1.f : 1.f});
                ps.radii.push_back(0.05f);
            }
    return ps;
}

}  // namespace

int main() {
    check(std::strcmp(vmap::version(), "0.1.0") >= 0, "vmap::version()");
    vmap::BuildParams bp;
    bp.octree.max_height = 4;
    bp.backend = vmap::Backend::kCpu;
    bp.threads = 1;
    const vmap::VisibilityMap vm = vmap::build_vmap(two_plates(), bp);
    check(vm.query(0, 100) == vmap::PairVisibility::kVisible, "facing plates see each other");
    check(vm.query(0, 99) == vmap::PairVisibility::kHidden, "points of one plate do not");
    check(vmap::visible_count(vm, 0) == 100, "point 0 sees the whole other plate");
    std::vector<uint32_t> pairs = {0, 100, 0, 99, 150, 5};
    std::vector<uint8_t> answers(3);
    vmap::query_pairs(vm, pairs, answers);
    check(answers[0] == 1 && answers[1] == 0 && answers[2] == 1, "query_pairs");
    try {
        const vmap::Scene sc = vmap::load_scene(vmap::default_scene_path());
        check(!sc.surfaces.empty(), "the installed default scene loads");
    } catch (const vmap::Error& e) {
        std::printf("FAIL: default scene: %s\n", e.what());
        ++failures;
    }
    return failures ? 1 : 0;
}
