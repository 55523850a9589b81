// The HTTP server behind `vmap view`: holds one V-map in memory, serves the page in a
// web folder and answers the page's questions with the library's queries.
//
// Endpoints (every id is an input point id, as in `vmap query`):
//   GET  /api/info            JSON: counts, octree height, bounds, camera, colour modes
//   GET  /api/points          binary, little-endian, input order, n = info.points:
//                             f32 positions[3n], f32 normals[3n], u8 albedo sRGB[3n],
//                             f32 radii[n], then u8 GI sRGB[3n] when info.gi is true
//   POST /api/visible {"id", "as"}   VisibilityMap::visible_set(id) as a sorted list "ids", or
//                             with "as": "bits" as "bits": a base64 bit mask over the points
//                             (id k is bit k & 7 of byte k >> 3; 8x smaller than the list);
//                             the id's leaf, its points, level and cell
//   POST /api/pair {"a","b"}  VisibilityMap::query(a, b): "visible" | "hidden" | "same-leaf"
//   POST /api/ray {"id","dir":[x,y,z]}   shoot_ray: the first splat hit from the point
//   GET  /<file>              a file under the web folder ("/" is index.html)
// A request the server cannot answer gets 400 (404 for unknown paths) with a JSON body
// {"error": message}. Files: only regular files inside the web folder with a known extension
// are served; a path with a ".." or "." segment, a backslash, or one that resolves (through
// symbolic links) outside the folder is refused with 404, so nothing else on disk is reachable.
// A server bound to a loopback address answers 403 to a request whose Host header names another
// host (a page of another site whose name was made to resolve to 127.0.0.1: DNS rebinding).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "vmap/camera.h"
#include "vmap/vec.h"
#include "vmap/visibility_map.h"

namespace vmap::view {

struct ServerConfig {
    std::string web_root;              // folder holding index.html (and what it loads)
    std::string name;                  // what the map is, shown by the page
    std::optional<Camera> camera;      // the initial view; default_camera(points) otherwise
    std::vector<Vec3> gi_colors;       // display colours from GI (linear RGB, input order), or
                                       // empty when none was computed
    size_t max_request_bytes = 65536;  // larger request bodies are refused (413)
};

class Server {
  public:
    // Takes the map (it must carry its links). Throws vmap::Error when the web folder or its
    // index.html is missing, the map has no links, or gi_colors has the wrong size.
    Server(VisibilityMap vm, ServerConfig config);
    ~Server();
    Server(const Server&) = delete;
    Server& operator=(const Server&) = delete;

    // Binds host:port (port 0: any free port) and starts listening; returns the port. Throws
    // vmap::Error naming the address when it cannot bind.
    int bind(const std::string& host, int port);
    // Serves until stop() (from another thread). Returns false when it could not run.
    bool serve();
    // Makes serve() return; safe from any thread, also before serve() started.
    void stop();

    const VisibilityMap& map() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// True when `relative` (a URL path after its leading '/', already percent-decoded) may name a
// file under the web folder: no empty, "." or ".." segment, no backslash, NUL or other control
// character. The server still checks the resolved path against the folder.
bool is_safe_relative_path(const std::string& relative);

// "localhost", "::1", "[::1]" or 127.x.y.z.
bool is_loopback_host(const std::string& host);

}  // namespace vmap::view
