// AtomicFile (vmap/files.h): a unique temporary, written, synced, renamed, folder synced.
#include "vmap/files.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include "vmap/error.h"

namespace vmap::io {
namespace {

namespace fs = std::filesystem;

std::string folder_of(const std::string& path) {
    const fs::path dir = fs::path(path).parent_path();
    return dir.empty() ? std::string(".") : dir.string();
}

// ".<name>.<pid>.<serial>.<clock>.tmp" in the output's folder: hidden, unique per process
// and per file, so no two writers ever share one.
std::string temp_name(const std::string& path, int attempt) {
    static std::atomic<uint64_t> serial{0};
    const fs::path p(path);
    const auto tick = std::chrono::steady_clock::now().time_since_epoch().count();
    const std::string name = fmt::format(".{}.{}.{}.{:x}.tmp", p.filename().string(), ::getpid(),
                                         serial.fetch_add(1), uint64_t(tick) + attempt);
    return (p.parent_path() / name).string();
}

void sync_folder(const std::string& path) {
    const int fd = ::open(folder_of(path).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) return;  // the rename is done; a folder we cannot open cannot be synced
    ::fsync(fd);
    ::close(fd);
}

// Removes the temporaries of `path` that processes which no longer exist left behind (killed
// during a save). Only names of our own pattern, whose process id is gone, are touched.
void remove_stale_temps(const std::string& path) {
    const fs::path p(path);
    const std::string prefix = fmt::format(".{}.", p.filename().string());
    std::error_code ec;
    for (fs::directory_iterator it(folder_of(path), ec), end; !ec && it != end; it.increment(ec)) {
        const std::string name = it->path().filename().string();
        if (name.size() <= prefix.size() + 4 || name.compare(0, prefix.size(), prefix) != 0 ||
            name.compare(name.size() - 4, 4, ".tmp") != 0)
            continue;
        const char* digits = name.c_str() + prefix.size();
        char* stop = nullptr;
        const long pid = std::strtol(digits, &stop, 10);
        if (stop == digits || *stop != '.' || pid <= 0 || pid == ::getpid()) continue;
        if (::kill(pid_t(pid), 0) != 0 && errno == ESRCH) ::unlink(it->path().c_str());
    }
}

}  // namespace

AtomicFile::AtomicFile(const std::string& path) : path_(path) {
    check_output_path(path);
    remove_stale_temps(path);
    for (int attempt = 0; attempt < 100 && fd_ < 0; ++attempt) {
        temp_ = temp_name(path, attempt);
        fd_ = ::open(temp_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
        if (fd_ < 0 && errno != EEXIST)
            throw Error(fmt::format("{}: cannot create a file in {}: {}", path, folder_of(path),
                                    std::strerror(errno)));
    }
    if (fd_ < 0) throw Error(fmt::format("{}: cannot create a unique temporary file", path));
}

AtomicFile::~AtomicFile() {
    if (fd_ >= 0) ::close(fd_);
    if (!committed_) ::unlink(temp_.c_str());
}

int AtomicFile::write_at(const void* data, size_t n, off_t at) noexcept {
    const auto* p = static_cast<const char*>(data);
    for (size_t done = 0; done < n;) {
        const ssize_t got = ::pwrite(fd_, p + done, n - done, at + off_t(done));
        if (got < 0 && errno == EINTR) continue;
        if (got <= 0) return got < 0 ? errno : EIO;
        done += size_t(got);
    }
    return 0;
}

void AtomicFile::start_writeback(off_t at, size_t n) noexcept {
#ifdef __linux__
    // Only starts the writeback: commit()'s fsync is what makes the bytes durable. A failure
    // here (a file system without it) changes nothing but the timing.
    (void)::sync_file_range(fd_, at, off_t(n), SYNC_FILE_RANGE_WRITE);
#else
    (void)at, (void)n;
#endif
}

void AtomicFile::write(const void* data, size_t n) {
    const auto* p = static_cast<const char*>(data);
    for (size_t done = 0; done < n;) {
        const ssize_t got = ::write(fd_, p + done, n - done);
        if (got < 0 && errno == EINTR) continue;
        if (got <= 0) fail(got < 0 ? errno : EIO);
        done += size_t(got);
    }
}

void AtomicFile::fail(int err) {
    throw Error(fmt::format("{}: write failed: {}", path_, std::strerror(err)));
}

void AtomicFile::commit() {
    if (::fsync(fd_) != 0) fail(errno);
    const int fd = fd_;
    fd_ = -1;
    if (::close(fd) != 0) fail(errno);
    if (::rename(temp_.c_str(), path_.c_str()) != 0)
        throw Error(fmt::format("{}: cannot put the finished file in place: {}", path_,
                                std::strerror(errno)));
    committed_ = true;
    sync_folder(path_);
}

void write_file_atomic(const std::string& path, std::string_view bytes) {
    AtomicFile f(path);
    f.write(bytes);
    f.commit();
}

void check_output_path(const std::string& path, const std::string& option) {
    const std::string who = option.empty() ? path : fmt::format("{}: {}", path, option);
    if (path.empty()) throw Error(fmt::format("{}: the output path is empty", option));
    const std::string dir = folder_of(path);
    struct stat st {};
    if (::stat(dir.c_str(), &st) != 0)
        throw Error(fmt::format("{}: the folder {} does not exist", who, dir));
    if (!S_ISDIR(st.st_mode)) throw Error(fmt::format("{}: {} is not a folder", who, dir));
    if (::access(dir.c_str(), W_OK | X_OK) != 0)
        throw Error(
            fmt::format("{}: cannot write in the folder {}: {}", who, dir, std::strerror(errno)));
    if (::stat(path.c_str(), &st) == 0) {
        if (S_ISDIR(st.st_mode)) throw Error(fmt::format("{}: is a folder", who));
        if (!S_ISREG(st.st_mode))
            throw Error(fmt::format("{}: is not a regular file (a FIFO, socket or device)", who));
    }
}

void make_output_folder(const std::string& dir, const std::string& option) {
    std::error_code ec;
    if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
        throw Error(fmt::format("{}: {}: is a file, not a folder", option, dir));
    fs::create_directories(dir, ec);
    if (ec)
        throw Error(fmt::format("{}: {}: cannot create the folder: {}", option, dir, ec.message()));
    check_output_path((fs::path(dir) / "probe").string(), option);
}

bool same_file(const std::string& a, const std::string& b) {
    struct stat sa {
    }, sb{};
    if (::stat(a.c_str(), &sa) != 0 || ::stat(b.c_str(), &sb) != 0) return false;
    return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
}

void check_input_path(const std::string& path) {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) {
        if (errno == ENOENT) throw Error(fmt::format("{}: no such file", path));
        throw Error(fmt::format("{}: cannot open: {}", path, std::strerror(errno)));
    }
    if (S_ISDIR(st.st_mode)) throw Error(fmt::format("{}: is a folder, not a file", path));
    if (!S_ISREG(st.st_mode))
        throw Error(fmt::format("{}: is not a regular file (a FIFO, socket or device)", path));
}

}  // namespace vmap::io
