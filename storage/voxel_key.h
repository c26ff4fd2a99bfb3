#pragma once
// Voxel keys of the primal octree.
//
// The root cube [min, min + size]^3 is level 0. Level l has cells of edge size / 2^l and
// (2^l + 1)^3 voxels at the cell corners, with integer coordinates 0..2^l per axis. A voxel of
// level l coincides with voxel (2x, 2y, 2z) of level l + 1; both are kept (the hSDF stores each
// level separately), so the key carries the level.
//
//   bit 63..62   61..57    56..38     37..19     18..0
//   ----------  --------  ---------  ---------  ---------
//     unused     level     z coord    y coord    x coord
//     (zero)    (5 bits)  (19 bits)  (19 bits)  (19 bits)
//
// A coordinate of level l reaches 2^l, which needs l + 1 bits, so with 19 bits the deepest level
// is 18 (262,145 voxels per axis: a 100 m root cube gives 0.38 mm cells). Keys compare first by
// level, then z, y, x; sorting them gives a deterministic order independent of hash tables.
#include <cstdint>
#include <functional>

namespace sf {

inline constexpr int kCoordBits = 19;
inline constexpr int kMaxLevel = 18;
inline constexpr std::uint64_t kCoordMask = (std::uint64_t{1} << kCoordBits) - 1;

struct VoxelKey {
  std::uint64_t bits = 0;

  // The layout, for code that puts keys together field by field (integration's lattice axes).
  static constexpr int kLevelShift = 3 * kCoordBits;
  static constexpr std::uint64_t level_bits(int level) { return std::uint64_t(level) << kLevelShift; }
  static constexpr int coord_shift(int axis) { return axis * kCoordBits; }  // axis 0 = x, 1 = y, 2 = z
  static constexpr VoxelKey make(int level, std::uint32_t x, std::uint32_t y, std::uint32_t z) {
    return VoxelKey{level_bits(level) | (std::uint64_t(z) << coord_shift(2)) | (std::uint64_t(y) << coord_shift(1)) |
                    (std::uint64_t(x) << coord_shift(0))};
  }
  constexpr int level() const { return int(bits >> kLevelShift); }
  constexpr std::uint32_t x() const { return std::uint32_t((bits >> coord_shift(0)) & kCoordMask); }
  constexpr std::uint32_t y() const { return std::uint32_t((bits >> coord_shift(1)) & kCoordMask); }
  constexpr std::uint32_t z() const { return std::uint32_t((bits >> coord_shift(2)) & kCoordMask); }

  // The same point one level finer (always exists below kMaxLevel).
  constexpr VoxelKey finer() const { return make(level() + 1, 2 * x(), 2 * y(), 2 * z()); }
  // The coinciding voxel one level coarser; valid only if all coordinates are even.
  constexpr bool has_coarser_twin() const {
    return level() > 0 && ((x() | y() | z()) & 1u) == 0;
  }
  constexpr VoxelKey coarser_twin() const { return make(level() - 1, x() / 2, y() / 2, z() / 2); }

  friend constexpr bool operator==(VoxelKey a, VoxelKey b) { return a.bits == b.bits; }
  friend constexpr bool operator!=(VoxelKey a, VoxelKey b) { return a.bits != b.bits; }
  friend constexpr bool operator<(VoxelKey a, VoxelKey b) { return a.bits < b.bits; }
};

// True if (level, x, y, z) is a representable voxel.
constexpr bool valid_voxel(int level, std::int64_t x, std::int64_t y, std::int64_t z) {
  const std::int64_t n = std::int64_t{1} << level;
  return level >= 0 && level <= kMaxLevel && x >= 0 && y >= 0 && z >= 0 && x <= n && y <= n && z <= n;
}

}  // namespace sf

template <>
struct std::hash<sf::VoxelKey> {
  std::size_t operator()(sf::VoxelKey k) const noexcept {
    // splitmix64 finaliser: keys of neighbouring voxels differ in low bits only.
    std::uint64_t z = k.bits + 0x9e3779b97f4a7c15ull;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return std::size_t(z ^ (z >> 31));
  }
};
