#pragma once
// The folder of brick tiles of one job. A brick's tile is named by its coordinates and a
// generation number that only grows, so a tile a checkpoint refers to is never overwritten by a
// later spill of the same brick: `b_X_Y_Z.G.tile`.
#include <cstdint>
#include <filesystem>
#include <set>
#include <utility>

#include "engine/error.h"
#include "storage/brick_map.h"

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
  explicit TileStore(std::filesystem::path dir);  // creates the folder

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
};

}  // namespace sf
