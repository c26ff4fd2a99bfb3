#pragma once
// A brick on disk: one LZ4-compressed tile file per brick, the unit the out-of-core store spills
// and reloads.
//
// Layout (little-endian; docs/formats.md has the table):
//   magic "SFTILE1\n" | u32 version | u32 brick_level | u32 brick x, y, z | u32 block count
//   | u64 raw payload bytes | u64 stored payload bytes | u64 FNV-1a of the stored payload
//   | u64 FNV-1a of the 56 header bytes before it | stored payload (LZ4 block format)
// The raw payload is the brick's blocks in ascending origin-key order, each as its u64 origin key
// followed by its 2^(3k) voxels (distance, weight, colour[3], colour_weight as float32). Blocks are
// sorted, so a brick's tile is byte-identical however its voxels were inserted.
//
// Writes go to a temporary name in the same directory, are fsynced and renamed over the target
// (and the directory is fsynced), so a tile is either the old one or the new one after a crash;
// a job's store skips the per-file syncs and syncs once per checkpoint instead.
// Reads check everything a damaged or foreign file could get wrong and throw InputError naming
// the tile; they never allocate more than the header's sizes allow for a file of that length.
#include <cstdint>
#include <filesystem>

#include "engine/hash.h"
#include "storage/brick_map.h"

namespace sf {

inline constexpr std::uint32_t kTileVersion = 1;

// Writes `voxels` (the voxels of brick `coord` at brick level `voxels.brick_level()`) to `path`.
// Returns the file's size in bytes. With durable = false the file and directory are not fsynced
// (the caller syncs many tiles at once, see TileStore::sync); the rename is still atomic.
std::uint64_t write_tile(const std::filesystem::path& path, BrickCoord coord, const VoxelTable& voxels,
                         bool durable = true);

// Reads a tile into `out` (which must be empty and have the tile's brick level); returns the
// brick's coordinates. Throws InputError "path: problem" on any damage.
BrickCoord read_tile(const std::filesystem::path& path, VoxelTable& out);


}  // namespace sf
