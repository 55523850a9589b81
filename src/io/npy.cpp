// The .npy format: magic "\x93NUMPY", major/minor version, header length (u16 for 1.0, u32
// for 2.0/3.0), then a Python dict literal {'descr': '<i8', 'fortran_order': False,
// 'shape': (M, 2), } padded to a multiple of 64 bytes, then the raw array.
#include "vmap/npy.h"

#include <fmt/format.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>

#include "vmap/error.h"
#include "vmap/files.h"

namespace vmap {
namespace {

struct Header {
    char order = '<';  // '<' little, '>' big, '|' not applicable
    char kind = 'i';   // 'i' signed, 'u' unsigned, 'b' bool
    int bytes = 8;
    bool fortran = false;
    std::vector<uint64_t> shape;
};

// The value text after 'key': in the header dict, up to the next top-level comma or brace.
std::string dict_value(const std::string& h, const std::string& key, const std::string& path) {
    const size_t k = h.find("'" + key + "'");
    if (k == std::string::npos) throw Error(fmt::format("{}: npy header: no '{}'", path, key));
    size_t at = h.find(':', k);
    if (at == std::string::npos)
        throw Error(fmt::format("{}: npy header: {}: no value", path, key));
    ++at;
    while (at < h.size() && h[at] == ' ') ++at;
    size_t end = at;
    if (at < h.size() && h[at] == '(') {
        end = h.find(')', at);
        if (end == std::string::npos)
            throw Error(fmt::format("{}: npy header: {}: unterminated tuple", path, key));
        return h.substr(at + 1, end - at - 1);
    }
    while (end < h.size() && h[end] != ',' && h[end] != '}') ++end;
    return h.substr(at, end - at);
}

Header parse_header(const std::string& h, const std::string& path) {
    Header r;
    std::string d = dict_value(h, "descr", path);
    if (d.size() < 4 || (d.front() != '\'' && d.front() != '"'))
        throw Error(fmt::format("{}: npy header: descr {} is not a simple dtype", path, d));
    d = d.substr(1, d.size() - 2);
    r.order = d[0];
    r.kind = d[1];
    r.bytes = std::atoi(d.c_str() + 2);
    if ((r.order != '<' && r.order != '>' && r.order != '|' && r.order != '=') ||
        (r.kind != 'i' && r.kind != 'u') ||
        (r.bytes != 1 && r.bytes != 2 && r.bytes != 4 && r.bytes != 8))
        throw Error(fmt::format("{}: npy header: descr '{}': expected an integer dtype (e.g. <i8)",
                                path, d));
    const std::string f = dict_value(h, "fortran_order", path);
    if (f != "False" && f != "True")
        throw Error(
            fmt::format("{}: npy header: fortran_order {}: expected True or False", path, f));
    r.fortran = f == "True";
    const std::string s = dict_value(h, "shape", path);
    for (size_t at = 0; at < s.size();) {
        while (at < s.size() && (s[at] == ' ' || s[at] == ',')) ++at;
        if (at >= s.size()) break;
        char* end = nullptr;
        const unsigned long long v = std::strtoull(s.c_str() + at, &end, 10);
        if (end == s.c_str() + at)
            throw Error(fmt::format("{}: npy header: shape ({}) is not a tuple of sizes", path, s));
        r.shape.push_back(v);
        at = size_t(end - s.c_str());
    }
    if (r.shape.size() != 2 || r.shape[1] != 2)
        throw Error(
            fmt::format("{}: npy header: shape ({}): expected (M, 2) point-id pairs", path, s));
    return r;
}

uint64_t read_uint(const unsigned char* p, int bytes, bool big) {
    uint64_t v = 0;
    for (int k = 0; k < bytes; ++k) v |= uint64_t(p[big ? bytes - 1 - k : k]) << (8 * k);
    return v;
}

}  // namespace

std::vector<uint32_t> read_npy_pairs(std::string_view data, const std::string& path) {
    const auto* b = reinterpret_cast<const unsigned char*>(data.data());
    if (data.size() < 10 || std::memcmp(b, "\x93NUMPY", 6) != 0)
        throw Error(fmt::format("{}: not a .npy file (magic)", path));
    const int major = b[6];
    if (major < 1 || major > 3)
        throw Error(fmt::format("{}: npy version {} not supported (1, 2 or 3)", path, major));
    const size_t lenbytes = major == 1 ? 2 : 4;
    if (data.size() < 8 + lenbytes) throw Error(fmt::format("{}: truncated header", path));
    const uint64_t hlen = read_uint(b + 8, int(lenbytes), false);
    const uint64_t here = 8 + lenbytes + hlen;
    if (here > data.size()) throw Error(fmt::format("{}: truncated header", path));
    const Header hd = parse_header(std::string(data.substr(8 + lenbytes, hlen)), path);
    const uint64_t m = hd.shape[0];
    const uint64_t body = m * 2 * uint64_t(hd.bytes);
    if (m > (uint64_t(1) << 40) || data.size() < here + body)
        throw Error(
            fmt::format("{}: truncated: the header promises {} pairs ({} bytes), the file "
                        "holds {}",
                        path, m, body, data.size() - here));
    std::vector<uint32_t> out(m * 2);
    const bool big = hd.order == '>';
    const uint64_t sign = uint64_t(1) << (8 * hd.bytes - 1);
    for (uint64_t e = 0; e < m * 2; ++e) {
        const uint64_t v = read_uint(b + here + e * hd.bytes, hd.bytes, big);
        if ((hd.kind == 'i' && (v & sign)) || v > 0xffffffffull)
            throw Error(fmt::format("{}: pair {}: id out of range (negative or above 2^32-1)", path,
                                    hd.fortran ? e % m : e / 2));
        // Fortran order stores column 0 (all i) then column 1 (all j).
        out[hd.fortran ? (e % m) * 2 + e / m : e] = static_cast<uint32_t>(v);
    }
    return out;
}

void write_npy_u8(const std::string& path, std::span<const uint8_t> values) {
    std::string h =
        fmt::format("{{'descr': '|u1', 'fortran_order': False, 'shape': ({},), }}", values.size());
    // Magic (6) + version (2) + length (2) + header + '\n' padded to a multiple of 64.
    const size_t total = (10 + h.size() + 1 + 63) / 64 * 64;
    h.append(total - 10 - h.size() - 1, ' ');
    h += '\n';
    const unsigned char pre[10] = {0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0,
                                   static_cast<unsigned char>(h.size() & 0xff),
                                   static_cast<unsigned char>(h.size() >> 8)};
    io::AtomicFile out(path);
    out.write(pre, sizeof pre);
    out.write(h);
    out.write(values.data(), values.size());
    out.commit();
}

}  // namespace vmap
