// Every file vmap writes goes through AtomicFile: the bytes go to a temporary file in the
// output's folder whose name is unique to this process and this file (created with O_EXCL), the
// temporary is synced and renamed onto the output, and the folder is synced. Readers see the old
// file or the whole new one, never a mix; two writers to one path leave one of the two complete
// files; a failure or an early exit (exception) removes the temporary.
#pragma once

#include <sys/types.h>

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace vmap::io {

class AtomicFile {
  public:
    // Creates the temporary next to `path`. Throws vmap::Error naming `path` when the folder is
    // missing or not writable.
    explicit AtomicFile(const std::string& path);
    ~AtomicFile();  // removes the temporary unless committed
    AtomicFile(const AtomicFile&) = delete;
    AtomicFile& operator=(const AtomicFile&) = delete;

    // Appends; throws vmap::Error naming the output on a write error (e.g. a full disk).
    void write(const void* data, size_t n);
    void write(std::string_view bytes) { write(bytes.data(), bytes.size()); }
    // Writes at an offset without throwing (safe from several threads at once); returns 0 or
    // the errno of the failure. Pass it to fail() on the calling thread.
    int write_at(const void* data, size_t n, off_t at) noexcept;
    // Starts the disk's writeback of bytes [at, at + n) already written, without waiting for
    // it (Linux's sync_file_range; nothing elsewhere). A large file written in pieces so has
    // most of its bytes on disk by the time commit()'s fsync waits. Thread-safe; best effort.
    void start_writeback(off_t at, size_t n) noexcept;
    [[noreturn]] void fail(int err);

    // fsync, close, rename onto the output, fsync the folder. Throws vmap::Error naming the
    // output (and the reason) on failure; the temporary is then removed.
    void commit();

    const std::string& path() const { return path_; }
    const std::string& temp_path() const { return temp_; }

  private:
    std::string path_, temp_;
    int fd_ = -1;
    bool committed_ = false;
};

// The whole of `bytes` to `path` through an AtomicFile.
void write_file_atomic(const std::string& path, std::string_view bytes);

// Before any work: throws vmap::Error naming `path` (and `option` when given) unless `path` can
// become a file: its folder exists and is a writable folder, and `path` is not a folder, a FIFO
// or a device.
void check_output_path(const std::string& path, const std::string& option = "");

// Creates the folder `dir` (and its parents) for outputs, before any work; throws vmap::Error
// naming `option` and `dir` when it cannot be created or written into.
void make_output_folder(const std::string& dir, const std::string& option);

// True when `a` and `b` name one existing file (same device and inode), however spelled.
bool same_file(const std::string& a, const std::string& b);

// A path given as input that is not a regular file: throws vmap::Error naming it ("is a
// folder", "is a FIFO or device", "no such file"). Opening a FIFO would block forever.
void check_input_path(const std::string& path);

}  // namespace vmap::io
