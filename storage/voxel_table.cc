#include "storage/voxel_table.h"

#include <functional>

namespace sf {

std::size_t VoxelTable::slot_of(std::uint64_t key) const {
  return std::hash<VoxelKey>{}(VoxelKey{key}) & (keys_.size() - 1);
}

const VoxelData* VoxelTable::find(VoxelKey key) const {
  if (keys_.empty()) return nullptr;
  const std::size_t mask = keys_.size() - 1;
  for (std::size_t i = slot_of(key.bits);; i = (i + 1) & mask) {
    if (keys_[i] == key.bits) return &values_[i];
    if (keys_[i] == kEmpty) return nullptr;
  }
}

VoxelData* VoxelTable::find(VoxelKey key) {
  return const_cast<VoxelData*>(static_cast<const VoxelTable*>(this)->find(key));
}

VoxelData& VoxelTable::find_or_insert(VoxelKey key, bool* created) {
  if ((size_ + 1) * 10 > keys_.size() * 7) rehash(keys_.empty() ? 64 : keys_.size() * 2);
  const std::size_t mask = keys_.size() - 1;
  for (std::size_t i = slot_of(key.bits);; i = (i + 1) & mask) {
    if (keys_[i] == key.bits) {
      if (created) *created = false;
      return values_[i];
    }
    if (keys_[i] == kEmpty) {
      keys_[i] = key.bits;
      values_[i] = VoxelData{};
      ++size_;
      if (created) *created = true;
      return values_[i];
    }
  }
}

void VoxelTable::rehash(std::size_t new_capacity) {
  std::vector<std::uint64_t> old_keys(new_capacity, kEmpty);
  std::vector<VoxelData> old_values(new_capacity);
  old_keys.swap(keys_);
  old_values.swap(values_);
  size_ = 0;
  const std::size_t mask = keys_.size() - 1;
  for (std::size_t j = 0; j < old_keys.size(); ++j) {
    if (old_keys[j] == kEmpty || old_values[j].erased()) continue;
    std::size_t i = slot_of(old_keys[j]);
    while (keys_[i] != kEmpty) i = (i + 1) & mask;
    keys_[i] = old_keys[j];
    values_[i] = old_values[j];
    ++size_;
  }
}

void VoxelTable::compact() {
  std::size_t live = 0;
  for_each([&](VoxelKey, VoxelData&) { ++live; });
  if (live == 0) {
    keys_.clear();
    values_.clear();
    size_ = 0;
    return;
  }
  std::size_t cap = 64;
  while (live * 10 > cap * 7) cap *= 2;
  rehash(cap);
}

}  // namespace sf
