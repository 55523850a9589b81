// NumPy's .npz (a zip of .npy files, stored uncompressed), written for `vmap validate
// --dump-eyes` and read back by its tests: `numpy.load` opens it, and so does read_npz, which
// accepts only what write_npz writes (stored entries, .npy version 1.0, C order).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace vmap::detail {

struct NpyArray {
    std::string name;             // entry name without ".npy"
    std::string descr;            // NumPy dtype string: "<f4", "<f8", "<u4", "|u1", "<i4"
    std::vector<uint64_t> shape;  // empty: a scalar
    std::string bytes;            // the elements, little-endian, C order

    uint64_t count() const;
    size_t item_size() const;  // from descr's digits
};

template <class T>
NpyArray npy_array(std::string name, std::string descr, std::vector<uint64_t> shape, const T* data,
                   size_t n) {
    return NpyArray{std::move(name), std::move(descr), std::move(shape),
                    std::string(reinterpret_cast<const char*>(data), n * sizeof(T))};
}

// The arrays as one .npz file, written atomically (vmap/files.h). Throws vmap::Error naming
// `path` when an array's bytes do not match its shape and dtype or the file cannot be written.
void write_npz(const std::string& path, const std::vector<NpyArray>& arrays);

// The arrays of a file write_npz wrote. Throws vmap::Error naming `path` and the entry for
// anything else (compressed entries, a bad CRC, a bad .npy header, a truncated file).
std::vector<NpyArray> read_npz(const std::string& path);

// The .npy bytes of one array, and back (errors name `where`).
std::string npy_bytes(const NpyArray& a);
NpyArray parse_npy(std::string_view data, const std::string& name, const std::string& where);

}  // namespace vmap::detail
