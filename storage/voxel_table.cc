#include "storage/voxel_table.h"

#include <functional>
#include <utility>

namespace sf {

std::size_t VoxelTable::live_count() const {
  std::size_t n = 0;
  for_each([&](VoxelKey, const VoxelData&) { ++n; });
  return n;
}

void VoxelTable::recount() {
  bytes_ = blocks_.capacity() * sizeof(Block) + index_keys_.capacity() * 12;
  for (const Block& b : blocks_) bytes_ += (std::size_t{1} << (3 * b.log)) * sizeof(VoxelData);
}

std::int64_t VoxelTable::find_slot(std::uint64_t origin) const {
  if (index_keys_.empty()) return -1;
  const std::size_t mask = index_keys_.size() - 1;
  for (std::size_t i = std::hash<VoxelKey>{}(VoxelKey{origin}) & mask;; i = (i + 1) & mask) {
    if (index_keys_[i] == origin) return index_pos_[i];
    if (index_keys_[i] == kEmpty) return -1;
  }
}

void VoxelTable::reindex(std::size_t capacity) {
  index_keys_.assign(capacity, kEmpty);
  index_pos_.assign(capacity, 0);
  const std::size_t mask = capacity - 1;
  for (std::size_t p = 0; p < blocks_.size(); ++p) {
    std::size_t i = std::hash<VoxelKey>{}(blocks_[p].origin) & mask;
    while (index_keys_[i] != kEmpty) i = (i + 1) & mask;
    index_keys_[i] = blocks_[p].origin.bits;
    index_pos_[i] = std::uint32_t(p);
  }
}

BlockRef VoxelTable::block(VoxelKey key, bool create) {
  const VoxelKey origin = block_origin(key);
  const int log = block_log(key.level(), brick_level_);
  const std::int64_t p = find_slot(origin.bits);
  if (p >= 0) return {origin, log, blocks_[std::size_t(p)].voxels.get()};
  if (!create) return {origin, log, nullptr};
  Block b;
  b.origin = origin;
  b.log = log;
  b.voxels = std::make_unique<VoxelData[]>(std::size_t{1} << (3 * log));
  const std::size_t old_capacity = blocks_.capacity();
  blocks_.push_back(std::move(b));
  bytes_ += (std::size_t{1} << (3 * log)) * sizeof(VoxelData) + (blocks_.capacity() - old_capacity) * sizeof(Block);
  if ((blocks_.size() + 1) * 10 > index_keys_.size() * 7) {
    bytes_ -= index_keys_.capacity() * 12;
    reindex(index_keys_.empty() ? 16 : index_keys_.size() * 2);
    bytes_ += index_keys_.capacity() * 12;
  } else {
    const std::size_t mask = index_keys_.size() - 1;
    std::size_t i = std::hash<VoxelKey>{}(origin) & mask;
    while (index_keys_[i] != kEmpty) i = (i + 1) & mask;
    index_keys_[i] = origin.bits;
    index_pos_[i] = std::uint32_t(blocks_.size() - 1);
  }
  return {origin, log, blocks_.back().voxels.get()};
}

const VoxelData* VoxelTable::find(VoxelKey key) const {
  const std::int64_t p = find_slot(block_origin(key).bits);
  if (p < 0) return nullptr;
  const Block& b = blocks_[std::size_t(p)];
  const VoxelData& v = BlockRef{b.origin, b.log, b.voxels.get()}.at(key);
  return v.weight != 0 ? &v : nullptr;
}

VoxelData* VoxelTable::find(VoxelKey key) {
  return const_cast<VoxelData*>(static_cast<const VoxelTable*>(this)->find(key));
}

VoxelData& VoxelTable::find_or_insert(VoxelKey key) { return block(key, true).at(key); }

void VoxelTable::compact() {
  std::vector<Block> kept;
  for (Block& b : blocks_) {
    const std::size_t n = std::size_t{1} << (3 * b.log);
    bool any = false;
    for (std::size_t i = 0; i < n; ++i) {
      if (b.voxels[i].erased()) b.voxels[i] = VoxelData{};
      any = any || b.voxels[i].live();
    }
    if (any) kept.push_back(std::move(b));
  }
  blocks_ = std::move(kept);
  std::size_t cap = 16;
  while ((blocks_.size() + 1) * 10 > cap * 7) cap *= 2;
  reindex(cap);
  recount();
}

void VoxelTable::clear() {
  std::vector<Block>().swap(blocks_);
  std::vector<std::uint64_t>().swap(index_keys_);
  std::vector<std::uint32_t>().swap(index_pos_);
  bytes_ = 0;
}

}  // namespace sf
