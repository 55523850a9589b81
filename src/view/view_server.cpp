// `vmap view`'s HTTP server (view_server.h): cpp-httplib (Debian's libcpp-httplib-dev) serving
// JSON answers from the in-memory V-map and the page's files.
#include "view/view_server.h"

#include <fmt/format.h>
#include <httplib.h>
#include <sys/socket.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "vmap/error.h"
#include "vmap/query.h"
#include "vmap/render.h"

namespace vmap::view {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// A request the server cannot answer: becomes a 400 with the message.
class BadRequest : public std::runtime_error {
  public:
    using std::runtime_error::runtime_error;
};

// httplib compresses a response whose type is text/* or exactly application/json (brotli at its
// highest quality when the browser accepts it: about half a second for a visible set's 200 kB of
// JSON). Over the loopback that only costs time, so the large answers carry types it leaves
// alone: JSON and JavaScript with a charset parameter (both still standard types).
constexpr const char* kJson = "application/json; charset=utf-8";

void reply_error(httplib::Response& res, int status, const std::string& message) {
    res.status = status;
    res.set_content(json{{"error", message}}.dump(), kJson);
}

json parse_body(const httplib::Request& req) {
    try {
        json j = json::parse(req.body);
        if (!j.is_object()) throw BadRequest("the request body must be a JSON object");
        return j;
    } catch (const json::parse_error& e) {
        throw BadRequest(fmt::format("malformed JSON: {}", e.what()));
    }
}

// An input point id from field `key` of `j`, checked against the map's size.
uint32_t id_field(const json& j, const char* key, size_t num_points) {
    if (!j.contains(key)) throw BadRequest(fmt::format("field '{}' missing (a point id)", key));
    const json& v = j.at(key);
    if (!v.is_number_integer())
        throw BadRequest(fmt::format("field '{}': {} is not an integer point id", key, v.dump()));
    if (v.is_number_unsigned() ? v.get<uint64_t>() >= num_points
                               : v.get<int64_t>() < 0 || v.get<int64_t>() >= int64_t(num_points))
        throw BadRequest(
            fmt::format("field '{}': point id {} out of range (the V-map has {} points)", key,
                        v.dump(), num_points));
    return v.get<uint32_t>();
}

Vec3 direction_field(const json& j, const char* key) {
    if (!j.contains(key)) throw BadRequest(fmt::format("field '{}' missing ([x, y, z])", key));
    const json& v = j.at(key);
    if (!v.is_array() || v.size() != 3 || !v[0].is_number() || !v[1].is_number() ||
        !v[2].is_number())
        throw BadRequest(fmt::format("field '{}': {} is not [x, y, z]", key, v.dump()));
    const Vec3 d{v[0].get<float>(), v[1].get<float>(), v[2].get<float>()};
    if (!std::isfinite(d.x) || !std::isfinite(d.y) || !std::isfinite(d.z) || !(length(d) > 0))
        throw BadRequest(fmt::format("field '{}': the direction must be finite and non-zero", key));
    return d;
}

json vec_json(Vec3 v) { return json::array({v.x, v.y, v.z}); }

// Standard base64 (RFC 4648, with padding).
std::string base64(const std::vector<uint8_t>& bytes) {
    static const char kDigits[] =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    out.reserve((bytes.size() + 2) / 3 * 4);
    for (size_t i = 0; i < bytes.size(); i += 3) {
        const size_t left = bytes.size() - i;
        const uint32_t v = uint32_t(bytes[i]) << 16 | (left > 1 ? uint32_t(bytes[i + 1]) << 8 : 0) |
                           (left > 2 ? bytes[i + 2] : 0);
        out += kDigits[v >> 18];
        out += kDigits[(v >> 12) & 63];
        out += left > 1 ? kDigits[(v >> 6) & 63] : '=';
        out += left > 2 ? kDigits[v & 63] : '=';
    }
    return out;
}

// A set of ids < n as a bit mask: id k is bit (k & 7) of byte k >> 3.
std::vector<uint8_t> bit_mask(const std::vector<uint32_t>& ids, size_t n) {
    std::vector<uint8_t> bits((n + 7) / 8, 0);
    for (uint32_t k : ids) bits[k >> 3] |= uint8_t(1u << (k & 7));
    return bits;
}

// The "as" field of /api/visible: "ids" (default, a list) or "bits" (a base64 bit mask).
bool wants_bits(const json& j) {
    if (!j.contains("as")) return false;
    const json& v = j.at("as");
    if (v == "ids") return false;
    if (v == "bits") return true;
    throw BadRequest(fmt::format("field 'as': {} is not \"ids\" or \"bits\"", v.dump()));
}

template <class T>
void append_raw(std::string& out, const T* data, size_t count) {
    out.append(reinterpret_cast<const char*>(data), count * sizeof(T));
}

// The /api/points buffer (layout in view_server.h); x86-64 and aarch64 are little-endian.
std::string points_buffer(const PointSet& p, const std::vector<Vec3>& gi_colors) {
    const size_t n = p.size();
    std::string out;
    out.reserve(n * (12 + 12 + 3 + 4 + 3));
    append_raw(out, p.positions.data(), n);
    if (p.has_normals()) {
        append_raw(out, p.normals.data(), n);
    } else {
        out.append(n * sizeof(Vec3), '\0');
    }
    auto append_srgb = [&](const std::vector<Vec3>& colors) {
        for (size_t i = 0; i < n; ++i) {
            const Vec3 c = colors.empty() ? Vec3{0.8f, 0.8f, 0.8f} : colors[i];
            out.push_back(char(linear_to_srgb8(c.x)));
            out.push_back(char(linear_to_srgb8(c.y)));
            out.push_back(char(linear_to_srgb8(c.z)));
        }
    };
    append_srgb(p.colors);
    if (p.has_radii()) {
        append_raw(out, p.radii.data(), n);
    } else {
        out.append(n * sizeof(float), '\0');
    }
    if (!gi_colors.empty()) append_srgb(gi_colors);
    return out;
}

const char* content_type(const fs::path& file) {
    static const std::pair<const char*, const char*> kTypes[] = {
        {".html", "text/html; charset=utf-8"},
        {".js", "application/javascript; charset=utf-8"},
        {".mjs", "application/javascript; charset=utf-8"},
        {".css", "text/css; charset=utf-8"},
        {".json", kJson},
        {".png", "image/png"},
        {".svg", "image/svg+xml"},
        {".ico", "image/x-icon"},
    };
    const std::string ext = file.extension().string();
    for (const auto& [e, type] : kTypes)
        if (ext == e) return type;
    return nullptr;
}

// The host part of a Host header ("127.0.0.1:8080", "[::1]:8080", "localhost").
std::string host_name(const std::string& header) {
    if (!header.empty() && header[0] == '[') return header.substr(0, header.find(']') + 1);
    return header.substr(0, header.find(':'));
}

}  // namespace

bool is_loopback_host(const std::string& host) {
    if (host == "localhost" || host == "::1" || host == "[::1]") return true;
    unsigned a, b, c, d;
    char extra;
    return std::sscanf(host.c_str(), "%u.%u.%u.%u%c", &a, &b, &c, &d, &extra) == 4 && a == 127 &&
           b < 256 && c < 256 && d < 256;
}

bool is_safe_relative_path(const std::string& relative) {
    if (relative.empty()) return false;
    for (unsigned char c : relative)
        if (c < 0x20 || c == 0x7f || c == '\\' || c == ':') return false;
    size_t at = 0;
    while (true) {
        const size_t end = relative.find('/', at);
        const std::string seg = relative.substr(at, end == std::string::npos ? end : end - at);
        if (seg.empty() || seg == "." || seg == "..") return false;
        if (end == std::string::npos) return true;
        at = end + 1;
    }
}

struct Server::Impl {
    VisibilityMap vm;
    ServerConfig config;
    fs::path root;  // canonical web folder
    std::string points_bin;
    json info;
    httplib::Server http;
    std::atomic<bool> stop_requested{false};
    std::atomic<int> state{0};  // 0 before serve(), 1 in serve(), 2 after
    bool loopback = false;      // bound to a loopback address: Host headers must name one too

    Impl(VisibilityMap map, ServerConfig cfg);
    void routes();
    json on_visible(const json& req) const;
    json on_pair(const json& req) const;
    json on_ray(const json& req) const;
    void on_file(const httplib::Request& req, httplib::Response& res) const;
    json make_info(const PointSet& input_order) const;
};

Server::Impl::Impl(VisibilityMap map, ServerConfig cfg)
    : vm(std::move(map)), config(std::move(cfg)) {
    std::error_code ec;
    root = fs::canonical(config.web_root, ec);
    if (ec || !fs::is_directory(root))
        throw Error(fmt::format("{}: the web folder does not exist", config.web_root));
    if (!fs::is_regular_file(root / "index.html"))
        throw Error(fmt::format("{}: no index.html in the web folder", config.web_root));
    vm.require_links("vmap view");
    if (!config.gi_colors.empty() && config.gi_colors.size() != vm.points().size())
        throw Error(
            fmt::format("GI colours: {} for {} points", config.gi_colors.size(), vm.points().size()));
    const PointSet input_order = points_in_input_order(vm);
    points_bin = points_buffer(input_order, config.gi_colors);
    info = make_info(input_order);
    routes();
}

json Server::Impl::make_info(const PointSet& p) const {
    Vec3 lo = p.positions[0], hi = p.positions[0];
    for (const Vec3& q : p.positions) {
        lo = {std::min(lo.x, q.x), std::min(lo.y, q.y), std::min(lo.z, q.z)};
        hi = {std::max(hi.x, q.x), std::max(hi.y, q.y), std::max(hi.z, q.z)};
    }
    const Camera cam = config.camera ? *config.camera : default_camera(p);
    const Octree& t = vm.octree();
    return json{
        {"name", config.name},
        {"points", p.size()},
        {"nodes", t.num_nodes()},
        {"leaves", t.num_leaves()},
        {"height", t.height()},
        {"max_height", vm.octree_params().max_height},
        {"leaf_points", vm.octree_params().leaf_points},
        {"links", vm.num_links()},
        {"bounds", {{"min", vec_json(lo)}, {"max", vec_json(hi)}}},
        {"camera",
         {{"eye", vec_json(cam.eye)},
          {"target", vec_json(cam.target)},
          {"up", vec_json(cam.up)},
          {"fov", cam.fov_y_deg}}},
        {"gi", !config.gi_colors.empty()},
        {"radii", p.has_radii()},
    };
}

json Server::Impl::on_visible(const json& req) const {
    const auto t0 = std::chrono::steady_clock::now();
    const uint32_t id = id_field(req, "id", vm.points().size());
    const bool bits = wants_bits(req);
    const std::vector<uint32_t> set = vm.visible_set(id);
    const Octree& t = vm.octree();
    const int32_t leaf = t.leaf_of_point(vm.inverse()[id]);
    const int32_t node = t.leaf_node()[leaf];
    std::vector<uint32_t> leaf_ids;
    for (uint32_t k = t.point_begin()[node]; k < t.point_end()[node]; ++k)
        leaf_ids.push_back(vm.order()[k]);
    std::sort(leaf_ids.begin(), leaf_ids.end());
    json out{{"id", id},
             {"count", set.size()},
             {"leaf", leaf},
             {"node", node},
             {"level", int(t.level()[node])},
             {"height", t.height()},
             {"cell", {{"center", vec_json(t.spheres()[node].center)}, {"half", t.half_size()[node]}}},
             {"leaf_ids", leaf_ids}};
    if (bits) {
        out["bits"] = base64(bit_mask(set, vm.points().size()));
    } else {
        out["ids"] = set;
    }
    out["server_ms"] =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    return out;
}

json Server::Impl::on_pair(const json& req) const {
    const uint32_t a = id_field(req, "a", vm.points().size());
    const uint32_t b = id_field(req, "b", vm.points().size());
    const PairVisibility v = vm.query(a, b);
    return json{{"a", a},
                {"b", b},
                {"result", v == PairVisibility::kVisible  ? "visible"
                           : v == PairVisibility::kHidden ? "hidden"
                                                          : "same-leaf"}};
}

json Server::Impl::on_ray(const json& req) const {
    const uint32_t id = id_field(req, "id", vm.points().size());
    const Vec3 dir = direction_field(req, "dir");
    RayStats st;
    const RayHit h = shoot_ray(vm, id, dir, &st);
    json out{
        {"id", id}, {"hit", h.hit}, {"node_tests", st.node_tests}, {"disc_tests", st.disc_tests}};
    if (h.hit) {
        out["hit_id"] = h.id;
        out["distance"] = h.distance;
        out["point"] = vec_json(vm.points().positions[vm.inverse()[h.id]]);
    }
    return out;
}

void Server::Impl::on_file(const httplib::Request& req, httplib::Response& res) const {
    std::string rel = req.path.size() > 1 ? req.path.substr(1) : "index.html";
    if (!rel.empty() && rel.back() == '/') rel += "index.html";
    if (rel.rfind("api/", 0) == 0) return reply_error(res, 404, "no such endpoint: " + req.path);
    const auto refuse = [&] { reply_error(res, 404, "not found: " + req.path); };
    if (!is_safe_relative_path(rel)) return refuse();
    std::error_code ec;
    const fs::path file = fs::canonical(root / rel, ec);
    if (ec || !fs::is_regular_file(file)) return refuse();
    // Inside the folder after resolving symbolic links: the root is a prefix, segment-wise.
    auto r = root.begin();
    for (auto f = file.begin(); r != root.end(); ++r, ++f)
        if (f == file.end() || *f != *r) return refuse();
    const char* type = content_type(file);
    if (!type) return refuse();
    std::ifstream in(file, std::ios::binary);
    std::ostringstream body;
    body << in.rdbuf();
    if (!in) return reply_error(res, 500, "cannot read " + req.path);
    res.set_content(body.str(), type);
}

void Server::Impl::routes() {
    using Fn = json (Impl::*)(const json&) const;
    const auto api = [this](Fn fn) {
        return [this, fn](const httplib::Request& req, httplib::Response& res) {
            try {
                res.set_content((this->*fn)(parse_body(req)).dump(), kJson);
            } catch (const BadRequest& e) {
                reply_error(res, 400, e.what());
            } catch (const Error& e) {
                reply_error(res, 400, e.what());
            }
        };
    };
    // SO_REUSEADDR (a restart may take the port of a socket in TIME_WAIT) but not httplib's
    // default SO_REUSEPORT, which would let a second server share a port in use and split the
    // requests between two maps.
    http.set_socket_options([](socket_t sock) {
        int yes = 1;
        setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
    });
    http.set_payload_max_length(config.max_request_bytes);
    http.set_default_headers(
        {{"X-Content-Type-Options", "nosniff"}, {"Cache-Control", "no-store"}});
    // A page on another site cannot read a loopback server's answers (same-origin policy), unless
    // its own name is made to resolve to 127.0.0.1 (DNS rebinding); its requests then carry that
    // name as Host. A server bound to the loopback answers only Host names of the loopback.
    http.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
        const std::string host = host_name(req.get_header_value("Host"));
        if (!loopback || is_loopback_host(host)) return httplib::Server::HandlerResponse::Unhandled;
        reply_error(res, 403, fmt::format("Host '{}' is not this machine's loopback name", host));
        return httplib::Server::HandlerResponse::Handled;
    });
    http.Get("/api/info", [this](const httplib::Request&, httplib::Response& res) {
        res.set_content(info.dump(), kJson);
    });
    http.Get("/api/points", [this](const httplib::Request&, httplib::Response& res) {
        res.set_content(points_bin, "application/octet-stream");
    });
    http.Post("/api/visible", api(&Impl::on_visible));
    http.Post("/api/pair", api(&Impl::on_pair));
    http.Post("/api/ray", api(&Impl::on_ray));
    http.Get(R"(/.*)",
             [this](const httplib::Request& req, httplib::Response& res) { on_file(req, res); });
    http.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
        if (res.body.empty())
            reply_error(res, res.status,
                        fmt::format("{} {}: status {}", req.method, req.path, res.status));
    });
    http.set_exception_handler(
        [](const httplib::Request&, httplib::Response& res, std::exception_ptr ep) {
            std::string what = "internal error";
            try {
                std::rethrow_exception(ep);
            } catch (const std::exception& e) {
                what = e.what();
            } catch (...) {
            }
            reply_error(res, 500, what);
        });
}

Server::Server(VisibilityMap vm, ServerConfig config)
    : impl_(std::make_unique<Impl>(std::move(vm), std::move(config))) {}

Server::~Server() = default;

int Server::bind(const std::string& host, int port) {
    if (port < 0 || port > 65535) throw Error(fmt::format("--port: {} is not 0..65535", port));
    const int got = port == 0 ? impl_->http.bind_to_any_port(host)
                              : (impl_->http.bind_to_port(host, port) ? port : -1);
    impl_->loopback = is_loopback_host(host);
    if (got < 0)
        throw Error(
            fmt::format("{}:{}: cannot listen there (address in use, or not this "
                        "machine's?)",
                        host, port));
    return got;
}

bool Server::serve() {
    impl_->state = 1;
    const bool ok = impl_->stop_requested || impl_->http.listen_after_bind();
    impl_->state = 2;
    return ok;
}

void Server::stop() {
    impl_->stop_requested = true;
    if (impl_->state != 1) return;  // not serving yet: serve() sees the flag; or done
    // serve() is entering the listen loop: wait until httplib says it runs, then stop it.
    while (impl_->state == 1 && !impl_->http.is_running())
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    impl_->http.stop();
}

const VisibilityMap& Server::map() const { return impl_->vm; }

}  // namespace vmap::view
