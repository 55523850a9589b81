// .npz writing and reading (src/validate/npz.h): a zip archive of stored (uncompressed) entries,
// one .npy (version 1.0) each, no zip64 (every entry and the whole file under 4 GiB).
#include "validate/npz.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <fstream>
#include <sstream>

#include "vmap/error.h"
#include "vmap/files.h"

namespace vmap::detail {

uint64_t NpyArray::count() const {
    uint64_t n = 1;
    for (uint64_t s : shape) n *= s;
    return n;
}

size_t NpyArray::item_size() const {
    size_t v = 0;
    for (size_t i = 2; i < descr.size(); ++i) {
        if (descr[i] < '0' || descr[i] > '9' || v > 64) return 0;
        v = 10 * v + size_t(descr[i] - '0');
    }
    return v;
}

namespace {

uint32_t crc32(std::string_view s) {
    static const std::array<uint32_t, 256> table = [] {
        std::array<uint32_t, 256> t{};
        for (uint32_t i = 0; i < 256; ++i) {
            uint32_t c = i;
            for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
            t[i] = c;
        }
        return t;
    }();
    uint32_t c = 0xFFFFFFFFu;
    for (unsigned char b : s) c = table[(c ^ b) & 0xFF] ^ (c >> 8);
    return c ^ 0xFFFFFFFFu;
}

void put(std::string& out, uint64_t v, int bytes) {
    for (int k = 0; k < bytes; ++k) out.push_back(char((v >> (8 * k)) & 0xFF));
}

uint64_t get(std::string_view s, size_t at, int bytes, const std::string& where) {
    if (at + bytes > s.size()) throw Error(fmt::format("{}: truncated", where));
    uint64_t v = 0;
    for (int k = 0; k < bytes; ++k) v |= uint64_t(uint8_t(s[at + k])) << (8 * k);
    return v;
}

std::string shape_text(const std::vector<uint64_t>& shape) {
    std::string s = "(";
    for (uint64_t d : shape) s += fmt::format("{}, ", d);
    if (shape.size() > 1) s.resize(s.size() - 2);
    if (shape.size() == 1) s.pop_back();
    return s + ")";
}

// The value text after `'key': ` in a .npy header dict.
std::string dict_value(const std::string& dict, const std::string& key, const std::string& where) {
    const size_t k = dict.find("'" + key + "':");
    if (k == std::string::npos) throw Error(fmt::format("{}: header: no '{}'", where, key));
    size_t b = dict.find_first_not_of(' ', k + key.size() + 3);
    const char open = b < dict.size() ? dict[b] : 0;
    const size_t e = open == '('    ? dict.find(')', b) + 1
                     : open == '\'' ? dict.find('\'', b + 1) + 1
                                    : dict.find_first_of(",}", b);
    if (b == std::string::npos || e == std::string::npos || e == 0)
        throw Error(fmt::format("{}: header: bad '{}'", where, key));
    return dict.substr(b, e - b);
}

}  // namespace

std::string npy_bytes(const NpyArray& a) {
    if (a.count() * a.item_size() != a.bytes.size())
        throw Error(fmt::format("array '{}': {} bytes for shape {} of {}", a.name, a.bytes.size(),
                                shape_text(a.shape), a.descr));
    std::string dict = fmt::format("{{'descr': '{}', 'fortran_order': False, 'shape': {}, }}",
                                   a.descr, shape_text(a.shape));
    while ((10 + dict.size() + 1) % 64) dict.push_back(' ');
    dict.push_back('\n');
    std::string out("\x93NUMPY\x01\x00", 8);
    put(out, dict.size(), 2);
    return out + dict + a.bytes;
}

NpyArray parse_npy(std::string_view data, const std::string& name, const std::string& where) {
    if (data.size() < 10 || data.substr(0, 6) != "\x93NUMPY" || data[6] != 1)
        throw Error(fmt::format("{}: not a version 1.0 .npy", where));
    const size_t hlen = get(data, 8, 2, where);
    if (10 + hlen > data.size()) throw Error(fmt::format("{}: header: truncated", where));
    const std::string dict(data.substr(10, hlen));
    NpyArray a;
    a.name = name;
    const std::string descr = dict_value(dict, "descr", where);
    if (descr.size() < 2 || descr.front() != '\'' || descr.back() != '\'')
        throw Error(fmt::format("{}: header: bad 'descr' {} (a quoted dtype expected)", where, descr));
    a.descr = descr.substr(1, descr.size() - 2);
    if (dict_value(dict, "fortran_order", where) != "False")
        throw Error(fmt::format("{}: header: fortran_order: only C order is read", where));
    const std::string sh = dict_value(dict, "shape", where);
    if (sh.size() < 2 || sh.front() != '(' || sh.back() != ')')
        throw Error(fmt::format("{}: header: bad shape {} (a tuple expected)", where, sh));
    std::istringstream in(sh.substr(1, sh.size() - 2));
    for (std::string tok; std::getline(in, tok, ',');) {
        const size_t b = tok.find_first_not_of(' ');
        if (b == std::string::npos) continue;
        const size_t e = tok.find_last_not_of(' ') + 1;
        if (tok.find_first_not_of("0123456789", b) < e || e - b > 15)
            throw Error(fmt::format("{}: header: bad shape {}", where, sh));
        a.shape.push_back(std::stoull(tok.substr(b, e - b)));
    }
    a.bytes = std::string(data.substr(10 + hlen));
    // The element count is multiplied out against the body's size, so that a shape whose
    // product overflows 64 bits cannot match a short body.
    bool fits = a.item_size() != 0;
    if (std::find(a.shape.begin(), a.shape.end(), 0) == a.shape.end()) {
        uint64_t room = fits ? a.bytes.size() / a.item_size() : 0;
        for (uint64_t d : a.shape) fits = fits && d <= room, room = fits ? room / d : 0;
    }
    if (!fits || a.bytes.size() != a.count() * a.item_size())
        throw Error(fmt::format("{}: body: {} bytes for shape {} of '{}'", where, a.bytes.size(),
                                sh, a.descr));
    return a;
}

void write_npz(const std::string& path, const std::vector<NpyArray>& arrays) {
    std::string file, central;
    for (const NpyArray& a : arrays) {
        const std::string body = npy_bytes(a), name = a.name + ".npy";
        if (file.size() + body.size() > 0xF0000000u)
            throw Error(fmt::format("{}: over 4 GiB: too large for a zip without zip64", path));
        const uint32_t crc = crc32(body);
        auto header = [&](uint32_t sig, bool central_entry) {
            std::string h;
            put(h, sig, 4);
            if (central_entry) put(h, 20, 2);           // made by
            put(h, 20, 2), put(h, 0, 2), put(h, 0, 2);  // needed, flags, stored
            put(h, 0, 2), put(h, 0x21, 2);              // 1980-01-01 00:00
            put(h, crc, 4), put(h, body.size(), 4), put(h, body.size(), 4);
            put(h, name.size(), 2), put(h, 0, 2);
            if (central_entry) {
                put(h, 0, 2), put(h, 0, 2), put(h, 0, 2);  // comment, disk, internal attributes
                put(h, 0, 4), put(h, file.size(), 4);      // external attributes, local header
            }
            return h + name;
        };
        central += header(0x02014b50u, true);
        file += header(0x04034b50u, false) + body;
    }
    std::string end;
    put(end, 0x06054b50u, 4), put(end, 0, 2), put(end, 0, 2);
    put(end, arrays.size(), 2), put(end, arrays.size(), 2);
    put(end, central.size(), 4), put(end, file.size(), 4), put(end, 0, 2);
    io::write_file_atomic(path, file + central + end);
}

std::vector<NpyArray> read_npz(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(fmt::format("{}: cannot open", path));
    const std::string s((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (s.size() < 22 || get(s, s.size() - 22, 4, path) != 0x06054b50u)
        throw Error(fmt::format("{}: not a zip written by write_npz (no end record)", path));
    const size_t entries = get(s, s.size() - 12, 2, path);
    size_t at = get(s, s.size() - 6, 4, path);
    std::vector<NpyArray> out;
    for (size_t e = 0; e < entries; ++e) {
        if (get(s, at, 4, path) != 0x02014b50u)
            throw Error(fmt::format("{}: central directory entry {}: bad signature", path, e));
        // The fixed 46 bytes of the entry first (the last field read ends there), then its name.
        const size_t size = get(s, at + 24, 4, path), local = get(s, at + 42, 4, path);
        const size_t name_size = get(s, at + 28, 2, path);
        if (at + 46 + name_size > s.size())
            throw Error(fmt::format("{}: central directory entry {}: truncated", path, e));
        const std::string name = s.substr(at + 46, name_size);
        const std::string where = fmt::format("{}: {}", path, name);
        if (get(s, at + 10, 2, path) != 0)
            throw Error(fmt::format("{}: compressed: only stored entries are read", where));
        const uint32_t crc = uint32_t(get(s, at + 16, 4, path));
        const size_t body = local + 30 + get(s, local + 26, 2, path) + get(s, local + 28, 2, path);
        if (body + size > s.size()) throw Error(fmt::format("{}: truncated", where));
        const std::string_view data = std::string_view(s).substr(body, size);
        if (crc32(data) != crc) throw Error(fmt::format("{}: CRC mismatch", where));
        const std::string stem = name.size() > 4 ? name.substr(0, name.size() - 4) : name;
        out.push_back(parse_npy(data, stem, where));
        at += 46 + name.size() + get(s, at + 30, 2, path) + get(s, at + 32, 2, path);
    }
    return out;
}

}  // namespace vmap::detail
