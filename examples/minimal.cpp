// The smallest vmap program: sample a scene, build its V-map on all cores, ask it questions.
//   minimal [SCENE.json] [OUT_DIR]   (defaults: the installed default scene, ./out)
#include <vmap/error.h>
#include <vmap/query.h>
#include <vmap/scene.h>
#include <vmap/version.h>
#include <vmap/vmap.h>

#include <cstdio>
#include <filesystem>
#include <string>

int main(int argc, char** argv) {
    try {
        const std::string scene_path = argc > 1 ? argv[1] : vmap::default_scene_path();
        const std::filesystem::path out_dir = argc > 2 ? argv[2] : "out";
        vmap::Scene scene = vmap::load_scene(scene_path);
        scene.points = 4000;  // small, so it runs in a second or two

        vmap::BuildParams params;
        params.octree.max_height = 6;
        vmap::BuildStats stats;
        const vmap::VisibilityMap vm =
            vmap::build_vmap(vmap::sample_scene(scene), params, &stats, scene_path);
        std::printf("vmap %s: %zu points, %zu links, built on %s in %.2f s\n", vmap::version(),
                    vm.points().size(), vm.num_links(), stats.backend.c_str(), stats.seconds_total);

        const vmap::PairVisibility v = vm.query(0, 1);
        std::printf("points 0 and 1: %s\n", v == vmap::PairVisibility::kVisible  ? "visible"
                                            : v == vmap::PairVisibility::kHidden ? "hidden"
                                                                                 : "same leaf");
        std::printf("point 0 sees %llu points\n",
                    static_cast<unsigned long long>(vmap::visible_count(vm, 0)));

        std::filesystem::create_directories(out_dir);
        const std::string file = (out_dir / "minimal.vmap").string();
        vmap::save_vmap(file, vm);
        std::printf("wrote %s\n", file.c_str());
        return 0;
    } catch (const vmap::Error& e) {
        std::fprintf(stderr, "minimal: %s\n", e.what());
        return 1;
    }
}
