#include "storage/brick_map.h"

#include <algorithm>
#include <mutex>

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
  if (!slot) slot = std::make_unique<Brick>(c, brick_level_);
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
  for (const Contribution& c : batch) {
    const BrickCoord bc = brick_of(c.key, brick_level_);
    if (bc.packed() != current_id) {
      if (lock.owns_lock()) lock.unlock();
      current = &brick(bc);
      current_id = bc.packed();
      lock = std::unique_lock<std::mutex>(current->mutex);
    }
    accumulate(current->voxels.find_or_insert(c.key), c.distance, c.weight, c.has_colour ? c.colour : nullptr);
  }
}

BlockRef BrickMap::block(VoxelKey key) {
  Brick& b = brick(brick_of(key, brick_level_));
  std::lock_guard lock(b.mutex);
  return b.voxels.block(key, true);
}

const VoxelData* BrickMap::find(VoxelKey key) const {
  const Brick* b = find_brick(brick_of(key, brick_level_));
  if (!b) return nullptr;
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
}

void BrickMap::compact() {
  std::unique_lock lock(bricks_mutex_);
  for (auto it = bricks_.begin(); it != bricks_.end();) {
    it->second->voxels.compact();
    if (it->second->voxels.block_count() == 0)
      it = bricks_.erase(it);
    else
      ++it;
  }
}

}  // namespace sf
