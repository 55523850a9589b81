// The sharded V-map: for maps whose links do not fit one host, each process of an MPI build
// writes the links of one range of nodes to a file of its own, and rank 0 writes a small index.
//
//   out.vmap                 the index (JSON): {"format": "vmap-shards", "version": 1,
//                            "base": file, "nodes": N, "links": L, "shards": [{"file", "nodes":
//                            [n0, n1], "ends", "bytes", "checksum"}, ...]}
//   out.vmap.base            a .vmap with everything but the links (points, octree, parameters)
//   out.vmap.shard-K-of-S    "VMAPLINK" | u32 version | u32 K | i32 n0 | i32 n1 | u64 ends |
//                            u64 checksum | u64 offsets[n1 - n0 + 1] (from 0) | i32 targets[ends]
//
// The ranges are contiguous and cover every node, so the shards' arrays laid end to end are the
// link arrays of the one-file map: load_vmap reads an index as that map, equal to it.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "mpi/share.h"
#include "vmap/files.h"
#include "vmap/vmap.h"

namespace vmap::mpi {

struct ShardInfo {
    std::string file;  // name in the index's folder
    int32_t n0 = 0, n1 = 0;
    uint64_t ends = 0, bytes = 0, checksum = 0;
};

// The checksum of a shard's arrays, as its header and the index store it.
uint64_t shard_checksum(const std::vector<uint64_t>& offsets, const std::vector<int32_t>& targets);

std::string shard_name(const std::string& index, int k, int shards);
std::string base_name(const std::string& index);

// Writes shard k's range to the temporary of an AtomicFile, returned uncommitted (a build
// commits all shards only once every process has written its own).
std::unique_ptr<io::AtomicFile> write_shard(const std::string& path, int k, const LinkRange& r,
                                            ShardInfo& info);

// The index, atomically; `vm` holds the points and octree (its links are not read).
void write_index(const std::string& path, const std::vector<ShardInfo>& shards, uint64_t links,
                 int32_t nodes);

// The .vmap of everything but the links (the base of a sharded map).
void save_base(const std::string& path, const VisibilityMap& vm);

// True when `path` starts like a shard index (and not like a .vmap).
bool is_shard_index(const std::string& path);

// The map an index describes, as one VisibilityMap. Throws vmap::Error naming the index or the
// shard that is missing, truncated, corrupt or from another build.
VisibilityMap load_sharded(const std::string& path);

}  // namespace vmap::mpi
