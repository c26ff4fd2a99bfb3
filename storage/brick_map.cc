#include "storage/brick_map.h"

#include <malloc.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <mutex>
#include <stdexcept>

#include "storage/tile_store.h"

namespace sf {

BrickCoord brick_of(VoxelKey key, int brick_level) {
  const int l = key.level();
  const std::uint32_t last = (1u << brick_level) - 1;
  auto axis = [&](std::uint32_t c) -> std::uint32_t {
    const std::uint64_t b = l >= brick_level ? (c >> (l - brick_level)) : (std::uint64_t(c) << (brick_level - l));
    return std::uint32_t(std::min<std::uint64_t>(b, last));
  };
  return BrickCoord{axis(key.x()), axis(key.y()), axis(key.z())};
}

void BrickBox::voxel_range(int level, int brick_level, int axis, std::int64_t* first, std::int64_t* last) const {
  const std::int64_t b0 = axis == 0 ? lo.x : axis == 1 ? lo.y : lo.z;
  const std::int64_t b1 = axis == 0 ? hi.x : axis == 1 ? hi.y : hi.z;
  // Voxel c of level l lies in brick floor(c 2^B / 2^l) (the last brick also takes c = 2^l), so
  // brick b starts at voxel ceil(b 2^l / 2^B).
  auto start = [&](std::int64_t b) {
    return level >= brick_level ? b << (level - brick_level)
                                : (b + (std::int64_t{1} << (brick_level - level)) - 1) >> (brick_level - level);
  };
  *first = start(b0);
  *last = b1 == (std::int64_t{1} << brick_level) ? (std::int64_t{1} << level) : start(b1) - 1;
}

// Memory a resident brick holds: its blocks and index, and the brick itself.
static std::size_t resident_size(const Brick& b) { return b.voxels.memory_bytes() + sizeof(Brick); }

BrickMap::BrickMap(int brick_level) : brick_level_(brick_level) {}

std::size_t BrickMap::brick_count() const {
  std::shared_lock lock(bricks_mutex_);
  return bricks_.size();
}

std::size_t BrickMap::voxel_count() const {
  std::size_t n = 0;
  for (Brick* b : bricks()) n += b->voxels.live_count();
  return n;
}

Brick& BrickMap::brick(BrickCoord c) {
  const std::uint64_t id = c.packed();
  {
    std::shared_lock lock(bricks_mutex_);
    auto it = bricks_.find(id);
    if (it != bricks_.end()) return *it->second;
  }
  std::unique_lock lock(bricks_mutex_);
  auto& slot = bricks_[id];
  if (!slot) {
    slot = std::make_unique<Brick>(c, brick_level_);
    resident_bytes_ += std::int64_t(sizeof(Brick) + slot->voxels.memory_bytes());
  }
  return *slot;
}

const Brick* BrickMap::find_brick(BrickCoord c) const {
  std::shared_lock lock(bricks_mutex_);
  auto it = bricks_.find(c.packed());
  return it == bricks_.end() ? nullptr : it->second.get();
}

void BrickMap::apply(std::vector<Contribution>& batch) {
  // Contributions of one batch come from neighbouring triangles and fall in runs of the same
  // brick: hold one brick's lock per run (never two locks at once).
  Brick* current = nullptr;
  std::uint64_t current_id = ~std::uint64_t{0};
  std::unique_lock<std::mutex> lock;
  std::int64_t before = 0;  // the current brick's bytes when its lock was taken
  for (const Contribution& c : batch) {
    const BrickCoord bc = brick_of(c.key, brick_level_);
    if (bc.packed() != current_id) {
      if (lock.owns_lock()) {
        resident_bytes_ += std::int64_t(current->voxels.memory_bytes()) - before;
        lock.unlock();
      }
      current = &brick(bc);
      current_id = bc.packed();
      lock = std::unique_lock<std::mutex>(current->mutex);
      make_resident(*current);
      current->dirty = true;
      current->last_use = epoch_;
      before = std::int64_t(current->voxels.memory_bytes());
    }
    accumulate(current->voxels.find_or_insert(c.key), c.distance, c.weight, c.has_colour ? c.colour : nullptr);
  }
  if (lock.owns_lock()) resident_bytes_ += std::int64_t(current->voxels.memory_bytes()) - before;
}

BlockGroup* BrickMap::group(Brick& b, VoxelKey key) {
  std::lock_guard lock(b.mutex);
  make_resident(b);
  b.dirty = true;
  b.last_use = epoch_;
  const std::int64_t before = std::int64_t(b.voxels.memory_bytes());
  BlockGroup* const g = b.voxels.group(key, true);
  resident_bytes_ += std::int64_t(b.voxels.memory_bytes()) - before;
  return g;
}

VoxelData* BrickMap::part(Brick& b, BlockGroup& group, int part, int log, unsigned thread) {
  // Without the brick's lock (VoxelTable::make_part_shared takes it only to add a chunk, one block
  // in ~250): under it, the lock's cache line went back and forth between the cores once per
  // block, and so did the shared count, which now changes only when a chunk is added.
  std::int64_t grown = 0;
  VoxelData* const v = b.voxels.make_part_shared(group, part, log, &b.mutex, thread, &grown);
  if (grown != 0) resident_bytes_ += grown;
  return v;
}

void BrickMap::make_resident(Brick& b) {
  if (b.resident) return;
  store_->read(b.coord, b.generation, b.voxels);
  resident_bytes_ += std::int64_t(resident_size(b));
  b.resident = true;
  b.dirty = false;
  ++reloaded_;
  bytes_read_ += b.tile_bytes;
}

void BrickMap::write_tile_as(Brick& b, std::uint64_t g) {
  b.tile_bytes = store_->write(b.coord, g, b.voxels);
  // The previous tile goes unless the committed checkpoint still needs it.
  if (b.generation != 0 && b.generation != b.checkpoint_generation) store_->remove(b.coord, b.generation);
  b.generation = g;
  b.dirty = false;
}

void BrickMap::write_tile_of(Brick& b) {
  write_tile_as(b, next_generation_++);
  bytes_written_ += b.tile_bytes;
}

void BrickMap::release(Brick& b) {
  b.field_bytes = resident_size(b);
  resident_bytes_ -= std::int64_t(b.field_bytes);
  b.voxels.clear();
  b.resident = false;
}


void BrickMap::attach_store(const TileStore* store, std::size_t memory_limit) {
  store_ = store;
  store_buffers_ = store ? store->buffer_bytes() : 0;
  memory_limit_ = memory_limit;
}

std::size_t BrickMap::resident_bytes() const { return std::size_t(std::max<std::int64_t>(0, resident_bytes_.load())); }

const VoxelTable& BrickMap::field_of(const Brick& b, VoxelTable& scratch) const {
  if (b.resident) return b.voxels;
  scratch.clear();
  store_->read(b.coord, b.generation, scratch);
  return scratch;
}

VoxelTable BrickMap::take_field(Brick& b) {
  std::lock_guard lock(b.mutex);
  VoxelTable out(brick_level_);
  if (!b.resident) {
    store_->read(b.coord, b.generation, out);
    return out;
  }
  resident_bytes_ -= std::int64_t(b.voxels.memory_bytes());
  std::swap(out, b.voxels);
  resident_bytes_ += std::int64_t(b.voxels.memory_bytes());
  return out;
}

std::array<std::size_t, kMaxLevel + 1> BrickMap::live_voxels_per_level() const {
  using Counts = std::array<std::size_t, kMaxLevel + 1>;
  const std::vector<Brick*> all = bricks();
  // Spilled bricks are read back from their tiles: in parallel, each thread with its own scratch.
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, all.size(), 16), Counts{},
      [&](const tbb::blocked_range<std::size_t>& r, Counts n) {
        VoxelTable scratch(brick_level_);
        for (std::size_t i = r.begin(); i != r.end(); ++i)
          field_of(*all[i], scratch).for_each_block([&](VoxelKey origin, int log, const VoxelData* v) {
            std::size_t live = 0;  // counted without a branch per voxel: blocks are 60-81 % full
            for (std::size_t j = 0, m = std::size_t{1} << (3 * log); j < m; ++j) live += v[j].live();
            n[std::size_t(origin.level())] += live;
          });
        return n;
      },
      [](Counts a, const Counts& b) {
        for (std::size_t l = 0; l < a.size(); ++l) a[l] += b[l];
        return a;
      });
}

void BrickMap::enforce_limit() {
  const std::size_t budget = brick_budget();
  if (!store_ || resident_bytes() <= budget) return;
  // Spill down to 7/8 of the budget, so that the next depth maps (or chunks) do not find it full
  // again at once: each spill round sorts every resident brick.
  const std::size_t target = budget - budget / 8;
  std::vector<Brick*> resident;
  {
    std::shared_lock lock(bricks_mutex_);
    for (auto& [id, b] : bricks_)
      if (b->resident) resident.push_back(b.get());
  }
  std::sort(resident.begin(), resident.end(), [](Brick* a, Brick* b) {
    return a->last_use != b->last_use ? a->last_use < b->last_use : a->coord.packed() < b->coord.packed();
  });
  for (Brick* b : resident) {
    if (resident_bytes() <= target) break;
    spill(*b);
  }
  // The spilled bricks' blocks were many small allocations, freed from several threads' malloc
  // arenas: hand the free pages back, or the process keeps them although the budget is met.
  ::malloc_trim(0);
}

void BrickMap::spill(Brick& b) {
  if (b.needs_tile()) write_tile_of(b);
  release(b);
  ++spilled_;
}

template <class Then>
void BrickMap::write_changed_tiles(const std::vector<Brick*>& bricks, Then&& then) {
  std::vector<std::uint64_t> generation(bricks.size(), 0);
  for (std::size_t i = 0; i < bricks.size(); ++i)
    if (bricks[i]->resident && bricks[i]->needs_tile()) generation[i] = next_generation_++;
  tbb::parallel_for(std::size_t{0}, bricks.size(), [&](std::size_t i) {
    if (!bricks[i]->resident) return;
    if (generation[i] != 0) {
      write_tile_as(*bricks[i], generation[i]);
      bytes_written_ += bricks[i]->tile_bytes;
    }
    then(i);
  });
}

void BrickMap::spill_all() {
  if (!store_) throw std::logic_error("BrickMap::spill_all without a tile store");
  // No malloc_trim here: the next tile reuses the freed heap, and returning it would only make the
  // kernel clear the same pages again.
  // At a plan tile's end every brick of the tile is written at once (written one by one, the
  // other cores waited).
  const std::vector<Brick*> all = bricks();
  write_changed_tiles(all, [&](std::size_t i) {
    release(*all[i]);
    ++spilled_;
  });
}

std::vector<std::pair<BrickCoord, std::size_t>> BrickMap::field_bytes() const {
  // A restored brick's size is unknown until loaded: LZ4 shrank a field about threefold with 4^3
  // blocks in memory, 2.2-fold with 2^3 blocks (igea, session 41), so this overestimates, which
  // errs on the side of the memory budget.
  constexpr std::size_t kTileToField = 3;
  std::vector<std::pair<BrickCoord, std::size_t>> out;
  for (Brick* b : bricks())
    out.push_back({b->coord, b->resident ? resident_size(*b)
                             : b->field_bytes ? b->field_bytes
                                              : b->tile_bytes * kTileToField});
  return out;
}

std::vector<ManifestEntry> BrickMap::write_checkpoint() {
  if (!store_) throw std::logic_error("BrickMap::write_checkpoint without a tile store");
  // The final checkpoint of an integration writes every brick, so in parallel (written one by
  // one they were a serial tail of the stage).
  const std::vector<Brick*> all = bricks();
  write_changed_tiles(all, [](std::size_t) {});
  std::vector<ManifestEntry> manifest;
  for (const Brick* b : all) manifest.push_back({b->coord, b->generation, b->tile_bytes});
  store_->sync();
  return manifest;
}

void BrickMap::checkpoint_committed() {
  for (Brick* b : bricks()) {
    if (b->checkpoint_generation != 0 && b->checkpoint_generation != b->generation)
      store_->remove(b->coord, b->checkpoint_generation);
    b->checkpoint_generation = b->generation;
  }
}

void BrickMap::restore(const std::vector<ManifestEntry>& manifest, std::uint64_t max_generation) {
  clear();
  for (const ManifestEntry& e : manifest) {
    Brick& b = brick(e.coord);
    resident_bytes_ -= std::int64_t(resident_size(b));
    b.resident = false;
    b.dirty = false;
    b.generation = b.checkpoint_generation = e.generation;
    b.tile_bytes = e.bytes;
  }
  next_generation_ = max_generation + 1;
}

void BrickMap::load_all() {
  for (Brick* b : bricks()) {
    std::lock_guard lock(b->mutex);
    make_resident(*b);
  }
}

const VoxelData* BrickMap::find(VoxelKey key) const {
  const Brick* b = find_brick(brick_of(key, brick_level_));
  if (!b) return nullptr;
  if (!b->resident) throw std::logic_error("BrickMap::find on a spilled brick (call load_all first)");
  const VoxelData* v = b->voxels.find(key);
  return (v && v->live()) ? v : nullptr;
}

VoxelData* BrickMap::find(VoxelKey key) {
  return const_cast<VoxelData*>(static_cast<const BrickMap*>(this)->find(key));
}

std::vector<Brick*> BrickMap::bricks() const {
  std::shared_lock lock(bricks_mutex_);
  std::vector<Brick*> out;
  out.reserve(bricks_.size());
  for (auto& [id, b] : bricks_) out.push_back(b.get());
  std::sort(out.begin(), out.end(), [](Brick* a, Brick* b) { return a->coord.packed() < b->coord.packed(); });
  return out;
}

void BrickMap::clear() {
  std::unique_lock lock(bricks_mutex_);
  bricks_.clear();
  resident_bytes_ = 0;
}

void BrickMap::compact() {
  std::unique_lock lock(bricks_mutex_);
  for (auto it = bricks_.begin(); it != bricks_.end();) {
    it->second->voxels.compact();
    if (it->second->voxels.group_count() == 0)
      it = bricks_.erase(it);
    else
      ++it;
  }
  std::int64_t n = 0;
  for (auto& [id, b] : bricks_)
    if (b->resident) n += std::int64_t(resident_size(*b));
  resident_bytes_ = n;
}

}  // namespace sf
