// JSON files with located errors (io/json_file.h).
#include "io/json_file.h"

#include <fmt/format.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "vmap/error.h"
#include "vmap/files.h"

namespace vmap::io {
namespace {

using nlohmann::json;

// A SAX consumer that only tracks where it is: a stack of open objects and arrays with the
// current key or index. When the parser reports an error, path() is where it happened.
class PathTracker : public nlohmann::json_sax<json> {
  public:
    bool null() override { return value(); }
    bool boolean(bool) override { return value(); }
    bool number_integer(number_integer_t) override { return value(); }
    bool number_unsigned(number_unsigned_t) override { return value(); }
    bool number_float(number_float_t, const string_t&) override { return value(); }
    bool string(string_t&) override { return value(); }
    bool binary(binary_t&) override { return value(); }
    bool start_object(std::size_t) override { return open(false); }
    bool start_array(std::size_t) override { return open(true); }
    bool end_object() override { return close(); }
    bool end_array() override { return close(); }
    bool key(string_t& k) override {
        frames_.back().key = k;
        return true;
    }
    bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception&) override {
        return false;
    }

    std::string path() const {
        std::string p;
        for (const Frame& f : frames_) {
            if (f.array)
                p += fmt::format("[{}]", f.index);
            else if (!f.key.empty())
                p += (p.empty() ? "" : ".") + f.key;
        }
        return p;
    }

  private:
    struct Frame {
        bool array = false;
        size_t index = 0;
        std::string key;
    };
    bool value() {  // a value ended: the next one is at the next index, or after a new key
        if (!frames_.empty()) {
            if (frames_.back().array) ++frames_.back().index;
            frames_.back().key.clear();
        }
        return true;
    }
    bool open(bool array) {
        frames_.push_back({array, 0, {}});
        return true;
    }
    bool close() {
        frames_.pop_back();
        return value();
    }
    std::vector<Frame> frames_;
};

// nlohmann's message without its "[json.exception.parse_error.101] " prefix.
std::string plain(const std::string& what) {
    const size_t k = what.find("] ");
    return what.rfind("[json.exception.", 0) == 0 && k != std::string::npos ? what.substr(k + 2)
                                                                            : what;
}

}  // namespace

std::string json_error_path(const std::string& text) {
    PathTracker t;
    if (json::sax_parse(text, &t, json::input_format_t::json, true, true)) return "";
    return t.path();
}

json parse_json_file(const std::string& path) {
    check_input_path(path);
    std::error_code ec;
    const auto bytes = std::filesystem::file_size(path, ec);
    constexpr uintmax_t kMaxBytes = uintmax_t(64) << 20;  // scene files are a few kilobytes
    if (!ec && bytes > kMaxBytes)
        throw Error(fmt::format("{}: {} bytes is too large for a scene file (at most 64 MiB)", path,
                                bytes));
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(fmt::format("{}: cannot open", path));
    std::ostringstream buf;
    buf << in.rdbuf();
    if (!in.good() && !in.eof()) throw Error(fmt::format("{}: read error", path));
    const std::string text = buf.str();
    try {
        return json::parse(text, nullptr, true, /*ignore_comments=*/true);
    } catch (const json::out_of_range& e) {  // number overflow (406)
        const std::string at = json_error_path(text);
        throw Error(fmt::format("{}: {}{} (beyond the double range)", path,
                                at.empty() ? "" : at + ": ", plain(e.what())));
    } catch (const json::exception& e) {
        const std::string at = json_error_path(text);
        throw Error(fmt::format("{}: not valid JSON{}: {}", path, at.empty() ? "" : " at " + at,
                                plain(e.what())));
    }
}

}  // namespace vmap::io
