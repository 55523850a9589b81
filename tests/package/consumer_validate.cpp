// Uses the optional component vmap::validate: exact visibility against the scene's triangles.
#include <vmap/scene.h>
#include <vmap/validate.h>

#include <cstdio>

int main() {
    const vmap::Scene sc = vmap::load_scene(vmap::default_scene_path());
    const vmap::ExactVisibility exact(sc.surfaces, sc.path);
    // From the floor straight up to the ceiling beside the bunny, and from the floor up through
    // the bunny (at x 0.3, z 0.3 in the default scene) to the ceiling.
    const bool open = !exact.occluded({0.05f, 0.01f, 0.05f}, {0.05f, 0.5f, 0.05f}, 0.f, 1.f);
    std::printf("%s: %llu triangles, a clear segment is clear\n", open ? "ok  " : "FAIL",
                static_cast<unsigned long long>(exact.triangles()));
    return open ? 0 : 1;
}
