// Streaming input for the xyz, pcd, obj and stl readers (internal to src/io): a file opened with
// the same messages as load_file, read in blocks of 1 MiB, handed out as lines (numbered from 1)
// or as raw bytes. Memory stays at one block plus the longest line, whatever the file's size; a
// line longer than 1 MiB (a binary file read as text) is an error, not an allocation.
#pragma once

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "io/text_util.h"

namespace vmap::detail {

class InputFile {
  public:
    explicit InputFile(const std::string& path) : path_(path), file_(nullptr, &std::fclose) {
        std::error_code ec;
        if (std::filesystem::is_directory(path, ec)) fail(path, "is a directory, not a file");
        file_.reset(std::fopen(path.c_str(), "rb"));
        if (file_ == nullptr) {
            if (errno == ENOENT) fail(path, "no such file");
            fail(path, "cannot open: ", std::strerror(errno));
        }
        const auto size = std::filesystem::file_size(path, ec);
        if (ec) fail(path, "cannot determine the file size: ", ec.message());
        size_ = static_cast<uint64_t>(size);
    }

    const std::string& path() const { return path_; }
    uint64_t size() const { return size_; }
    // Bytes handed out so far (lines with their newlines, and raw bytes).
    uint64_t offset() const { return offset_; }
    size_t line() const { return line_; }

    // The next line without its "\n" or "\r\n"; false at the end of the file.
    bool next_line(std::string_view& line) {
        constexpr size_t kMaxLine = size_t{1} << 20;
        for (;;) {
            const char* b = buffer_.data() + pos_;
            const char* nl = static_cast<const char*>(std::memchr(b, '\n', end_ - pos_));
            if (nl != nullptr || (eof_ && pos_ != end_)) {
                const size_t n = nl != nullptr ? size_t(nl - b) : end_ - pos_;
                const size_t used = nl != nullptr ? n + 1 : n;
                pos_ += used;
                offset_ += used;
                ++line_;
                line = std::string_view(b, n > 0 && b[n - 1] == '\r' ? n - 1 : n);
                return true;
            }
            if (eof_) return false;
            if (end_ - pos_ >= kMaxLine) {
                fail(path_, "line ", line_ + 1, ": longer than ", kMaxLine,
                     " bytes (not a text file?)");
            }
            refill();
        }
    }

    // Copies the next n bytes to `out`; returns how many there were (fewer at the end).
    size_t read_bytes(char* out, size_t n) {
        size_t got = std::min(n, end_ - pos_);
        if (got > 0) std::memcpy(out, buffer_.data() + pos_, got);  // out may be null when n is 0
        pos_ += got;
        if (got < n) {
            const size_t more = std::fread(out + got, 1, n - got, file_.get());
            check_read();
            read_ += more;
            got += more;
        }
        offset_ += got;
        return got;
    }

  private:
    void refill() {
        // A block of 1 MiB, or what the file has left (plus one byte, to see its end) when that
        // is less, so that small files are not read into a megabyte of zeroes.
        constexpr uint64_t kBlock = uint64_t{1} << 20;
        const uint64_t left = size_ > read_ ? size_ - read_ : 0;
        const size_t want = static_cast<size_t>(std::clamp<uint64_t>(left + 1, 4096, kBlock));
        std::memmove(buffer_.data(), buffer_.data() + pos_, end_ - pos_);
        end_ -= pos_;
        pos_ = 0;
        if (buffer_.size() < end_ + want + 1) buffer_.resize(end_ + want + 1);
        const size_t got = std::fread(buffer_.data() + end_, 1, want, file_.get());
        check_read();
        read_ += got;
        end_ += got;
        eof_ = got < want;
        buffer_[end_] = '\0';
    }

    void check_read() {
        if (std::ferror(file_.get())) fail(path_, "read error: ", std::strerror(errno));
    }

    std::string path_;
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> file_;
    uint64_t size_ = 0;
    uint64_t read_ = 0;  // bytes taken from the file
    std::vector<char> buffer_ = std::vector<char>(1, '\0');
    size_t pos_ = 0, end_ = 0;
    bool eof_ = false;
    uint64_t offset_ = 0;
    size_t line_ = 0;
};

// Splits `line` at blanks and at any character in `separators` (empty words between two
// separators are kept, so "1,,2" has three words; blanks around a separator are not words).
inline void split_fields(std::string_view line, std::string_view separators,
                         std::vector<std::string_view>& words) {
    words.clear();
    size_t i = 0;
    const size_t n = line.size();
    bool after_separator = false;
    while (i < n) {
        while (i < n && is_blank(line[i])) ++i;
        if (i == n) break;
        if (separators.find(line[i]) != std::string_view::npos) {
            if (after_separator || words.empty()) words.emplace_back();
            after_separator = true;
            ++i;
            continue;
        }
        const size_t start = i;
        while (i < n && !is_blank(line[i]) && separators.find(line[i]) == std::string_view::npos)
            ++i;
        words.push_back(line.substr(start, i - start));
        after_separator = false;
    }
    if (after_separator) words.emplace_back();
}

inline std::string lower(std::string_view s) {
    std::string out(s);
    for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return out;
}

}  // namespace vmap::detail
