#pragma once
// The folder of brick tiles of one job. A brick's tile is named by its coordinates and a
// generation number that only grows, so a tile a checkpoint refers to is never overwritten by a
// later spill of the same brick: `b_X_Y_Z.G.tile`.
#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <set>
#include <utility>

#include "engine/error.h"
#include "storage/brick_map.h"
#include "storage/tile_file.h"

namespace sf {

// A tile a checkpoint refers to is missing or fails its checks (storage/tile_file.h). Bad input
// like any damaged file, but it names the brick, so that a job can rebuild the tile from the
// depth maps it integrated (cli: run_fuse).
class DamagedTile : public InputError {
 public:
  DamagedTile(const std::string& message, BrickCoord coord, std::uint64_t generation)
      : InputError(message), coord(coord), generation(generation) {}
  BrickCoord coord;
  std::uint64_t generation;
};

class TileStore {
 public:
  // Creates the folder. The store keeps up to `buffer_bytes` of tile buffers for reuse
  // (tile_buffer_budget()); they count against the job's memory limit (BrickMap::attach_store).
  explicit TileStore(std::filesystem::path dir, std::size_t buffer_bytes = 0);

  std::size_t buffer_bytes() const { return buffers_->max_retained(); }
  const std::filesystem::path& dir() const { return dir_; }
  std::filesystem::path path(BrickCoord c, std::uint64_t generation) const;
  // Writes a tile (not yet durable); returns its bytes.
  std::uint64_t write(BrickCoord c, std::uint64_t generation, const VoxelTable& voxels) const;
  // Makes every tile written so far durable (one syncfs of the folder's file system), before a
  // checkpoint that refers to them is committed.
  void sync() const;
  // Throws DamagedTile if the tile is missing or damaged.
  void read(BrickCoord c, std::uint64_t generation, VoxelTable& voxels) const;
  void remove(BrickCoord c, std::uint64_t generation) const;
  // Deletes every tile (and leftover temporary file) not in `keep` = {(packed coord, generation)}:
  // after a crash, what was written after the last checkpoint.
  std::size_t remove_all_except(const std::set<std::pair<std::uint64_t, std::uint64_t>>& keep) const;

 private:
  std::filesystem::path dir_;
  std::unique_ptr<TileBuffers> buffers_;  // a pointer: the store stays movable
};

// The tile buffers a store keeps for a job with this memory limit: 1/16 of it, 64 MiB at most
// (a thread writing a tile takes 3 MiB of chunk buffers, one reading takes 4 MiB; whole images
// of older tiles' formats that do not fit are unmapped after use).
inline std::size_t tile_buffer_budget(std::size_t memory_limit) {
  return std::min(memory_limit / 16, std::size_t{64} << 20);
}

}  // namespace sf
