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

BlockGroup* VoxelTable::find_group(std::uint64_t origin) const {
  if (index_.empty()) return nullptr;
  const std::size_t mask = index_.size() - 1;
  for (std::size_t i = std::hash<VoxelKey>{}(VoxelKey{origin}) & mask;; i = (i + 1) & mask) {
    if (index_[i].key == origin) return index_[i].group;
    if (index_[i].key == kEmpty) return nullptr;
  }
}

void VoxelTable::insert_slot(std::uint64_t origin, BlockGroup* group) {
  const std::size_t mask = index_.size() - 1;
  std::size_t i = std::hash<VoxelKey>{}(VoxelKey{origin}) & mask;
  while (index_[i].key != kEmpty) i = (i + 1) & mask;
  index_[i] = {origin, group};
}

void VoxelTable::reindex(std::size_t capacity) {
  const std::vector<Slot> old = std::exchange(index_, std::vector<Slot>(capacity, Slot{kEmpty, nullptr}));
  for (const Slot& s : old)
    if (s.key != kEmpty) insert_slot(s.key, s.group);
}

VoxelTable::VoxelTable(VoxelTable&& other) noexcept : brick_level_(other.brick_level_) { *this = std::move(other); }

VoxelTable& VoxelTable::operator=(VoxelTable&& other) noexcept {
  if (this == &other) return *this;
  brick_level_ = other.brick_level_;
  chunks_ = std::exchange(other.chunks_, {});
  for (unsigned c = 0; c < kCursors; ++c)
    current_[c].store(other.current_[c].exchange(nullptr, std::memory_order_relaxed), std::memory_order_relaxed);
  chunk_bytes_ = std::exchange(other.chunk_bytes_, 0);
  groups_ = std::exchange(other.groups_, 0);
  index_ = std::exchange(other.index_, {});
  return *this;
}

std::size_t VoxelTable::block_count() const {
  std::size_t n = 0;
  for_each_block([&](VoxelKey, int, const VoxelData*) { ++n; });
  return n;
}

std::size_t VoxelTable::grow(std::size_t bytes, unsigned cursor) {
  std::size_t n = chunks_.empty() ? kFirstChunkBytes : std::min(2 * chunk_bytes_, kMaxChunkBytes);
  n = std::max(n, bytes);
  // The head, and one cache line more to align it (calloc aligns to 16).
  const std::size_t total = n + sizeof(ChunkHead) + 64;
  void* raw = std::calloc(1, total);
  if (!raw) throw std::bad_alloc();
  chunks_.emplace_back(raw);
  chunk_bytes_ += total;
  auto* head = new (reinterpret_cast<void*>((reinterpret_cast<std::uintptr_t>(raw) + 63) & ~std::uintptr_t{63})) ChunkHead;
  head->size = n;
  // Release: a thread that finds this chunk finds its head set and its bytes zeroed.
  current_[cursor].store(head, std::memory_order_release);
  return total;
}

void* VoxelTable::allocate(std::size_t bytes, bool alone, std::mutex* lock, std::int64_t* grown, unsigned cursor) {
  static_assert(std::is_trivially_copyable_v<VoxelData> && std::is_trivially_destructible_v<VoxelData>,
                "blocks are calloc'd bytes, never constructed or destroyed");
  bytes = (bytes + 63) & ~std::size_t{63};
  cursor %= kCursors;
  for (;;) {
    ChunkHead* const c = current_[cursor].load(std::memory_order_acquire);
    if (c) {
      std::size_t at;
      if (alone) {
        at = c->used.load(std::memory_order_relaxed);
        if (at + bytes <= c->size) c->used.store(at + bytes, std::memory_order_relaxed);
      } else {
        // Past the end, the count only marks the chunk as full: nothing is carved from there.
        at = c->used.fetch_add(bytes, std::memory_order_relaxed);
      }
      if (at + bytes <= c->size) return c->bytes() + at;
    }
    std::unique_lock<std::mutex> held = lock ? std::unique_lock<std::mutex>(*lock) : std::unique_lock<std::mutex>();
    if (current_[cursor].load(std::memory_order_relaxed) == c) {  // not replaced meanwhile by another thread
      const std::size_t added = grow(bytes, cursor);
      if (grown) *grown += std::int64_t(added);
    }
  }
}

void VoxelTable::reserve(std::size_t groups) {
  std::size_t capacity = index_.empty() ? 16 : index_.size();
  while ((groups + 1) * 10 > capacity * 7) capacity *= 2;  // group()'s rule for growing
  if (capacity > index_.size()) reindex(capacity);
}

BlockGroup* VoxelTable::group(VoxelKey key, bool create) {
  const VoxelKey origin = aligned_origin(key, tile_block_log(key.level(), brick_level_));
  if (BlockGroup* found = find_group(origin.bits)) return found;
  if (!create) return nullptr;
  BlockGroup* const g = new (allocate(sizeof(BlockGroup), false)) BlockGroup{};
  ++groups_;
  if ((groups_ + 1) * 10 > index_.size() * 7) reindex(index_.empty() ? 16 : index_.size() * 2);
  insert_slot(origin.bits, g);
  return g;
}

VoxelData* VoxelTable::part_voxels(int log, bool alone, std::mutex* lock, unsigned cursor, std::int64_t* grown) {
  // calloc's zeros are VoxelData{} (absent voxels), and a VoxelData is an implicit-lifetime type,
  // which memory from the malloc family holds without a constructor.
  const std::size_t n = std::size_t{1} << (3 * log);
  return static_cast<VoxelData*>(allocate(n * sizeof(VoxelData), alone, lock, grown, cursor));
}

VoxelData* VoxelTable::make_part(BlockGroup& group, int part_index, int log) {
  std::atomic<VoxelData*>& part = group.part[part_index];
  VoxelData* v = part.load(std::memory_order_relaxed);
  if (!v) {
    v = part_voxels(log, true, nullptr, 0, nullptr);
    part.store(v, std::memory_order_relaxed);
  }
  return v;
}

VoxelData* VoxelTable::make_part_shared(BlockGroup& group, int part_index, int log, std::mutex* lock, unsigned cursor,
                                        std::int64_t* grown) {
  std::atomic<VoxelData*>& part = group.part[part_index];
  VoxelData* made = part.load(std::memory_order_acquire);
  if (made) return made;
  VoxelData* const fresh = part_voxels(log, false, lock, cursor, grown);
  // Release: a thread that finds the pointer finds the block's zeroed voxels. If another thread
  // made the block first, `fresh` stays unused in the arena (zeroed bytes no group points to).
  return part.compare_exchange_strong(made, fresh, std::memory_order_acq_rel, std::memory_order_acquire) ? fresh : made;
}

BlockRef VoxelTable::block(VoxelKey key, bool create) {
  const VoxelKey origin = block_origin(key);
  const int log = block_log(key.level(), brick_level_);
  BlockGroup* const g = group(key, create);
  if (!g) return {origin, log, nullptr};
  const int part = group_part(key, brick_level_);
  // The caller holds the lock that guards the index, but integration's threads may be making
  // blocks of this table without it: the same steps as theirs.
  VoxelData* const v = create ? make_part_shared(*g, part, log, nullptr, 0, nullptr)
                              : g->part[part].load(std::memory_order_acquire);
  return {origin, log, v};
}

const VoxelData* VoxelTable::find(VoxelKey key) const {
  const BlockGroup* const g =
      find_group(aligned_origin(key, tile_block_log(key.level(), brick_level_)).bits);
  if (!g) return nullptr;
  VoxelData* const voxels = g->part[group_part(key, brick_level_)].load(std::memory_order_acquire);
  if (!voxels) return nullptr;
  const VoxelData& v = BlockRef{block_origin(key), block_log(key.level(), brick_level_), voxels}.at(key);
  return v.weight != 0 ? &v : nullptr;
}

VoxelData* VoxelTable::find(VoxelKey key) {
  return const_cast<VoxelData*>(static_cast<const VoxelTable*>(this)->find(key));
}

VoxelData& VoxelTable::find_or_insert(VoxelKey key) { return block(key, true).at(key); }

void VoxelTable::compact() {
  VoxelTable kept(brick_level_);
  for_each_block([&](VoxelKey origin, int log, const VoxelData* v) {
    VoxelData* const voxels = const_cast<VoxelData*>(v);
    const std::size_t n = std::size_t{1} << (3 * log);
    bool any = false;
    for (std::size_t i = 0; i < n; ++i) {
      if (voxels[i].erased()) voxels[i] = VoxelData{};
      any = any || voxels[i].live();
    }
    if (any) std::copy(voxels, voxels + n, kept.block(origin, true).data);
  });
  *this = std::move(kept);
}

void VoxelTable::clear() {
  std::vector<Slot>().swap(index_);
  std::vector<std::unique_ptr<void, FreeChunk>>().swap(chunks_);
  for (std::atomic<ChunkHead*>& c : current_) c.store(nullptr, std::memory_order_relaxed);
  chunk_bytes_ = 0;
  groups_ = 0;
}

}  // namespace sf
