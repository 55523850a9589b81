// `vmap view`: an interactive viewer in the browser (src/view/view_server.h, web/).
//   vmap view [MAP.vmap | SCENE.json | CLOUD.ply] [--scene SCENE] [--port P] [--host H] [--gi]
// A scene or cloud is sampled and its V-map built first. The server binds 127.0.0.1 (a free port
// unless --port) and prints the URL; Ctrl-C (SIGINT) or SIGTERM stops it cleanly (exit 0).
#include <fmt/format.h>
#include <pthread.h>
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <thread>

#include "apps/commands.h"
#include "view/view_server.h"
#include "vmap/error.h"
#include "vmap/gi.h"
#include "vmap/io.h"
#include "vmap/render.h"
#include "vmap/scene.h"
#include "vmap/version.h"

namespace vmap::cli {
namespace {

namespace fs = std::filesystem;

struct ViewArgs {
    InputOptions in;  // the input and its overrides (vmap/input.h)
    std::string scene, host = "127.0.0.1", web;
    int port = 0;
    Backend backend = Backend::kAuto;
    bool gi = false;
};

// The map to show: loaded, or built from a scene, mesh or cloud (vmap/input.h); the camera and
// name from --scene, else the input's.
VisibilityMap input_map(const ViewArgs& a, view::ServerConfig& cfg) {
    if (!a.scene.empty()) {
        const Scene sc = load_scene(a.scene);
        cfg.camera = sc.camera;
        cfg.name = sc.name;
    }
    InputOptions io = a.in;
    io.progress = sampling_progress();
    Input in = load_input(io);
    print_notes(in.notes);
    if (!cfg.camera) cfg.camera = in.camera;
    if (cfg.name.empty()) cfg.name = in.name;
    if (in.vmap) return std::move(*in.vmap);
    BuildParams bp;
    bp.octree = in.octree;
    bp.visibility.roughness = in.roughness;
    bp.backend = a.backend;
    bp.progress = cli::stderr_progress();
    BuildStats st;
    VisibilityMap vm = build_vmap(std::move(in.points), bp, &st, a.in.path);
    fmt::print(
        "built:      V-map of {} points at max_height {}: {} leaves, {} links, {:.2f} s on "
        "{}\n",
        vm.points().size(), bp.octree.max_height, vm.octree().num_leaves(), vm.num_links(),
        st.seconds_total, st.backend);
    return vm;
}

// GI display colours in input order (the page's "GI" mode).
std::vector<Vec3> gi_colors(const VisibilityMap& vm, Backend backend) {
    GiParams gp;
    gp.backend = backend;
    gp.progress = cli::stderr_progress();
    GiStats st;
    const auto t0 = std::chrono::steady_clock::now();
    const std::vector<Vec3> B = solve_radiosity(vm, gp, &st);
    std::vector<Vec3> colors;
    tone_map(vm, B, 0, colors);
    std::vector<Vec3> out(colors.size());
    for (size_t k = 0; k < colors.size(); ++k) out[vm.order()[k]] = colors[k];
    fmt::print("gi:         {} bounces, theta {} on {}: {:.2f} s\n", gp.bounces, gp.theta,
               st.backend,
               std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    return out;
}

// SIGINT and SIGTERM are blocked in every thread (set before any is started) and taken by one
// waiting thread: while serving it stops the server (serve() returns, main exits 0); before,
// it ends the process at once (exit 130), as an interrupted build would.
std::atomic<view::Server*> g_server{nullptr};

void start_signal_thread() {
    sigset_t set;
    sigemptyset(&set);
    sigaddset(&set, SIGINT);
    sigaddset(&set, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &set, nullptr);
    std::thread([set] {
        int sig = 0;
        sigwait(&set, &sig);
        view::Server* s = g_server.load();
        if (!s) {
            std::fputs("vmap view: interrupted\n", stderr);
            std::_Exit(130);
        }
        s->stop();
    }).detach();
}

int run_view(ViewArgs& a) {
    if (a.in.path.empty()) a.in.path = default_scene_path();
    if (a.web.empty()) a.web = data_dir() + "/web";
    const fs::path three = fs::path(a.web) / "vendor" / "three.module.js";
    if (!fs::is_regular_file(three))
        throw Error(
            fmt::format("{}: missing: the page needs three.js, fetched at set-up time "
                        "(run scripts/fetch-web.sh)",
                        three.string()));
    start_signal_thread();
    view::ServerConfig cfg;
    cfg.web_root = a.web;
    VisibilityMap vm = input_map(a, cfg);
    if (a.gi) cfg.gi_colors = gi_colors(vm, a.backend);
    view::Server server(std::move(vm), cfg);
    const int port = server.bind(a.host, a.port);
    const VisibilityMap& m = server.map();
    fmt::print("serving:    {} ({} points, octree height {}, {} links)\n", cfg.name,
               m.points().size(), m.octree().height(), m.num_links());
    const std::string host = a.host.find(':') != std::string::npos ? "[" + a.host + "]" : a.host;
    fmt::print("url:        http://{}:{}/   (Ctrl-C stops)\n", host, port);
    std::fflush(stdout);
    g_server = &server;
    const bool ok = server.serve();
    g_server = nullptr;
    if (!ok) throw Error(fmt::format("{}:{}: the server stopped with an error", a.host, port));
    fmt::print("stopped.\n");
    return 0;
}

}  // namespace

Command add_view_command(CLI::App& app) {
    auto a = std::make_shared<ViewArgs>();
    auto* c = app.add_subcommand(
        "view", "Interactive viewer in the browser: a local server holding the V-map");
    add_input_options(c, a->in,
                      "A .vmap file, or a scene (.json), mesh or cloud to build one from "
                      "(default: scenes/cornell-bunny.json)");
    c->add_option("--scene", a->scene, "Take the camera and name from this scene file");
    c->add_option("--host", a->host, "Address to bind (only this machine unless changed)")
        ->capture_default_str();
    c->add_option("--port", a->port, "TCP port (0: a free one)")
        ->check(CLI::Range(0, 65535))
        ->capture_default_str();
    c->add_option("--web", a->web, "The page's folder (default: the source tree's web/)");
    cli::add_choice(c, "--backend", a->backend, "auto, cpu or cuda (building and --gi)");
    c->add_flag("--gi", a->gi, "Compute global illumination first (the page's GI colours)");
    return {c, [a] { return run_view(*a); }};
}

}  // namespace vmap::cli
