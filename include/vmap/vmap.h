// The vmap library in one include: point sets and their files, scenes, the octree, the V-map
// (build, save, load), queries, rendering and global illumination. Validation and the Embree
// reference (vmap/validate.h, vmap/gi_reference.h) are the optional `validate` component
// (find_package(vmap COMPONENTS validate), target vmap::validate) and are included apart.
#pragma once

#include "vmap/camera.h"
#include "vmap/error.h"
#include "vmap/gi.h"
#include "vmap/io.h"
#include "vmap/mesh.h"
#include "vmap/normals.h"
#include "vmap/octree.h"
#include "vmap/options.h"
#include "vmap/progress.h"
#include "vmap/query.h"
#include "vmap/render.h"
#include "vmap/scene.h"
#include "vmap/vec.h"
#include "vmap/version.h"
#include "vmap/visibility.h"
#include "vmap/visibility_map.h"
