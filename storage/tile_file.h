#pragma once
// A brick on disk: one LZ4-compressed tile file per brick, the unit the out-of-core store spills
// and reloads.
//
// Layout (little-endian; docs/formats.md has the table):
//   magic "SFTILE1\n" | u32 version | u32 brick_level | u32 brick x, y, z | u32 block count
//   | u64 raw payload bytes | u64 stored payload bytes | u64 XXH3-64 of the stored payload
//   | u64 XXH3-64 of the 56 header bytes before it | stored payload
// The stored payload is the raw payload in chunks of whole blocks, each its u32 raw bytes (at
// most 1 MiB; written at most 256 KiB; whole 16-byte units), u32 stored bytes, u64 XXH3-64 of the
// stored bytes and the chunk's byte planes (storage/byte_planes.h) as two LZ4 blocks, planes 0-7
// (distance and weight) then 8-15 (colour), behind the u32 stored bytes of the first, so that
// tiles are written and read through buffers of one chunk; the header's payload checksum is then
// that of the chunk headers. The raw payload is the brick's blocks in
// ascending origin-key order, each as its u64 origin key, a u64 mask of its present voxels
// (weight != 0; bit i for voxel i of its 2^(3k), x fastest) and the present voxels' records of 16
// bytes (distance, weight as float32; colour[3] in 1/256 steps and the colour share in 1/65535 of
// the weight as u16; see VoxelData). Blocks are sorted, so a brick's tile is byte-identical
// however its voxels were inserted.
// Older formats are still read: version 6 compressed a chunk's planes as one LZ4 block; version 5
// compressed each chunk's raw bytes rather than their byte planes; version 4 stored the raw payload as one LZ4 block; version 3
// stored every voxel of a block, absent ones as zeros; version 2 stored 24-byte voxels (distance,
// weight, colour[3], colour weight as float32), version 1 also checksummed with FNV-1a, which
// hashes under 1 GB/s, about a twentieth of XXH3's speed (every tile is hashed when written and
// again when read).
//
// Writes go to a temporary name in the same directory, are fsynced and renamed over the target
// (and the directory is fsynced), so a tile is either the old one or the new one after a crash;
// a job's store skips the per-file syncs and syncs once per checkpoint instead.
// Reads check everything a damaged or foreign file could get wrong and throw InputError naming
// the tile; they never allocate more than one chunk's bound (formats 5 to 7) or the header's sizes allow
// for a file of that length (formats 1 to 4).
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <mutex>
#include <vector>

#include "engine/hash.h"
#include "storage/brick_map.h"

namespace sf {

inline constexpr std::uint32_t kTileVersion = 7;

// The checksum of a tile of format `version` (1 to 4) over `size` bytes.
std::uint64_t tile_checksum(std::uint32_t version, const void* data, std::size_t size);

// Page-mapped buffers for tiles' chunks (and the whole raw and compressed images of tiles of
// formats 1 to 4), kept for reuse up to a byte budget. Mapped afresh for each tile, every 4 KiB
// page costs a fault and the kernel's zeroing, about a quarter of a spilling integration's time
// when buffers were whole images (bench/README.md, session 18). Reused, they cost nothing; kept
// out of malloc, they never raise its thresholds or hide in its heap. Safe to use from several
// threads at once.
class TileBuffers {
 public:
  struct Mapping {
    unsigned char* data = nullptr;
    std::size_t capacity = 0;
  };
  // Keeps at most `max_retained` bytes of unused mappings (0: none, every buffer is unmapped).
  explicit TileBuffers(std::size_t max_retained) : max_retained_(max_retained) {}
  ~TileBuffers();
  TileBuffers(const TileBuffers&) = delete;
  TileBuffers& operator=(const TileBuffers&) = delete;

  // A mapping of at least `size` bytes (> 0): a kept one if one is large enough, else a new one.
  // Its contents are whatever its last user left.
  Mapping take(std::size_t size);
  // Hands a mapping back; the smallest kept mappings are unmapped while over the budget.
  void give_back(Mapping m);
  std::size_t max_retained() const { return max_retained_; }
  std::size_t retained_bytes() const;

 private:
  const std::size_t max_retained_;
  mutable std::mutex mutex_;
  std::vector<Mapping> free_;  // ascending capacity
  std::size_t retained_ = 0;
};

// Writes `voxels` (the voxels of brick `coord` at brick level `voxels.brick_level()`) to `path`.
// Returns the file's size in bytes. With durable = false the file and directory are not fsynced
// (the caller syncs many tiles at once, see TileStore::sync); the rename is still atomic.
// `buffers`, if given, lends the images' memory.
std::uint64_t write_tile(const std::filesystem::path& path, BrickCoord coord, const VoxelTable& voxels,
                         bool durable = true, TileBuffers* buffers = nullptr);

// Reads a tile into `out` (which must be empty and have the tile's brick level); returns the
// brick's coordinates. Throws InputError "path: problem" on any damage, leaving `out` empty.
BrickCoord read_tile(const std::filesystem::path& path, VoxelTable& out, TileBuffers* buffers = nullptr);


}  // namespace sf
