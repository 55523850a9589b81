// The .vmap file's LINK section from version 5 on: each node's sorted link targets as a
// delta-coded StreamVByte stream (libstreamvbyte), nodes grouped into chunks that encode and
// decode in parallel. The targets of a node are increasing node ids, so their gaps are small:
// 1.3 bytes a link end on the default scene's map against 4 raw (docs/formats.md).
//
// Layout: u64 chunks | u32 chunk_node[chunks + 1] | u64 chunk_byte[chunks + 1] | u8 stream[]
// (after the u64 offsets[nodes + 1] of every version). Chunk k holds the nodes
// [chunk_node[k], chunk_node[k + 1]) and the stream bytes [chunk_byte[k], chunk_byte[k + 1]);
// in it each node with links has its own stream of offsets[n + 1] - offsets[n] values,
// streamvbyte_delta_encode'd from 0, one after the other.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "util/huge_array.h"

namespace vmap::detail {

struct EncodedLinks {
    std::vector<uint32_t> chunk_node;  // chunks + 1 node boundaries, 0 .. nodes
    std::vector<uint64_t> chunk_byte;  // chunks + 1 byte boundaries, 0 .. stream size
    HugeVector<uint8_t> stream;        // every chunk's bytes, chunk k at chunk_byte[k]
};

// The links coded in two steps, so that a writer can code each chunk just before it writes it:
// the constructor counts every chunk's bytes (delta_stream_bytes, in parallel), which fixes
// every chunk's place in the stream (allocated, not yet written); code(k) then codes chunk k
// into its place, from any thread, in any order (each chunk once).
class LinkCoder {
  public:
    LinkCoder(std::span<const uint64_t> offsets, std::span<const int32_t> targets);
    size_t chunks() const { return e_.chunk_node.size() - 1; }
    const EncodedLinks& links() const { return e_; }
    EncodedLinks& links() { return e_; }
    // Codes chunk k; `scratch` is the calling thread's buffer (reused across calls).
    void code(size_t k, std::vector<uint8_t>& scratch);

  private:
    std::span<const uint64_t> offsets_;
    const uint32_t* targets_;
    EncodedLinks e_;
};

// Encodes the per-node link lists (offsets: nodes + 1 entries; targets sorted per node): a
// LinkCoder's chunks, all coded in parallel.
EncodedLinks encode_links(std::span<const uint64_t> offsets, std::span<const int32_t> targets);

// streamvbyte_delta_encode(values, count, out, 0), byte for byte, without its branches: each gap
// is stored as four bytes and the stream moves on by its length, so `out` needs 3 bytes of room
// past the stream (delta_stream_bytes + 3). Debian's libstreamvbyte is built without its SIMD
// coders; its scalar one branches on every gap's length and coded the links at about 13 ns a
// link end. The library stays the reference in the tests.
size_t encode_delta_stream(const uint32_t* values, uint32_t count, uint8_t* out);

// streamvbyte_delta_decode(in, out, count, 0) without its branches: each gap read as four bytes
// and masked to its length, where at least four bytes are left before `end` (byte by byte in
// the last three). The caller has checked that the stream's bytes (stream_bytes) lie before
// `end`.
void decode_delta_stream(const uint8_t* in, const uint8_t* end, uint32_t count, uint32_t* out);

// The bytes streamvbyte_delta_encode makes of `count` values coded from 0: a control byte for
// every four values, then each gap from the value before in 1 to 4 bytes (its bytes up to the
// highest that is not zero; one at least).
size_t delta_stream_bytes(const uint32_t* values, uint32_t count);

// The length in bytes of a StreamVByte stream of `count` values that starts at p, read off its
// control bytes; SIZE_MAX when it would run past `avail` bytes.
size_t stream_bytes(const uint8_t* p, size_t avail, uint32_t count);

// Decodes `stream` (chunk boundaries as above, already checked to be increasing and within the
// stream) into targets (offsets[nodes] entries). Returns "" or what is wrong (the first chunk's
// problem found): a node's stream running out of its chunk, a chunk with bytes left over, a
// target out of [0, nodes), targets of a node not in increasing order.
std::string decode_links(std::span<const uint64_t> offsets, std::span<const uint32_t> chunk_node,
                         std::span<const uint64_t> chunk_byte, const uint8_t* stream,
                         int32_t* targets);

}  // namespace vmap::detail
