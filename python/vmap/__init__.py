"""vmap: view-independent mutual visibility for point models (Python binding).

    import numpy as np, vmap
    vm = vmap.build_file(vmap.data_dir() + "/scenes/cornell-bunny.json", points=5000)
    visible = vm.query(np.array([[0, 1], [10, 2000]]))      # bool[2]
    offsets, ids = vm.visible_from(np.array([0, 1, 2]))    # CSR of the visible sets
    picture = vm.render(eye_id=10)                           # H x W x 3 uint8
    radiosity = vm.gi()                                      # N x 3 float32
    normals = vmap.estimate_normals(scan_xyz)["normals"]     # N x 3, signed as build() does

Errors are vmap.Error (a RuntimeError) carrying the library's message.
"""
from ._vmap import (Cancelled, Error, VisibilityMap, __version__, build, build_file,
                    built_with_cuda, commit, data_dir, estimate_normals, load, surface_noise,
                    write_png)

__all__ = ["Cancelled", "Error", "VisibilityMap", "__version__", "build", "build_file",
           "built_with_cuda", "commit", "data_dir", "estimate_normals", "load", "surface_noise",
           "write_png"]
