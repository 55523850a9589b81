// Option parsing shared by the subcommands in apps/ (apps/commands.h).
#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <sstream>

#include "apps/commands.h"
#include "vmap/error.h"
#include "vmap/scene.h"

namespace vmap::cli {

bool ends_with_ci(std::string s, const std::string& suffix) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
    return s.size() >= suffix.size() &&
           s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

bool sampled_input(const std::string& path, bool as_points) {
    try {
        return is_scene_input(path, as_points);
    } catch (const Error&) {
        return true;
    }
}

void print_notes(const std::vector<std::string>& notes) {
    for (const std::string& note : notes) fmt::print(stderr, "note:       {}\n", note);
}

Vec3 parse_vec3(const std::string& text, const std::string& option) {
    float v[3];
    size_t at = 0;
    for (int k = 0; k < 3; ++k) {
        const size_t end = k < 2 ? text.find(',', at) : text.size();
        if (end == std::string::npos) break;
        const std::string part = text.substr(at, end - at);
        size_t used = 0;
        try {
            v[k] = std::stof(part, &used);
        } catch (const std::exception&) {
            used = 0;
        }
        if (used == 0 || used != part.size() || !std::isfinite(v[k]))
            throw Error(fmt::format("{}: '{}' is not x,y,z (three finite numbers)", option, text));
        at = end + 1;
        if (k == 2) return {v[0], v[1], v[2]};
    }
    throw Error(fmt::format("{}: '{}' is not x,y,z (three finite numbers)", option, text));
}

std::pair<int, int> parse_size(const std::string& text, const std::string& option) {
    int w = 0, h = 0;
    char x = 0, extra = 0;
    if (std::sscanf(text.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X'))
        throw Error(fmt::format("{}: '{}' is not WxH (e.g. 800x600)", option, text));
    if (w < 1 || h < 1 || w > 16384 || h > 16384)
        throw Error(fmt::format("{}: {}x{} out of range (1..16384 each)", option, w, h));
    return {w, h};
}

void check_output(const std::string& path, const char* option) {
    if (path.empty()) return;
    const std::filesystem::path dir = std::filesystem::path(path).parent_path();
    if (!dir.empty() && !std::filesystem::is_directory(dir))
        throw Error(
            fmt::format("{}: {}: the folder {} does not exist", path, option, dir.string()));
}

}  // namespace vmap::cli
