// The LINK section's codec (link_codec.h).
#include "io/link_codec.h"

#include <fmt/format.h>
#include <streamvbytedelta.h>
#include <streamvbyte.h>

#include <tbb/enumerable_thread_specific.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cstring>
#include <mutex>

#include "vmap/parallel.h"

namespace vmap::detail {
namespace {

// About this many link ends a chunk: a few MiB of stream, many chunks for the threads.
constexpr uint64_t kChunkEnds = uint64_t(1) << 22;

std::vector<uint32_t> chunk_bounds(std::span<const uint64_t> offsets) {
    const uint32_t nn = uint32_t(offsets.size() - 1);
    std::vector<uint32_t> b{0};
    uint64_t since = 0;
    for (uint32_t n = 0; n < nn; ++n) {
        since += offsets[n + 1] - offsets[n];
        if (since >= kChunkEnds && n + 1 < nn) {
            b.push_back(n + 1);
            since = 0;
        }
    }
    b.push_back(nn);
    return b;
}

}  // namespace

namespace {

// A gap's code: its length in bytes, less one.
uint32_t gap_code(uint32_t gap) {
    return uint32_t(gap >= (1u << 8)) + uint32_t(gap >= (1u << 16)) + uint32_t(gap >= (1u << 24));
}

}  // namespace

size_t delta_stream_bytes(const uint32_t* values, uint32_t count) {
    size_t data = 0;
    uint32_t prev = 0;
    for (uint32_t i = 0; i < count; ++i) {
        data += 1 + gap_code(values[i] - prev);
        prev = values[i];
    }
    return (size_t(count) + 3) / 4 + data;
}

size_t encode_delta_stream(const uint32_t* values, uint32_t count, uint8_t* out) {
    static_assert(std::endian::native == std::endian::little, "the gaps' low bytes come first");
    uint8_t* key = out;
    uint8_t* data = out + (size_t(count) + 3) / 4;
    uint32_t prev = 0;
    for (uint32_t i = 0; i < count; i += 4) {
        const uint32_t in_key = std::min(4u, count - i);
        uint8_t k = 0;
        for (uint32_t j = 0; j < in_key; ++j) {
            const uint32_t gap = values[i + j] - prev;
            prev = values[i + j];
            const uint32_t code = gap_code(gap);
            std::memcpy(data, &gap, 4);  // all four bytes; the next gap writes over the spare ones
            data += code + 1;
            k = uint8_t(k | (code << (2 * j)));
        }
        *key++ = k;
    }
    return size_t(data - out);
}

void decode_delta_stream(const uint8_t* in, const uint8_t* end, uint32_t count, uint32_t* out) {
    static constexpr uint32_t kMask[4] = {0xffu, 0xffffu, 0xffffffu, 0xffffffffu};
    const uint8_t* key = in;
    const uint8_t* data = in + (size_t(count) + 3) / 4;
    uint32_t prev = 0;
    for (uint32_t i = 0; i < count; i += 4) {
        const uint32_t k = *key++, in_key = std::min(4u, count - i);
        for (uint32_t j = 0; j < in_key; ++j) {
            const uint32_t code = (k >> (2 * j)) & 3;
            uint32_t gap = 0;
            if (end - data >= 4) {
                std::memcpy(&gap, data, 4);  // all four bytes, then only the gap's kept
                gap &= kMask[code];
            } else {  // the last bytes of the buffer: only what is there
                std::memcpy(&gap, data, code + 1);
            }
            data += code + 1;
            prev += gap;
            out[i + j] = prev;
        }
    }
}

// The chunks' sizes are counted first; then each chunk is coded into a buffer of its thread's
// (reused: a fresh buffer a chunk, zeroed and returned, cost more than the coding on 16 threads,
// in page faults and unmapping) and copied to its place (the coder writes up to 3 bytes past
// its stream, which must not reach the next chunk's while another thread codes it). The count
// and the coder share gap_code, so a chunk's buffer of its count and 4 bytes always holds it.
LinkCoder::LinkCoder(std::span<const uint64_t> offsets, std::span<const int32_t> targets)
    : offsets_(offsets), targets_(reinterpret_cast<const uint32_t*>(targets.data())) {
    e_.chunk_node = chunk_bounds(offsets);
    const size_t n = chunks();
    e_.chunk_byte.assign(n + 1, 0);
    parallel_for(n, [&](size_t k) {
        size_t bytes = 0;
        for (uint32_t v = e_.chunk_node[k]; v < e_.chunk_node[k + 1]; ++v)
            bytes += delta_stream_bytes(targets_ + offsets[v], uint32_t(offsets[v + 1] - offsets[v]));
        e_.chunk_byte[k + 1] = bytes;
    });
    for (size_t k = 0; k < n; ++k) e_.chunk_byte[k + 1] += e_.chunk_byte[k];
    e_.stream.resize(e_.chunk_byte[n]);  // (not zeroed: every byte is coded)
}

void LinkCoder::code(size_t k, std::vector<uint8_t>& buf) {
    const uint32_t n0 = e_.chunk_node[k], n1 = e_.chunk_node[k + 1];
    const size_t room = e_.chunk_byte[k + 1] - e_.chunk_byte[k] + 4;
    if (buf.size() < room) buf.resize(room);
    size_t at = 0;
    for (uint32_t n = n0; n < n1; ++n) {
        const uint32_t len = uint32_t(offsets_[n + 1] - offsets_[n]);
        if (len) at += encode_delta_stream(targets_ + offsets_[n], len, buf.data() + at);
    }
    if (at) std::memcpy(e_.stream.data() + e_.chunk_byte[k], buf.data(), at);  // none: no array
}

EncodedLinks encode_links(std::span<const uint64_t> offsets, std::span<const int32_t> targets) {
    LinkCoder c(offsets, targets);
    tbb::enumerable_thread_specific<std::vector<uint8_t>> scratch;
    parallel_for(c.chunks(), [&](size_t k) { c.code(k, scratch.local()); });
    return std::move(c.links());
}

// StreamVByte: (count + 3) / 4 control bytes, two bits a value (value i in bits 2 (i % 4) of
// byte i / 4), code c meaning c + 1 data bytes; then the data bytes.
size_t stream_bytes(const uint8_t* p, size_t avail, uint32_t count) {
    const size_t keys = (size_t(count) + 3) / 4;
    if (keys > avail) return SIZE_MAX;
    size_t data = 0;
    for (size_t i = 0; i < keys; ++i) {
        const uint8_t k = p[i];
        const uint32_t in_byte = (i + 1 < keys || count % 4 == 0) ? 4 : count % 4;
        for (uint32_t j = 0; j < in_byte; ++j) data += ((k >> (2 * j)) & 3) + 1;
    }
    return keys + data > avail ? SIZE_MAX : keys + data;
}

std::string decode_links(std::span<const uint64_t> offsets, std::span<const uint32_t> chunk_node,
                         std::span<const uint64_t> chunk_byte, const uint8_t* stream,
                         int32_t* targets) {
    const int64_t nn = int64_t(offsets.size() - 1);
    std::mutex m;
    std::string first;
    size_t first_chunk = SIZE_MAX;
    auto fail = [&](size_t k, std::string what) {
        std::lock_guard lock(m);
        if (k < first_chunk) first_chunk = k, first = std::move(what);
    };
    parallel_for(chunk_node.size() - 1, [&](size_t k) {
        const uint8_t* p = stream + chunk_byte[k];
        const uint8_t* end = stream + chunk_byte[k + 1];
        for (uint32_t n = chunk_node[k]; n < chunk_node[k + 1]; ++n) {
            const uint64_t len = offsets[n + 1] - offsets[n];
            if (len == 0) continue;
            if (len > uint64_t(nn))
                return fail(k, fmt::format("node {} has {} links, more than there are nodes", n, len));
            const size_t bytes = stream_bytes(p, size_t(end - p), uint32_t(len));
            if (bytes == SIZE_MAX)
                return fail(k, fmt::format("node {}'s links run past their chunk", n));
            auto* out = reinterpret_cast<uint32_t*>(targets + offsets[n]);
            decode_delta_stream(p, end, uint32_t(len), out);
            p += bytes;
            for (uint64_t i = 0; i < len; ++i) {
                if (out[i] >= uint64_t(nn))
                    return fail(k, fmt::format("link target {} of node {} out of range", out[i], n));
                if (i > 0 && out[i] < out[i - 1])
                    return fail(k, fmt::format("node {}'s links are not sorted", n));
            }
        }
        if (p != end) fail(k, fmt::format("chunk {} has {} bytes left over", k, end - p));
    });
    return first;
}

}  // namespace vmap::detail
