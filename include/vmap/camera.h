// A pinhole camera: where it is, what it looks at, and its vertical field of view.
//
// Kept apart from render.h so that a scene file can carry one (Scene::camera) without the scene
// code depending on the renderer.
#pragma once

#include "vmap/vec.h"

namespace vmap {

struct Camera {
    Vec3 eye;
    Vec3 target;
    Vec3 up{0, 1, 0};
    float fov_y_deg = 40;  // vertical field of view in degrees, in (0, 180)
};

}  // namespace vmap
