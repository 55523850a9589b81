// Text-file helpers shared by the PLY and OFF readers (internal to src/io): reading a whole file
// into memory, error messages that name the file, and locale-free number parsing with from_chars.
#pragma once

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "vmap/error.h"

namespace vmap::detail {

template <class... Parts>
[[noreturn]] void fail(const std::string& path, const Parts&... parts) {
    std::ostringstream out;
    out << path << ": ";
    (out << ... << parts);
    throw Error(out.str());
}

// Tokens from a broken or binary file end up in messages; keep those one short printable line.
inline std::string quoted(std::string_view text) {
    constexpr size_t kMax = 32;
    std::string out = "'";
    for (size_t i = 0; i < text.size() && i < kMax; ++i) {
        const unsigned char c = static_cast<unsigned char>(text[i]);
        out += (c >= 0x20 && c < 0x7f) ? static_cast<char>(c) : '?';
    }
    if (text.size() > kMax) out += "...";
    return out + "'";
}

struct FileBuffer {
    std::unique_ptr<char[]> bytes;
    size_t size = 0;
    const char* begin() const { return bytes.get(); }
    const char* end() const { return bytes.get() + size; }
};

inline FileBuffer load_file(const std::string& path) {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec)) fail(path, "is a directory, not a file");
    std::FILE* file = std::fopen(path.c_str(), "rb");
    if (file == nullptr) {
        if (errno == ENOENT) fail(path, "no such file");
        fail(path, "cannot open: ", std::strerror(errno));
    }
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> closer(file, &std::fclose);
    const auto size = std::filesystem::file_size(path, ec);
    if (ec) fail(path, "cannot determine the file size: ", ec.message());
    FileBuffer buffer;
    // make_unique_for_overwrite: zero-filling tens of megabytes first would be wasted work.
    buffer.bytes = std::make_unique_for_overwrite<char[]>(size + 1);
    buffer.size = static_cast<size_t>(size);
    if (std::fread(buffer.bytes.get(), 1, buffer.size, file) != buffer.size) {
        fail(path, "read error: ", std::ferror(file) ? std::strerror(errno) : "file shrank");
    }
    buffer.bytes[buffer.size] = '\0';
    return buffer;
}

inline bool is_blank(char c) {
    return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

// Appends the blank-separated words of [b, e) to `words`, as views into that text.
inline void append_words(const char* b, const char* e, std::vector<std::string_view>& words) {
    while (b != e) {
        while (b != e && is_blank(*b)) ++b;
        const char* start = b;
        while (b != e && !is_blank(*b)) ++b;
        if (b != start) words.emplace_back(start, b - start);
    }
}

// from_chars rejects a leading '+', which some writers emit; "+-1" must still be rejected.
inline const char* skip_plus(const char* b, const char* e) {
    if (e - b >= 2 && b[0] == '+' && b[1] != '-' && b[1] != '+') return b + 1;
    return b;
}

// from_chars reports values beyond the type's range as errors; overflow should become an
// infinity (rejected later with a clear message) and underflow a zero, as strtod would give.
template <class T>
bool parse_real(std::string_view token, T& out) {
    const char* b = skip_plus(token.data(), token.data() + token.size());
    const char* e = token.data() + token.size();
    auto [ptr, ec] = std::from_chars(b, e, out);
    if (ptr != e) return false;
    if (ec == std::errc()) return true;
    if (ec != std::errc::result_out_of_range) return false;
    double wide = 0;
    auto [wptr, wec] = std::from_chars(b, e, wide);
    if (wptr == e && wec == std::errc()) {
        out = static_cast<T>(wide);
        return true;
    }
    const bool negative = *b == '-';
    const char* mantissa = negative ? b + 1 : b;
    const char* exponent = std::find_if(mantissa, e, [](char c) { return c == 'e' || c == 'E'; });
    const bool underflow = exponent != e ? (exponent + 1 != e && exponent[1] == '-')
                                         : (*mantissa == '0' || *mantissa == '.');
    const T magnitude = underflow ? T(0) : std::numeric_limits<T>::infinity();
    out = negative ? -magnitude : magnitude;
    return true;
}

inline bool parse_int(std::string_view token, int64_t& out) {
    const char* e = token.data() + token.size();
    auto [ptr, ec] = std::from_chars(skip_plus(token.data(), e), e, out);
    return ec == std::errc() && ptr == e && !token.empty();
}

}  // namespace vmap::detail
