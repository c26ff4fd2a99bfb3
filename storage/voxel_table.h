#pragma once
// The voxels of one brick: an open-addressing hash table (linear probing) from VoxelKey to
// VoxelData. ~32 bytes per slot at <= 70% load, against ~64+ for std::unordered_map, and one cache
// miss per lookup. Erasure is lazy (see VoxelData::erased) and compact() rebuilds.
#include <cstdint>
#include <vector>

#include "storage/voxel_key.h"

namespace sf {

// The hSDF sample of one voxel: cumulative weighted averages (equations 2-3 of the paper).
struct VoxelData {
  float distance = 0;       // D: weighted mean signed distance, metres, positive in front
  float weight = 0;         // W: accumulated weight (confidence); < 0 marks an erased voxel
  float colour[3] = {0, 0, 0};  // weighted mean colour, 0..255
  float colour_weight = 0;  // weight of the contributions that carried colour

  bool erased() const { return weight < 0; }
};

class VoxelTable {
 public:
  VoxelTable() = default;

  std::size_t size() const { return size_; }  // slots in use, erased ones included until compact()
  std::size_t capacity() const { return keys_.size(); }

  VoxelData* find(VoxelKey key);
  const VoxelData* find(VoxelKey key) const;
  // Returns the voxel, creating a zero one if absent (then *created = true).
  VoxelData& find_or_insert(VoxelKey key, bool* created = nullptr);
  // Drops erased voxels and shrinks the table.
  void compact();

  // Visits every live (non-erased) voxel: f(VoxelKey, VoxelData&).
  template <class F>
  void for_each(F&& f) {
    for (std::size_t i = 0; i < keys_.size(); ++i)
      if (keys_[i] != kEmpty && !values_[i].erased()) f(VoxelKey{keys_[i]}, values_[i]);
  }
  template <class F>
  void for_each(F&& f) const {
    for (std::size_t i = 0; i < keys_.size(); ++i)
      if (keys_[i] != kEmpty && !values_[i].erased()) f(VoxelKey{keys_[i]}, values_[i]);
  }

 private:
  // No valid key has all bits set (the two top bits are always zero).
  static constexpr std::uint64_t kEmpty = ~std::uint64_t{0};
  void rehash(std::size_t new_capacity);
  std::size_t slot_of(std::uint64_t key) const;

  std::vector<std::uint64_t> keys_;
  std::vector<VoxelData> values_;
  std::size_t size_ = 0;
};

}  // namespace sf
