// `vmap view`'s server over real HTTP (httplib's client on 127.0.0.1): its answers equal the
// library's queries, bad requests get 400 with a message, and no file outside the web folder is
// ever served.
#include <gtest/gtest.h>
#include <httplib.h>
#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <thread>

#include "test_util.h"
#include "view/view_server.h"
#include "vmap/error.h"
#include "vmap/query.h"
#include "vmap/render.h"

namespace vmap {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

void write_file(const fs::path& p, const std::string& text) {
    fs::create_directories(p.parent_path());
    std::ofstream(p) << text;
}

const char kSecret[] = "secret outside the web folder";
const char kBase64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

class ViewTest : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        vm_ = new VisibilityMap(build_vmap(test::sample(test::scene_path("cornell-bunny"), 1500, 3),
                                           test::cpu_params(6, 4)));
    }
    static void TearDownTestSuite() { delete vm_; }

    void SetUp() override {
        dir_ = fs::temp_directory_path() / ("vmap_view_test_" + std::to_string(::getpid()));
        fs::remove_all(dir_);
        write_file(dir_ / "web/index.html", "<!doctype html><p>index</p>");
        write_file(dir_ / "web/app.js", "console.log(1);");
        write_file(dir_ / "web/sub/style.css", "p {}");
        write_file(dir_ / "web/notes.txt", "no known extension");
        write_file(dir_ / "secret.txt", kSecret);
        write_file(dir_ / "secret.js", kSecret);
        fs::create_symlink(dir_ / "secret.js", dir_ / "web/link.js");
        view::ServerConfig cfg;
        cfg.web_root = (dir_ / "web").string();
        cfg.name = "test";
        server_ = std::make_unique<view::Server>(*vm_, cfg);
        port_ = server_->bind("127.0.0.1", 0);
        thread_ = std::thread([this] { server_->serve(); });
        client_ = std::make_unique<httplib::Client>("127.0.0.1", port_);
        client_->set_url_encode(false);
    }
    void TearDown() override {
        server_->stop();
        thread_.join();
        fs::remove_all(dir_);
    }

    json post(const std::string& path, const json& body, int expect = 200) {
        return post_raw(path, body.dump(), expect);
    }
    json post_raw(const std::string& path, const std::string& body, int expect) {
        auto r = client_->Post(path.c_str(), body, "application/json");
        EXPECT_TRUE(r) << path;
        if (!r) return {};
        EXPECT_EQ(r->status, expect) << path << " " << body << " -> " << r->body;
        return json::parse(r->body, nullptr, false);
    }
    // A 400 whose message mentions `words`.
    void expect_400(const std::string& path, const std::string& body, const std::string& words) {
        const json j = post_raw(path, body, 400);
        ASSERT_TRUE(j.is_object() && j.contains("error")) << body;
        EXPECT_NE(j["error"].get<std::string>().find(words), std::string::npos)
            << body << " -> " << j["error"];
    }

    static VisibilityMap* vm_;
    fs::path dir_;
    std::unique_ptr<view::Server> server_;
    int port_ = 0;
    std::thread thread_;
    std::unique_ptr<httplib::Client> client_;
};
VisibilityMap* ViewTest::vm_ = nullptr;

TEST_F(ViewTest, InfoDescribesTheMap) {
    auto r = client_->Get("/api/info");
    ASSERT_TRUE(r);
    ASSERT_EQ(r->status, 200);
    const json j = json::parse(r->body);
    EXPECT_EQ(j["points"], vm_->points().size());
    EXPECT_EQ(j["leaves"], vm_->octree().num_leaves());
    EXPECT_EQ(j["height"], vm_->octree().height());
    EXPECT_EQ(j["links"], vm_->num_links());
    EXPECT_EQ(j["gi"], false);
    EXPECT_EQ(j["camera"]["eye"].size(), 3u);
}

TEST_F(ViewTest, PointsBufferHoldsTheCloudInInputOrder) {
    auto r = client_->Get("/api/points");
    ASSERT_TRUE(r);
    const PointSet p = points_in_input_order(*vm_);
    const size_t n = p.size();
    ASSERT_EQ(r->body.size(), n * (12 + 12 + 3 + 4));
    std::vector<Vec3> pos(n), nrm(n);
    std::vector<float> rad(n);
    std::memcpy(pos.data(), r->body.data(), 12 * n);
    std::memcpy(nrm.data(), r->body.data() + 12 * n, 12 * n);
    std::memcpy(rad.data(), r->body.data() + 27 * n, 4 * n);
    for (size_t i = 0; i < n; ++i) {
        ASSERT_EQ(pos[i].x, p.positions[i].x) << i;
        ASSERT_EQ(pos[i].z, p.positions[i].z) << i;
        ASSERT_EQ(nrm[i].y, p.normals[i].y) << i;
        ASSERT_EQ(rad[i], p.radii[i]) << i;
        ASSERT_EQ(uint8_t(r->body[24 * n + 3 * i]), linear_to_srgb8(p.colors[i].x)) << i;
    }
}

TEST_F(ViewTest, VisibleSetEqualsTheLibrary) {
    const uint32_t n = uint32_t(vm_->points().size());
    std::mt19937 rng(7);
    std::vector<uint32_t> ids{0, n / 2, n - 1};
    for (int k = 0; k < 12; ++k) ids.push_back(rng() % n);
    uint64_t total = 0;
    for (uint32_t id : ids) {
        const json j = post("/api/visible", {{"id", id}});
        const std::vector<uint32_t> want = vm_->visible_set(id);
        ASSERT_EQ(j["ids"].get<std::vector<uint32_t>>(), want) << id;
        EXPECT_EQ(j["count"], want.size());
        EXPECT_EQ(j["count"], visible_count(*vm_, id));
        const auto leaf = j["leaf_ids"].get<std::vector<uint32_t>>();
        EXPECT_NE(std::find(leaf.begin(), leaf.end(), id), leaf.end()) << "its own leaf";
        const int32_t node = vm_->octree().leaf_node()[vm_->octree().leaf_of_point(vm_->inverse()[id])];
        EXPECT_EQ(j["level"], int(vm_->octree().level()[node]));
        EXPECT_EQ(leaf.size(), vm_->octree().point_end()[node] - vm_->octree().point_begin()[node]);
        total += want.size();
        // The same set as a base64 bit mask.
        const std::string b64 = post("/api/visible", {{"id", id}, {"as", "bits"}})["bits"];
        std::vector<uint32_t> got;
        std::string bytes;
        for (size_t i = 0; i + 3 < b64.size(); i += 4) {
            uint32_t v = 0;
            for (int c = 0; c < 4; ++c) {
                const char ch = b64[i + c];
                const auto at = std::string(kBase64).find(ch);
                v = v << 6 | (ch == '=' ? 0 : uint32_t(at));
            }
            bytes += char(v >> 16), bytes += char(v >> 8), bytes += char(v);
        }
        ASSERT_GE(bytes.size(), (n + 7) / 8);
        for (uint32_t k = 0; k < n; ++k)
            if (uint8_t(bytes[k >> 3]) >> (k & 7) & 1) got.push_back(k);
        ASSERT_EQ(got, want) << "bits of " << id;
    }
    EXPECT_GT(total, 0u);
}

TEST_F(ViewTest, ConcurrentClientsGetTheSameAnswers) {
    const uint32_t n = uint32_t(vm_->points().size());
    std::atomic<int> wrong{0}, done{0};
    std::vector<std::thread> clients;
    for (int t = 0; t < 4; ++t)
        clients.emplace_back([&, t] {
            httplib::Client c("127.0.0.1", port_);
            for (int k = 0; k < 20; ++k) {
                const uint32_t id = (t * 977 + k * 131) % n;
                auto r = c.Post("/api/visible", json{{"id", id}}.dump(), "application/json");
                if (!r || r->status != 200 ||
                    json::parse(r->body)["ids"].get<std::vector<uint32_t>>() !=
                        vm_->visible_set(id))
                    ++wrong;
                ++done;
            }
        });
    for (auto& c : clients) c.join();
    EXPECT_EQ(done, 80);
    EXPECT_EQ(wrong, 0);
}

TEST_F(ViewTest, LargeAnswersAreNotCompressed) {
    // Brotli at httplib's quality took half a second for a visible set; the loopback needs none.
    const httplib::Headers br{{"Accept-Encoding", "br, gzip, deflate"}};
    auto v = client_->Post("/api/visible", br, "{\"id\": 3}", "application/json");
    ASSERT_TRUE(v);
    EXPECT_EQ(v->status, 200);
    EXPECT_FALSE(v->has_header("Content-Encoding"));
    auto js = client_->Get("/app.js", br);
    ASSERT_TRUE(js);
    EXPECT_FALSE(js->has_header("Content-Encoding"));
}

TEST_F(ViewTest, PairAndRayEqualTheLibrary) {
    const uint32_t n = uint32_t(vm_->points().size());
    std::mt19937 rng(9);
    int seen[3] = {0, 0, 0};
    for (int k = 0; k < 300; ++k) {
        const uint32_t a = rng() % n, b = k % 50 == 0 ? a : rng() % n;
        const PairVisibility v = vm_->query(a, b);
        const char* want = v == PairVisibility::kVisible  ? "visible"
                           : v == PairVisibility::kHidden ? "hidden"
                                                          : "same-leaf";
        ASSERT_EQ(post("/api/pair", {{"a", a}, {"b", b}})["result"], want) << a << " " << b;
        seen[int(v)]++;
    }
    EXPECT_GT(seen[0], 0);
    EXPECT_GT(seen[1], 0);
    EXPECT_GT(seen[2], 0);
    int hits = 0;
    for (int k = 0; k < 40; ++k) {
        const uint32_t id = rng() % n;
        const Vec3 d = vm_->points().normals[vm_->inverse()[id]];
        const RayHit h = shoot_ray(*vm_, id, d);
        const json j = post("/api/ray", {{"id", id}, {"dir", {d.x, d.y, d.z}}});
        ASSERT_EQ(j["hit"], h.hit) << id;
        if (!h.hit) continue;
        ++hits;
        EXPECT_EQ(j["hit_id"], h.id);
        EXPECT_EQ(j["distance"].get<float>(), h.distance);
    }
    EXPECT_GT(hits, 10);
}

TEST_F(ViewTest, BadRequestsGet400WithAMessage) {
    const std::string n = std::to_string(vm_->points().size());
    expect_400("/api/visible", "{\"id\": ", "malformed JSON");
    expect_400("/api/visible", "", "malformed JSON");
    expect_400("/api/visible", "[1, 2]", "JSON object");
    expect_400("/api/visible", "{}", "field 'id' missing");
    expect_400("/api/visible", "{\"id\": " + n + "}", "out of range (the V-map has " + n);
    expect_400("/api/visible", "{\"id\": -1}", "out of range");
    expect_400("/api/visible", "{\"id\": 99999999999999}", "out of range");
    expect_400("/api/visible", "{\"id\": \"3\"}", "not an integer");
    expect_400("/api/visible", "{\"id\": 2.5}", "not an integer");
    expect_400("/api/visible", "{\"id\": 1, \"as\": \"png\"}", "field 'as'");
    expect_400("/api/pair", "{\"a\": 1}", "field 'b' missing");
    expect_400("/api/ray", "{\"id\": 1}", "field 'dir' missing");
    expect_400("/api/ray", "{\"id\": 1, \"dir\": [0, 0, 0]}", "non-zero");
    expect_400("/api/ray", "{\"id\": 1, \"dir\": [1, 2]}", "not [x, y, z]");
    expect_400("/api/ray", "{\"id\": 1, \"dir\": [1, \"a\", 2]}", "not [x, y, z]");
    auto big =
        client_->Post("/api/visible", std::string(200000, ' ') + "{\"id\": 1}", "application/json");
    ASSERT_TRUE(big);
    EXPECT_EQ(big->status, 413);
    auto none = client_->Get("/api/nothing");
    ASSERT_TRUE(none);
    EXPECT_EQ(none->status, 404);
    EXPECT_NE(none->body.find("no such endpoint"), std::string::npos);
    // The server still answers after all that.
    EXPECT_EQ(post("/api/visible", {{"id", 1}})["id"], 1);
}

TEST_F(ViewTest, ServesItsOwnFiles) {
    auto index = client_->Get("/");
    ASSERT_TRUE(index);
    EXPECT_EQ(index->status, 200);
    EXPECT_EQ(index->body, "<!doctype html><p>index</p>");
    auto js = client_->Get("/app.js");
    ASSERT_TRUE(js);
    EXPECT_EQ(js->status, 200);
    EXPECT_EQ(js->get_header_value("Content-Type"), "application/javascript; charset=utf-8");
    auto css = client_->Get("/sub/style.css");
    ASSERT_TRUE(css);
    EXPECT_EQ(css->status, 200);
}

TEST_F(ViewTest, RefusesEveryPathOutsideItsFolder) {
    for (const char* path :
         {"/../secret.txt", "/../secret.js", "/sub/../../secret.js", "/%2e%2e/secret.js",
          "/%2E%2E/secret.js", "/..%2fsecret.js", "/sub/%2e%2e/%2e%2e/secret.js", "/..\\secret.js",
          "/%2e%2e%5csecret.js", "/link.js", "//secret.js", "/./app.js", "/sub//style.css",
          "/notes.txt", "/sub", "/nothing.js", "/%00", "/app.js%00.html"}) {
        auto r = client_->Get(path);
        if (!r) continue;  // a connection the server dropped serves nothing either
        EXPECT_GE(r->status, 400) << path;
        EXPECT_EQ(r->body.find(kSecret), std::string::npos) << path;
    }
    // A raw request line, past any client-side path handling.
    httplib::Client raw("127.0.0.1", port_);
    raw.set_url_encode(false);
    auto r = raw.Get("/../../../../../../etc/passwd");
    if (r) {
        EXPECT_GE(r->status, 400);
        EXPECT_EQ(r->body.find("root:"), std::string::npos);
    }
}

TEST_F(ViewTest, AnswersOnlyLoopbackHostNames) {
    for (const char* host : {"127.0.0.1", "localhost", "[::1]", "127.1.2.3"}) {
        auto r =
            client_->Get("/api/info", {{"Host", std::string(host) + ":" + std::to_string(port_)}});
        ASSERT_TRUE(r);
        EXPECT_EQ(r->status, 200) << host;
    }
    for (const char* host : {"evil.example", "127.0.0.1.evil.example", "10.0.0.1", "[::2]", ""}) {
        auto r =
            client_->Get("/api/info", {{"Host", std::string(host) + ":" + std::to_string(port_)}});
        ASSERT_TRUE(r);
        EXPECT_EQ(r->status, 403) << host;
        EXPECT_EQ(r->body.find("\"points\""), std::string::npos) << host;
    }
    EXPECT_TRUE(view::is_loopback_host("127.0.0.1"));
    EXPECT_FALSE(view::is_loopback_host("127.0.0.256"));
    EXPECT_FALSE(view::is_loopback_host("0.0.0.0"));
}

TEST(ViewPaths, SafeRelativePaths) {
    EXPECT_TRUE(view::is_safe_relative_path("index.html"));
    EXPECT_TRUE(view::is_safe_relative_path("vendor/three.module.js"));
    EXPECT_TRUE(view::is_safe_relative_path("a..b/c.js"));
    for (const char* bad :
         {"", "..", "../x", "a/../b", "a/./b", ".", "a//b", "/abs", "a/", "a\\b", "c:x", "a\nb"})
        EXPECT_FALSE(view::is_safe_relative_path(bad)) << bad;
}

TEST_F(ViewTest, StopEndsServeAndAPortInUseIsAnError) {
    view::ServerConfig cfg;
    cfg.web_root = (dir_ / "web").string();
    view::Server other(*vm_, cfg);
    EXPECT_THROW(other.bind("127.0.0.1", port_), Error);
    view::Server early(*vm_, cfg);
    early.bind("127.0.0.1", 0);
    early.stop();
    EXPECT_TRUE(early.serve()) << "stop() before serve(): serve() returns at once";
}

TEST_F(ViewTest, GiColoursFollowThePointsAndMustMatchTheirCount) {
    view::ServerConfig cfg;
    cfg.web_root = (dir_ / "web").string();
    const size_t n = vm_->points().size();
    for (size_t i = 0; i < n; ++i) cfg.gi_colors.push_back({float(i % 7) / 7, 0.5f, 1.0f});
    view::Server gi(*vm_, cfg);
    const int port = gi.bind("127.0.0.1", 0);
    std::thread t([&] { gi.serve(); });
    httplib::Client c("127.0.0.1", port);
    auto info = c.Get("/api/info");
    auto pts = c.Get("/api/points");
    gi.stop();
    t.join();
    ASSERT_TRUE(info && pts);
    EXPECT_EQ(json::parse(info->body)["gi"], true);
    ASSERT_EQ(pts->body.size(), n * (12 + 12 + 3 + 4 + 3));
    for (size_t i = 0; i < n; ++i)
        ASSERT_EQ(uint8_t(pts->body[31 * n + 3 * i]), linear_to_srgb8(float(i % 7) / 7)) << i;
    cfg.gi_colors.pop_back();
    EXPECT_THROW(view::Server(*vm_, cfg), Error);
}

TEST(ViewServer, AWebFolderWithoutIndexIsAnError) {
    VisibilityMap vm =
        build_vmap(test::sample(test::scene_path("cornell-bunny"), 300, 1), test::cpu_params(4, 4));
    view::ServerConfig cfg;
    cfg.web_root = "/nonexistent/web";
    try {
        view::Server s(vm, cfg);
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("/nonexistent/web"), std::string::npos);
    }
    const fs::path empty =
        fs::temp_directory_path() / ("vmap_view_empty_" + std::to_string(getpid()));
    fs::create_directories(empty);
    cfg.web_root = empty.string();
    EXPECT_THROW(view::Server(vm, cfg), Error);
    fs::remove_all(empty);
}

}  // namespace
}  // namespace vmap
