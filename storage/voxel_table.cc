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
  bytes_ = blocks_.capacity() * sizeof(Block) + index_.capacity() * sizeof(Slot);
  for (const Block& b : blocks_) bytes_ += (std::size_t{1} << (3 * b.log)) * sizeof(VoxelData);
}

VoxelData* VoxelTable::find_block(std::uint64_t origin) const {
  if (index_.empty()) return nullptr;
  const std::size_t mask = index_.size() - 1;
  for (std::size_t i = std::hash<VoxelKey>{}(VoxelKey{origin}) & mask;; i = (i + 1) & mask) {
    if (index_[i].key == origin) return index_[i].voxels;
    if (index_[i].key == kEmpty) return nullptr;
  }
}

void VoxelTable::insert_slot(std::uint64_t origin, VoxelData* voxels) {
  const std::size_t mask = index_.size() - 1;
  std::size_t i = std::hash<VoxelKey>{}(VoxelKey{origin}) & mask;
  while (index_[i].key != kEmpty) i = (i + 1) & mask;
  index_[i] = {origin, voxels};
}

void VoxelTable::reindex(std::size_t capacity) {
  index_.assign(capacity, Slot{kEmpty, nullptr});
  for (const Block& b : blocks_) insert_slot(b.origin.bits, b.voxels.get());
}

BlockRef VoxelTable::block(VoxelKey key, bool create) {
  const VoxelKey origin = block_origin(key);
  const int log = block_log(key.level(), brick_level_);
  if (VoxelData* found = find_block(origin.bits)) return {origin, log, found};
  if (!create) return {origin, log, nullptr};
  Block b;
  b.origin = origin;
  b.log = log;
  b.voxels = std::make_unique<VoxelData[]>(std::size_t{1} << (3 * log));
  VoxelData* const voxels = b.voxels.get();
  const std::size_t old_capacity = blocks_.capacity();
  blocks_.push_back(std::move(b));
  bytes_ += (std::size_t{1} << (3 * log)) * sizeof(VoxelData) + (blocks_.capacity() - old_capacity) * sizeof(Block);
  if ((blocks_.size() + 1) * 10 > index_.size() * 7) {
    bytes_ -= index_.capacity() * sizeof(Slot);
    reindex(index_.empty() ? 16 : index_.size() * 2);
    bytes_ += index_.capacity() * sizeof(Slot);
  } else {
    insert_slot(origin.bits, voxels);
  }
  return {origin, log, voxels};
}

const VoxelData* VoxelTable::find(VoxelKey key) const {
  const VoxelKey origin = block_origin(key);
  VoxelData* const voxels = find_block(origin.bits);
  if (!voxels) return nullptr;
  const VoxelData& v = BlockRef{origin, block_log(key.level(), brick_level_), voxels}.at(key);
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
  std::vector<Slot>().swap(index_);
  bytes_ = 0;
}

}  // namespace sf
