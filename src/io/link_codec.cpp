// The LINK section's codec (link_codec.h).
#include "io/link_codec.h"

#include <fmt/format.h>
#include <streamvbytedelta.h>
#include <streamvbyte.h>

#include <atomic>
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

EncodedLinks encode_links(std::span<const uint64_t> offsets, std::span<const int32_t> targets) {
    EncodedLinks e;
    e.chunk_node = chunk_bounds(offsets);
    const size_t chunks = e.chunk_node.size() - 1;
    e.chunks.resize(chunks);
    const auto* t = reinterpret_cast<const uint32_t*>(targets.data());
    parallel_for(chunks, [&](size_t k) {
        const uint32_t n0 = e.chunk_node[k], n1 = e.chunk_node[k + 1];
        std::vector<uint8_t> buf(streamvbyte_max_compressedbytes(uint32_t(offsets[n1] - offsets[n0])) +
                                 (n1 - n0));
        size_t at = 0;
        for (uint32_t n = n0; n < n1; ++n) {
            const uint32_t len = uint32_t(offsets[n + 1] - offsets[n]);
            if (len) at += streamvbyte_delta_encode(t + offsets[n], len, buf.data() + at, 0);
        }
        e.chunks[k].assign(buf.begin(), buf.begin() + ptrdiff_t(at));  // exact size: buf goes
    });
    e.chunk_byte.assign(chunks + 1, 0);
    for (size_t k = 0; k < chunks; ++k) e.chunk_byte[k + 1] = e.chunk_byte[k] + e.chunks[k].size();
    return e;
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
            streamvbyte_delta_decode(p, out, uint32_t(len), 0);
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
