// `vmap info`: what a .vmap file (or a sharded map's index) holds.
#include <fmt/format.h>

#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>

#include "apps/commands.h"
#include "vmap/files.h"
#include "vmap/vmap.h"

namespace vmap::cli {
namespace {

namespace fs = std::filesystem;

int run_info(const std::string& path, bool json) {
    io::check_input_path(path);
    VisibilityMap vm = load_vmap(path);
    if (json) {
        nlohmann::json j = params_json(vm);
        j["file"] = path;
        j["bytes"] = fs::file_size(path);
        j["points"] = vm.points().size();
        j["links"] = vm.num_links();
        j["links_per_level"] = links_per_level(vm);
        const std::array<double, 3>& o = vm.points().origin;
        if (o != std::array<double, 3>{0, 0, 0}) j["origin"] = o;
        fmt::print("{}\n", j.dump(2));
        return 0;
    }
    fmt::print("file:       {} ({} bytes)\n", path, fs::file_size(path));
    fmt::print("points:     {}\n", vm.points().size());
    const std::array<double, 3>& o = vm.points().origin;
    if (o != std::array<double, 3>{0, 0, 0})
        fmt::print("origin:     ({}, {}, {}): the input's coordinates are the points' plus this\n",
                   o[0], o[1], o[2]);
    print_params(vm);
    fmt::print("links:      {}\n", vm.num_links());
    print_tree_summary(vm);
    return 0;
}

}  // namespace

// `vmap info`: what a .vmap file holds.
Command add_info_command(CLI::App& app) {
    auto path = std::make_shared<std::string>();
    auto json = std::make_shared<bool>(false);
    auto* info = app.add_subcommand("info", "Describe a .vmap file");
    info->add_option("file", *path, "The .vmap file")->required();
    info->add_flag("--json", *json, "Print it as one JSON object (for scripts)");
    return {info, [path, json]() { return run_info(*path, *json); }};
}

}  // namespace vmap::cli
