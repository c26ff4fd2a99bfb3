#pragma once
// The hSDF's voxel map, grouped in spatial bricks: key -> brick -> voxel.
//
// A brick is a cube of the root at the "brick level" B (2^B bricks per axis). A voxel of any level
// belongs to the brick containing its position; positions on a brick's upper faces belong to the
// next brick, except at the root's upper faces. Bricks are the unit that later stages page to
// disk and process independently, so all access goes through a brick.
#include <cstdint>
#include <algorithm>
#include <array>
#include <atomic>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <unordered_map>
#include <utility>
#include <vector>

#include "storage/voxel_key.h"
#include "storage/voxel_table.h"

namespace sf {

struct BrickCoord {
  std::uint32_t x = 0, y = 0, z = 0;
  std::uint64_t packed() const { return (std::uint64_t(z) << 42) | (std::uint64_t(y) << 21) | x; }
  static BrickCoord unpack(std::uint64_t id) {
    return {std::uint32_t(id & 0x1fffff), std::uint32_t((id >> 21) & 0x1fffff), std::uint32_t(id >> 42)};
  }
};

// Brick of a voxel for brick level `brick_level`.
BrickCoord brick_of(VoxelKey key, int brick_level);

// A box of bricks, lo <= coord < hi per axis: a tile of the integration plan (scheduler/tile_plan.h).
struct BrickBox {
  BrickCoord lo, hi;
  static BrickBox whole(int brick_level) {
    const std::uint32_t n = 1u << brick_level;
    return {{0, 0, 0}, {n, n, n}};
  }
  bool contains(BrickCoord c) const {
    return c.x >= lo.x && c.x < hi.x && c.y >= lo.y && c.y < hi.y && c.z >= lo.z && c.z < hi.z;
  }
  bool empty() const { return lo.x >= hi.x || lo.y >= hi.y || lo.z >= hi.z; }
  // Grows the box to hold brick c (an empty box becomes c alone).
  void extend(BrickCoord c) {
    const BrickCoord c1{c.x + 1, c.y + 1, c.z + 1};
    if (empty()) {
      lo = c, hi = c1;
      return;
    }
    lo = {std::min(lo.x, c.x), std::min(lo.y, c.y), std::min(lo.z, c.z)};
    hi = {std::max(hi.x, c1.x), std::max(hi.y, c1.y), std::max(hi.z, c1.z)};
  }
  // Whether the boxes share a brick (boxes that only touch do not).
  bool meets(const BrickBox& o) const {
    return lo.x < o.hi.x && o.lo.x < hi.x && lo.y < o.hi.y && o.lo.y < hi.y && lo.z < o.hi.z && o.lo.z < hi.z;
  }
  // The voxel indices [first, last] of level `level` along `axis` (0..2) whose voxels belong
  // (brick_of) to the box's bricks; first > last if none.
  void voxel_range(int level, int brick_level, int axis, std::int64_t* first, std::int64_t* last) const;
};

struct Brick {
  explicit Brick(BrickCoord c, int brick_level) : coord(c), voxels(brick_level) {}
  BrickCoord coord;
  std::mutex mutex;  // held while loading, creating blocks or applying contributions
  VoxelTable voxels;
  // Out-of-core state (see BrickMap::attach_store). A brick not resident has its voxels only in
  // tile `generation`.
  bool resident = true;
  bool dirty = false;                    // changed since tile `generation` was written
  std::uint64_t generation = 0;          // newest tile, 0 = none
  std::uint64_t checkpoint_generation = 0;  // the tile the last committed checkpoint refers to
  std::uint64_t tile_bytes = 0;          // size of tile `generation`
  std::uint64_t field_bytes = 0;         // memory it held when last resident (0: unknown)
  std::uint64_t last_use = 0;            // epoch of the last access (least recently used spills first)

  // Its voxels differ from its newest tile, or it has none: spilling or a checkpoint writes it.
  bool needs_tile() const { return dirty || generation == 0; }
};

class TileStore;

// One brick of a checkpoint: which tile holds it.
struct ManifestEntry {
  BrickCoord coord;
  std::uint64_t generation = 0, bytes = 0;
};

struct SpillStats {
  std::size_t spilled = 0, reloaded = 0;  // cumulative brick counts
  std::uint64_t bytes_written = 0, bytes_read = 0;
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

  // For integration's threads, which keep a brick and a group at hand and read and make the
  // group's blocks without the brick's lock (BlockGroup): the brick at `c`, made (empty) if absent
  // (it lives until clear() or compact()); the group of blocks holding `key`, a voxel of `brick`,
  // created if absent (VoxelTable::group); and block `part` (edge 2^log) of a group of `brick`,
  // created if absent, by the thread of index `thread` in its task arena (it picks the chunk the
  // block is carved from). Safe to call from several threads at once; pointers stay valid until
  // compact() or clear(). Writers must never touch the same voxel concurrently (integration
  // guarantees it: one contribution per voxel per depth map).
  Brick& brick(BrickCoord c);
  BlockGroup* group(Brick& brick, VoxelKey key);
  VoxelData* part(Brick& brick, BlockGroup& group, int part, int log, unsigned thread);

  const VoxelData* find(VoxelKey key) const;  // not safe concurrently with apply()
  VoxelData* find(VoxelKey key);

  // All bricks, in ascending packed-coordinate order (deterministic). Their voxels are only in
  // memory if resident (after load_all(), all are).
  std::vector<Brick*> bricks() const;
  // Drops erased voxels and empty bricks (all bricks must be resident).
  void compact();
  // Drops everything.
  void clear();

  // --- Out of core ---------------------------------------------------------------------------
  // Lets bricks spill to `store` when their memory passes `memory_limit` bytes. Spilling happens
  // only in enforce_limit(), which callers run at safe points (between depth maps), so block
  // pointers handed out during a depth map stay valid: a depth map's bricks are pinned for its
  // duration. A brick touched again is reloaded from its tile under its own lock.
  void attach_store(const TileStore* store, std::size_t memory_limit);
  bool spills() const { return store_ != nullptr; }
  // Memory the caller holds outside the bricks (depth maps in flight and their working sets): the
  // bricks get the limit minus this, but at least a quarter of the limit.
  void set_reserve(std::size_t bytes) { reserve_ = bytes; }
  std::size_t memory_limit() const { return memory_limit_; }
  // The store's reusable tile buffers are held outside the bricks too.
  std::size_t brick_budget() const {
    const std::size_t outside = reserve_ + store_buffers_;
    return std::max(memory_limit_ / 4, memory_limit_ > outside ? memory_limit_ - outside : std::size_t{0});
  }
  // Starts a new access epoch (one per depth map, or per chunk of one).
  void next_epoch() { ++epoch_; }
  // Spills least recently used bricks (ties by coordinate) until resident memory fits the limit.
  // Not safe concurrently with any other access.
  void enforce_limit();
  // Spills every resident brick (a plan tile is finished: its bricks are not touched again).
  void spill_all();
  // The memory each brick's field takes when resident (for planning): measured for bricks that
  // were resident in this process, estimated from the tile size for restored ones.
  std::vector<std::pair<BrickCoord, std::size_t>> field_bytes() const;
  // Writes every changed resident brick to a new tile and returns the manifest of all bricks.
  std::vector<ManifestEntry> write_checkpoint();
  // After the manifest is committed: tiles the previous checkpoint referred to are deleted.
  void checkpoint_committed();
  // Recreates the bricks of a committed checkpoint, none resident; generations continue after
  // `max_generation`. Deletes tiles written after that checkpoint.
  void restore(const std::vector<ManifestEntry>& manifest, std::uint64_t max_generation);
  // Makes every brick resident (for stages that do not page yet: regularization, extraction).
  void load_all();
  // A brick's voxels to read: its table if resident, else its tile read into `scratch`. Not safe
  // concurrently with spilling or loading that brick.
  const VoxelTable& field_of(const Brick& b, VoxelTable& scratch) const;
  // A brick's voxels, taken out of memory (a resident brick is left empty) or read from its tile
  // (which stays): for a stage that consumes the field brick by brick.
  VoxelTable take_field(Brick& b);
  std::size_t resident_bytes() const;
  // Live voxels per octree level over every brick, reading spilled bricks' tiles one at a time
  // into a scratch table (memory: one brick). Not safe concurrently with any other access.
  std::array<std::size_t, kMaxLevel + 1> live_voxels_per_level() const;
  std::uint64_t max_generation() const { return next_generation_ - 1; }
  SpillStats spill_stats() const {
    return {spilled_.load(), reloaded_.load(), bytes_written_.load(), bytes_read_.load()};
  }

 private:
  const Brick* find_brick(BrickCoord c) const;
  void make_resident(Brick& b);   // caller holds b.mutex
  void write_tile_of(Brick& b);   // caller holds b.mutex (or has exclusive access)
  // Writes b's tile as generation g and drops the tile it replaces (no counters: thread-safe
  // for distinct bricks).
  void write_tile_as(Brick& b, std::uint64_t g);
  // Writes the resident bricks of `bricks` that changed since their tile (or never had one):
  // generations numbered in the given order, as one write after the other would number them, the
  // tiles (each its own LZ4 block and file) written in parallel. then(i) runs for every resident
  // brick i, after its write. Exclusive access.
  template <class Then>
  void write_changed_tiles(const std::vector<Brick*>& bricks, Then&& then);
  // Drops b's field from memory (no spill counter).
  void release(Brick& b);
  void spill(Brick& b);           // exclusive access

  int brick_level_;
  const TileStore* store_ = nullptr;
  std::size_t store_buffers_ = 0;  // the store's TileStore::buffer_bytes()
  std::size_t memory_limit_ = 0, reserve_ = 0;
  std::uint64_t epoch_ = 1, next_generation_ = 1;
  // Atomic: bricks are reloaded by integration workers, each holding only its brick's mutex.
  std::atomic<std::size_t> spilled_{0}, reloaded_{0};
  std::atomic<std::uint64_t> bytes_written_{0}, bytes_read_{0};
  // Σ over resident bricks of their arena chunks, group index and Brick, kept up to date as groups
  // and chunks are made, bricks load and spill, so that enforce_limit() costs nothing while under
  // the limit.
  std::atomic<std::int64_t> resident_bytes_{0};
  mutable std::shared_mutex bricks_mutex_;
  std::unordered_map<std::uint64_t, std::unique_ptr<Brick>> bricks_;
};

}  // namespace sf
