#include "engine/extract/lattice_cubes.h"

#include <algorithm>
#include <numeric>

namespace sf::extract_detail {
namespace {

// (level, x, y, z) of a lattice position of that level; indices are at most 2^18.
constexpr int kField = 19;
std::uint64_t cube_key(int level, std::int64_t x, std::int64_t y, std::int64_t z) {
  return (std::uint64_t(level) << (3 * kField)) | (std::uint64_t(z) << (2 * kField)) | (std::uint64_t(y) << kField) |
         std::uint64_t(x);
}
std::uint64_t cell_key(std::int64_t x, std::int64_t y, std::int64_t z) { return cube_key(0, x, y, z); }

}  // namespace

EmptyCubes::EmptyCubes(const std::vector<LatticePoint>& points, const std::vector<std::uint8_t>& level, int G,
                       std::uint32_t levels, const Holds& holds)
    : points_(points), level_(level), G_(G), cube_at_(points.size()), interior_(points.size(), 0) {
  const std::size_t count = points.size();
  const auto index_of = [&](std::size_t i, int a) { return std::int64_t(points[i][a]) >> (G - level[i]); };
  // The points' keys (level, z, y, x) in increasing order, as a window's members come (others are
  // sorted first): the key of a cube's corner (x + dx, y + dy, z + dz) is its minimum corner's
  // plus a constant (no carry: indices are at most 2^18), so for each of the 7 other corners a
  // cursor walks the keys once, in step with the minimum corners. A hash table of the window's
  // size cost a cache miss per corner.
  std::vector<std::uint64_t> key(count);
  std::uint32_t here = 0;
  for (std::size_t i = 0; i < count; ++i) {
    key[i] = cube_key(level[i], index_of(i, 0), index_of(i, 1), index_of(i, 2));
    here |= 1u << level[i];
  }
  std::vector<std::uint32_t> order;  // point at each place in key order; empty: already in order
  if (!std::is_sorted(key.begin(), key.end())) {
    order.resize(count);
    std::iota(order.begin(), order.end(), 0u);
    std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return key[a] < key[b]; });
    std::vector<std::uint64_t> sorted(count);
    for (std::size_t s = 0; s < count; ++s) sorted[s] = key[order[s]];
    key.swap(sorted);
  }
  const auto point_at = [&](std::size_t s) { return order.empty() ? std::uint32_t(s) : order[s]; };
  // Per level l with finer voxels in the set: their cells on the grid of level l + 1.
  std::vector<std::vector<std::uint64_t>> finer(std::size_t(G) + 1);
  for (int l = 0; l < G; ++l) {
    if (!(here >> l & 1) || !(here >> (l + 1))) continue;
    const int shift = G - l - 1;
    for (std::size_t s = 0; s < count; ++s) {
      const std::uint32_t i = point_at(s);
      if (level[i] <= l) continue;
      // Runs along x share a cell (the points are in key order): left out before the sort.
      const std::uint64_t cell = cell_key(points[i][0] >> shift, points[i][1] >> shift, points[i][2] >> shift);
      if (finer[l].empty() || finer[l].back() != cell) finer[l].push_back(cell);
    }
    std::sort(finer[l].begin(), finer[l].end());
  }
  const std::int64_t side = std::int64_t{1} << G;
  std::array<std::size_t, 8> cursor{};  // per corner: the first place whose key is not below the corner's
  for (std::size_t s = 0; s < count; ++s) {
    const std::uint32_t i = point_at(s);
    const int l = level[i];
    const std::int64_t x = index_of(i, 0), y = index_of(i, 1), z = index_of(i, 2);
    std::array<std::uint32_t, 8> corner;
    corner[0] = i;
    bool complete = true;
    for (int c = 1; c < 8 && complete; ++c) {
      const std::uint64_t want = key[s] + cube_key(0, c & 1, c >> 1 & 1, c >> 2 & 1);
      std::size_t& at = cursor[std::size_t(c)];
      while (at < count && key[at] < want) ++at;
      complete = at < count && key[at] == want;
      if (complete) corner[c] = point_at(at);
    }
    if (!complete) continue;
    if (levels >> (l + 1)) {
      // Finer voxels strictly inside the sphere are within h of its centre on every axis: in the
      // cube grown by h/2, which the set must be known to hold, on the 4^3 cells of level l + 1
      // around the centre.
      const std::int64_t h = std::int64_t{1} << (G - l);
      std::int64_t lo[3], hi[3];
      const std::int64_t idx[3] = {x, y, z};
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::max<std::int64_t>(0, idx[a] * h - h / 2);
        hi[a] = std::min(side, (idx[a] + 1) * h + h / 2);
      }
      bool empty = true;
      for (int L = l + 1; L <= G && empty; ++L)
        if (levels >> L & 1) empty = holds(L, lo, hi);
      if (empty && !finer[l].empty())
        for (std::int64_t cz = 2 * z - 1; cz <= 2 * z + 2 && empty; ++cz)
          for (std::int64_t cy = 2 * y - 1; cy <= 2 * y + 2 && empty; ++cy) {
            if (cz < 0 || cy < 0) continue;
            const auto it = std::lower_bound(finer[l].begin(), finer[l].end(), cell_key(std::max<std::int64_t>(0, 2 * x - 1), cy, cz));
            empty = !(it != finer[l].end() && *it <= cell_key(2 * x + 2, cy, cz));
          }
      if (!empty) continue;
    }
    cube_at_.insert(cube_key(l, x, y, z), std::uint32_t(corners_.size()));
    corners_.push_back(corner);
    cube_levels_ |= 1u << l;
  }
  // A point is interior when it is a corner of all 8 cubes of its level around it: corner c of
  // one of them, for each c (interior_ holds those 8 bits).
  for (const std::array<std::uint32_t, 8>& corner : corners_)
    for (int c = 0; c < 8; ++c) interior_[corner[c]] |= std::uint8_t(1u << c);
}

bool EmptyCubes::covers(const Tet& t) const {
  const int l = level_[t[0]];
  if (level_[t[1]] != l || level_[t[2]] != l || level_[t[3]] != l || !(cube_levels_ >> l & 1)) return false;
  if (!interior_[t[0]] || !interior_[t[1]] || !interior_[t[2]] || !interior_[t[3]]) return false;
  std::int64_t c[3];  // 4 x the centroid
  for (int a = 0; a < 3; ++a)
    c[a] = std::int64_t(points_[t[0]][a]) + points_[t[1]][a] + points_[t[2]][a] + points_[t[3]][a];
  return covers_at(l, c);
}

bool EmptyCubes::covers(const LatticePoint& p0, const LatticePoint& p1, const LatticePoint& p2,
                        const LatticePoint& p3) const {
  std::int64_t c[3];  // 4 x the centroid
  for (int a = 0; a < 3; ++a) c[a] = std::int64_t(p0[a]) + p1[a] + p2[a] + p3[a];
  for (int l = 0; l <= G_; ++l)
    if ((cube_levels_ >> l & 1) && covers_at(l, c)) return true;
  return false;
}

bool EmptyCubes::covers_at(int l, const std::int64_t c[3]) const {
  // A centroid on a face, edge or corner of the level's cubes is in each cube sharing it.
  const std::int64_t edge = std::int64_t{4} << (G_ - l);
  std::int64_t lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    hi[a] = c[a] / edge;
    lo[a] = c[a] % edge == 0 && hi[a] > 0 ? hi[a] - 1 : hi[a];
  }
  for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
    for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
      for (std::int64_t x = lo[0]; x <= hi[0]; ++x)
        if (cube_at_.find(cube_key(l, x, y, z)) >= 0) return true;
  return false;
}

}  // namespace sf::extract_detail
