#include "storage/voxel_table.h"

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <functional>
#include <new>
#include <type_traits>
#include <utility>

namespace sf {

std::size_t VoxelTable::live_count() const {
  std::size_t n = 0;
  for_each([&](VoxelKey, const VoxelData&) { ++n; });
  return n;
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
  const std::vector<Slot> old = std::exchange(index_, std::vector<Slot>(capacity, Slot{kEmpty, nullptr}));
  for (const Slot& s : old)
    if (s.key != kEmpty) insert_slot(s.key, s.voxels);
}

VoxelData* VoxelTable::allocate(std::size_t voxels) {
  static_assert(std::is_trivially_copyable_v<VoxelData> && std::is_trivially_destructible_v<VoxelData>,
                "blocks are calloc'd bytes, never constructed or destroyed");
  constexpr std::size_t kLine = 64 / sizeof(VoxelData);  // voxels per cache line
  voxels = (voxels + kLine - 1) / kLine * kLine;
  if (room_ < voxels) {
    std::size_t n = chunks_.empty() ? kFirstChunkVoxels : std::min(2 * (chunk_bytes_ / sizeof(VoxelData)), kMaxChunkVoxels);
    n = std::max(n, voxels);
    // One cache line more than asked for, to align the first voxel (calloc aligns to 16 bytes).
    const std::size_t bytes = n * sizeof(VoxelData) + 64;
    void* raw = std::calloc(1, bytes);
    if (!raw) throw std::bad_alloc();
    chunks_.emplace_back(raw);
    chunk_bytes_ += bytes;
    const std::uintptr_t at = (reinterpret_cast<std::uintptr_t>(raw) + 63) & ~std::uintptr_t{63};
    next_ = reinterpret_cast<VoxelData*>(at);
    room_ = n;
  }
  VoxelData* const out = next_;
  next_ += voxels;
  room_ -= voxels;
  return out;
}

BlockRef VoxelTable::block(VoxelKey key, bool create) {
  const VoxelKey origin = block_origin(key);
  const int log = block_log(key.level(), brick_level_);
  if (VoxelData* found = find_block(origin.bits)) return {origin, log, found};
  if (!create) return {origin, log, nullptr};
  VoxelData* const voxels = allocate(std::size_t{1} << (3 * log));
  ++blocks_;
  if ((blocks_ + 1) * 10 > index_.size() * 7)
    reindex(index_.empty() ? 16 : index_.size() * 2);
  insert_slot(origin.bits, voxels);
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
  VoxelTable kept(brick_level_);
  for (const Slot& s : index_) {
    if (s.key == kEmpty) continue;
    const std::size_t n = std::size_t{1} << (3 * block_log(VoxelKey{s.key}.level(), brick_level_));
    bool any = false;
    for (std::size_t i = 0; i < n; ++i) {
      if (s.voxels[i].erased()) s.voxels[i] = VoxelData{};
      any = any || s.voxels[i].live();
    }
    if (!any) continue;
    VoxelData* const to = kept.block(VoxelKey{s.key}, true).data;
    std::copy(s.voxels, s.voxels + n, to);
  }
  *this = std::move(kept);
}

void VoxelTable::clear() {
  std::vector<Slot>().swap(index_);
  std::vector<std::unique_ptr<void, FreeChunk>>().swap(chunks_);
  next_ = nullptr;
  room_ = 0;
  chunk_bytes_ = 0;
  blocks_ = 0;
}

}  // namespace sf
