#pragma once
// The pieces of section 7 that the global extraction (extract.cc) and the brick-by-brick one
// (engine/extract_bricks.cc) share: a set of voxels in key order with the attributes the output
// interpolates, the 7.1 cell filter, crossings' attributes, and the order of output vertices.
#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <string>
#include <vector>

#include "engine/extract/delaunay.h"
#include "engine/extract/extract.h"
#include "engine/extract/marching_tets.h"
#include "storage/voxel_key.h"

namespace sf::extract_detail {

// The voxels in key order, with the attributes the output interpolates.
struct Voxels {
  std::vector<VoxelKey> key;
  std::vector<Eigen::Vector3d> position;
  std::vector<float> distance, weight, scale;
  std::vector<std::array<float, 3>> colour;

  std::size_t size() const { return key.size(); }
  FieldView view() const { return FieldView{position.data(), distance.data()}; }
};

// 7.1 on one cell: all six edges must join neighbouring voxels.
inline bool keep_cell(const Tet& t, const Voxels& v, int n) {
  for (int i = 0; i < 4; ++i) {
    for (int j = i + 1; j < 4; ++j) {
      if (!are_neighbours(v.key[t[i]], v.key[t[j]], n)) return false;
    }
  }
  return true;
}

inline std::array<float, 4> cell_distances(const Tet& t, const std::vector<float>& d) {
  return {d[t[0]], d[t[1]], d[t[2]], d[t[3]]};
}

// Which candidate list a kept cell goes to; kNever: it can never emit.
enum class CellKind { kNever, kMixed, kNegativeOnly };
inline CellKind cell_kind(const std::array<float, 4>& d) {
  if (!(d[0] < 0 || d[1] < 0 || d[2] < 0 || d[3] < 0)) return CellKind::kNever;
  return (d[0] > 0 || d[1] > 0 || d[2] > 0 || d[3] > 0) ? CellKind::kMixed : CellKind::kNegativeOnly;
}

// Interpolated attributes of a crossing or a voxel.
struct Attributes {
  Eigen::Vector3d position;
  std::array<float, 3> colour;
  float weight, scale;
};

inline Attributes voxel_attributes(const Voxels& v, std::uint32_t i) {
  return {v.position[i], v.colour[i], v.weight[i], v.scale[i]};
}

inline Attributes crossing_attributes(const Voxels& v, std::uint32_t lo, std::uint32_t hi) {
  const double t = crossing_fraction(v.distance[lo], v.distance[hi]);
  const auto mix = [t](float a, float b) { return float(double(a) + t * (double(b) - double(a))); };
  Attributes a;
  a.position = lerp(v.position[lo], v.position[hi], t);
  for (int c = 0; c < 3; ++c) a.colour[c] = mix(v.colour[lo][c], v.colour[hi][c]);
  a.weight = mix(v.weight[lo], v.weight[hi]);
  a.scale = mix(v.scale[lo], v.scale[hi]);
  return a;
}

inline std::uint8_t to_byte(float c) { return std::uint8_t(std::lround(std::clamp(c, 0.0f, 255.0f))); }

// What is wrong with a voxel's values (non-finite distance, weight or colour), or nullptr; both
// extraction paths check their input with it.
inline const char* value_problem(const SurfaceVoxel& v) {
  if (!std::isfinite(v.distance)) return "has a non-finite distance";
  if (!std::isfinite(v.weight)) return "has a non-finite weight";
  for (float c : v.colour)
    if (!std::isfinite(c)) return "has a non-finite colour";
  return nullptr;
}

// "level L (x, y, z)", for error messages.
inline std::string describe(VoxelKey k) {
  std::ostringstream s;
  s << "level " << k.level() << " (" << k.x() << ", " << k.y() << ", " << k.z() << ")";
  return s.str();
}

// The order of output vertices. A vertex is named by its voxels (a, a) or the crossing (a, b),
// a < b in key order; vertices sort by the Morton code of a's position on the deepest lattice,
// then by a's key, then b's. A brick of any level is one contiguous range of Morton codes, so the
// vertices whose voxel a lies in one brick (the brick's "home" vertices) are contiguous in the
// output, bricks in Morton order: the brick-by-brick extraction can number them brick by brick
// and produce the same file as the global one, whatever the brick size.
inline std::uint64_t spread_bits(std::uint64_t v) {  // bit i -> bit 3i, for 21-bit v
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffull;
  v = (v | v << 16) & 0x1f0000ff0000ffull;
  v = (v | v << 8) & 0x100f00f00f00f00full;
  v = (v | v << 4) & 0x10c30c30c30c30c3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}
inline std::uint64_t morton(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
  return spread_bits(x) | spread_bits(y) << 1 | spread_bits(z) << 2;
}
// The Morton code of a voxel's position at level kMaxLevel; the root's upper faces are clamped
// into the last cell, as bricks take them (storage/brick_map.h).
inline std::uint64_t home_code(VoxelKey k) {
  const int shift = kMaxLevel - k.level();
  constexpr std::uint32_t last = (std::uint32_t{1} << kMaxLevel) - 1;
  return morton(std::min(k.x() << shift, last), std::min(k.y() << shift, last), std::min(k.z() << shift, last));
}

}  // namespace sf::extract_detail
