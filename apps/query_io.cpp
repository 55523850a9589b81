#include "apps/query_io.h"

#include <fmt/format.h>

#include <charconv>
#include <cstring>
#include <fstream>
#include <iterator>

#include "vmap/error.h"
#include "vmap/npy.h"
#include "vmap/parallel.h"

namespace vmap::cli {
namespace {

std::string slurp(const std::string& path) {
    std::string data;
    if (path == "-") {
        char buf[1 << 16];
        size_t n;
        while ((n = std::fread(buf, 1, sizeof buf, stdin)) > 0) data.append(buf, n);
        return data;
    }
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(fmt::format("{}: cannot open the pairs file", path));
    in.seekg(0, std::ios::end);
    data.resize(static_cast<size_t>(in.tellg()));
    in.seekg(0);
    in.read(data.data(), std::streamsize(data.size()));
    return data;
}

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r'; }

// One line's pair, or nothing for a blank or comment line.
bool parse_line(const char* p, const char* end, uint32_t& i, uint32_t& j) {
    while (p < end && is_space(*p)) ++p;
    if (p == end || *p == '#') return false;
    auto r = std::from_chars(p, end, i);
    if (r.ec != std::errc() || r.ptr == end || !(is_space(*r.ptr) || *r.ptr == ','))
        throw std::invalid_argument("");
    p = r.ptr;
    while (p < end && (is_space(*p) || *p == ',')) ++p;
    r = std::from_chars(p, end, j);
    if (r.ec != std::errc()) throw std::invalid_argument("");
    p = r.ptr;
    while (p < end && is_space(*p)) ++p;
    if (p != end) throw std::invalid_argument("");
    return true;
}

std::vector<uint32_t> parse_text(const std::string& data, const std::string& name) {
    std::vector<uint32_t> ids;
    ids.reserve(data.size() / 6);
    const char* p = data.data();
    const char* end = p + data.size();
    for (uint64_t line = 1; p < end; ++line) {
        const char* nl = static_cast<const char*>(std::memchr(p, '\n', size_t(end - p)));
        const char* le = nl ? nl : end;
        uint32_t i, j;
        try {
            if (parse_line(p, le, i, j)) ids.insert(ids.end(), {i, j});
        } catch (const std::invalid_argument&) {
            const std::string text(p, std::min<size_t>(size_t(le - p), 60));
            throw Error(fmt::format("{}: line {}: expected two point ids 'I J', found '{}'", name,
                                    line, text));
        }
        p = le + 1;
    }
    return ids;
}

}  // namespace

std::vector<uint32_t> read_pairs(const std::string& path) {
    const std::string data = slurp(path);
    const std::string name = path == "-" ? "stdin" : path;
    if (data.size() >= 6 && std::memcmp(data.data(), "\x93NUMPY", 6) == 0)
        return read_npy_pairs(data, name);
    return parse_text(data, name);
}

void write_answers(std::FILE* out, std::span<const uint32_t> ids, std::span<const uint8_t> ans,
                   const char* (*word)(uint8_t)) {
    constexpr size_t kBlock = 1 << 16;
    const size_t blocks = (ans.size() + kBlock - 1) / kBlock;
    std::vector<std::string> text(std::min<size_t>(blocks, 64));
    for (size_t b0 = 0; b0 < blocks; b0 += text.size()) {
        const size_t nb = std::min(text.size(), blocks - b0);
        parallel_for(size_t(0), nb, [&](size_t b) {
            fmt::memory_buffer buf;
            const size_t k1 = std::min(ans.size(), (b0 + b + 1) * kBlock);
            for (size_t k = (b0 + b) * kBlock; k < k1; ++k)
                fmt::format_to(std::back_inserter(buf), "{} {} {}\n", ids[2 * k], ids[2 * k + 1],
                               word(ans[k]));
            text[b].assign(buf.data(), buf.size());
        });
        for (size_t b = 0; b < nb; ++b) std::fwrite(text[b].data(), 1, text[b].size(), out);
    }
}

void write_id_lists(std::FILE* out, const VisibleSets& sets, bool one_line_each) {
    fmt::memory_buffer buf;
    const size_t n = sets.offsets.size() - 1;
    for (size_t k = 0; k < n; ++k) {
        for (uint64_t e = sets.offsets[k]; e < sets.offsets[k + 1]; ++e) {
            const bool last = e + 1 == sets.offsets[k + 1];
            fmt::format_to(std::back_inserter(buf), "{}{}", sets.targets[e],
                           one_line_each && !last ? ' ' : '\n');
        }
        if (one_line_each && sets.offsets[k] == sets.offsets[k + 1]) buf.push_back('\n');
        if (buf.size() > (1 << 20)) {
            std::fwrite(buf.data(), 1, buf.size(), out);
            buf.clear();
        }
    }
    std::fwrite(buf.data(), 1, buf.size(), out);
}

}  // namespace vmap::cli
