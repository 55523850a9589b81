// Option parsing shared by the subcommands in apps/ (apps/commands.h).
#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "apps/commands.h"
#include "util/progress.h"
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

Verbosity& verbosity() {
    static Verbosity v = Verbosity::kNormal;
    return v;
}

std::string format_duration(double s) {
    if (!(s >= 0) || s > 1e9) return "a very long time";
    const auto t = static_cast<uint64_t>(s + 0.5);
    if (s < 10) return fmt::format("{:.1f} s", s);
    if (t < 60) return fmt::format("{} s", t);
    if (t < 3600) return fmt::format("{} min {} s", t / 60, t % 60);
    return fmt::format("{} h {} min", t / 3600, (t % 3600) / 60);
}

ProgressCallback stderr_progress() {
    const bool quiet = verbosity() == Verbosity::kQuiet;
    const bool moving = !quiet && detail::stderr_is_terminal();
    return [quiet, moving](const ProgressInfo& p) {
        if (quiet) return true;
        if (p.done == 0 && p.seconds < 1e-3) {
            std::string line = fmt::format("{}: {} to do", p.stage, p.total);
            if (*p.backend) line += fmt::format(" on {}", p.backend);
            if (p.estimate_seconds > 0)
                line += fmt::format(", about {}", format_duration(p.estimate_seconds));
            fmt::print(stderr, "{}\n", line);
            if (*p.note) fmt::print(stderr, "note: {}\n", p.note);
            if (p.estimate_seconds > 3600)
                fmt::print(stderr,
                           "warning: this is estimated to take {}; Ctrl-C stops it (fewer "
                           "--points or a lower --max-height make it smaller)\n",
                           format_duration(p.estimate_seconds));
            return true;
        }
        if (!moving) return true;
        if (p.done >= p.total) {
            fmt::print(stderr, "\r\033[K");
        } else {
            const double f = p.total ? double(p.done) / double(p.total) : 1.0;
            fmt::print(stderr, "\r\033[K{}: {:5.1f}%  {} elapsed, about {} left", p.stage, 100 * f,
                       format_duration(p.seconds),
                       p.done ? format_duration(p.eta_seconds) : std::string("?"));
        }
        std::fflush(stderr);
        return true;
    };
}

}  // namespace vmap::cli
