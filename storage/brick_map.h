#pragma once
// The hSDF's voxel map, grouped in spatial bricks: key -> brick -> voxel.
//
// A brick is a cube of the root at the "brick level" B (2^B bricks per axis). A voxel of any level
// belongs to the brick containing its position; positions on a brick's upper faces belong to the
// next brick, except at the root's upper faces. Bricks are the unit that later stages page to
// disk and process independently, so all access goes through a brick.
#include <cstdint>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <unordered_map>
#include <vector>

#include "storage/voxel_key.h"
#include "storage/voxel_table.h"

namespace sf {

struct BrickCoord {
  std::uint32_t x = 0, y = 0, z = 0;
  std::uint64_t packed() const { return (std::uint64_t(z) << 42) | (std::uint64_t(y) << 21) | x; }
};

// Brick of a voxel for brick level `brick_level`.
BrickCoord brick_of(VoxelKey key, int brick_level);

struct Brick {
  explicit Brick(BrickCoord c, int brick_level) : coord(c), voxels(brick_level) {}
  BrickCoord coord;
  std::mutex mutex;  // held while creating blocks or applying contributions
  VoxelTable voxels;
};

// One contribution of one depth map to one voxel (d_i, w_i of equations 2-3, plus colour).
struct Contribution {
  VoxelKey key;
  float distance;
  float weight;
  std::uint8_t colour[3];
  bool has_colour;
};

class BrickMap {
 public:
  explicit BrickMap(int brick_level);

  int brick_level() const { return brick_level_; }
  std::size_t brick_count() const;
  std::size_t voxel_count() const;

  // Applies equations 2-3 for every contribution. Safe to call from several threads at once.
  // Each voxel must receive at most one contribution per depth map, and depth maps must be applied
  // in a fixed order: then the result does not depend on thread timing.
  void apply(std::vector<Contribution>& batch);

  // The block holding `key`, created if absent. Safe to call from several threads at once; the
  // returned pointer stays valid until compact() or clear(). Writers must never touch the same
  // voxel concurrently (integration guarantees it: one contribution per voxel per depth map).
  BlockRef block(VoxelKey key);

  const VoxelData* find(VoxelKey key) const;  // not safe concurrently with apply()
  VoxelData* find(VoxelKey key);

  // All bricks, in ascending packed-coordinate order (deterministic).
  std::vector<Brick*> bricks() const;
  // Drops erased voxels and empty bricks.
  void compact();
  // Drops everything.
  void clear();

 private:
  Brick& brick(BrickCoord c);
  const Brick* find_brick(BrickCoord c) const;

  int brick_level_;
  mutable std::shared_mutex bricks_mutex_;
  std::unordered_map<std::uint64_t, std::unique_ptr<Brick>> bricks_;
};

}  // namespace sf
