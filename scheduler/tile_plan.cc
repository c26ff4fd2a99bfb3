#include "scheduler/tile_plan.h"

#include <algorithm>
#include <map>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>

namespace sf {

std::vector<std::pair<BrickCoord, double>> estimate_brick_bytes(
    const std::vector<VoxelKey>& cells, int brick_level, const IntegrateOptions& options,
    const std::vector<std::pair<BrickCoord, std::size_t>>& existing, const std::vector<std::uint64_t>& touched) {
  // A live voxel cost about 35 bytes with its share of its block (16-byte voxels, 4^3 blocks about
  // half full) and of the block index. The tents leave the ramps' ends empty and blocks are
  // shared: measured fields are about 0.3 of this count. Together the estimate was 1.25x the city
  // block's field, 1.36x igea's and 0.9x the bunny scans' (bench/README.md, session 30): tight
  // enough that tiles use the budget, since every extra tile re-reads the depth maps reaching it.
  // Since session 41 the table keeps 2^3 blocks, and fields take 0.72x (igea) to 0.86x (city
  // eighth) the bytes: the estimate is looser, on the side of the budget (at 25 bytes the city
  // eighth's plan did not change, session 40), and is kept until a recalibration over all three.
  constexpr double kBytesPerLiveVoxel = 35.0, kMeasuredShare = 0.3;
  const double bytes_per_cell =
      kMeasuredShare * 8.0 * 8.0 * 1.5 * ((1.0 + options.behind) * options.gamma) * kBytesPerLiveVoxel;
  std::map<std::uint64_t, std::pair<BrickCoord, double>> by_brick;
  for (VoxelKey k : cells) {
    const BrickCoord c = brick_of(k, brick_level);
    auto& e = by_brick[c.packed()];
    e.first = c;
    e.second += bytes_per_cell;
  }
  for (const auto& [c, bytes] : existing) {
    auto& e = by_brick[c.packed()];
    e.first = c;
    e.second += double(bytes);
  }
  for (std::uint64_t id : touched) {
    auto& e = by_brick[id];
    e.first = BrickCoord::unpack(id);
  }
  std::vector<std::pair<BrickCoord, double>> out;
  out.reserve(by_brick.size());
  for (const auto& [id, e] : by_brick) out.push_back(e);
  return out;
}

namespace {

std::uint32_t& at(BrickCoord& c, int axis) { return axis == 0 ? c.x : axis == 1 ? c.y : c.z; }
std::uint32_t at(const BrickCoord& c, int axis) { return axis == 0 ? c.x : axis == 1 ? c.y : c.z; }

void bisect(BrickBox box, std::vector<std::pair<BrickCoord, double>>::iterator first,
            std::vector<std::pair<BrickCoord, double>>::iterator last, double target, std::vector<BrickBox>& out) {
  if (first == last) return;  // nothing to integrate here
  const double total = std::accumulate(first, last, 0.0, [](double s, const auto& e) { return s + e.second; });
  // The occupied extent per axis; split the longest (ties: x, y, z).
  std::uint32_t lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = at(first->first, a);
    hi[a] = lo[a];
  }
  for (auto it = first; it != last; ++it)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], at(it->first, a));
      hi[a] = std::max(hi[a], at(it->first, a));
    }
  int axis = 0;
  for (int a = 1; a < 3; ++a)
    if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
  if (total <= target || hi[axis] == lo[axis]) {
    out.push_back(box);
    return;
  }
  std::sort(first, last, [axis](const auto& a, const auto& b) {
    return at(a.first, axis) != at(b.first, axis) ? at(a.first, axis) < at(b.first, axis)
                                                   : a.first.packed() < b.first.packed();
  });
  // The weighted median: the first coordinate with at least half the total before it, and at least
  // one brick on each side.
  std::uint32_t split = hi[axis];
  double before = 0;
  for (auto it = first; it != last; ++it) {
    const std::uint32_t c = at(it->first, axis);
    if (c > lo[axis] && before >= total / 2) {
      split = c;
      break;
    }
    before += it->second;
  }
  auto mid = std::partition_point(first, last, [&](const auto& e) { return at(e.first, axis) < split; });
  BrickBox left = box, right = box;
  at(left.hi, axis) = split;
  at(right.lo, axis) = split;
  bisect(left, first, mid, target, out);
  bisect(right, mid, last, target, out);
}


// Splits `box` holding [first, last) into n boxes (see split_tiles).
void split(BrickBox box, std::vector<std::pair<BrickCoord, double>>::iterator first,
           std::vector<std::pair<BrickCoord, double>>::iterator last, std::size_t n, std::vector<BrickBox>& out) {
  const auto empty_boxes = [&](std::size_t count) {
    for (std::size_t i = 0; i < count; ++i) out.push_back({box.lo, box.lo});
  };
  if (n == 1 || first == last) {
    if (n == 0) return;
    out.push_back(box);
    empty_boxes(n - 1);
    return;
  }
  std::uint32_t lo[3], hi[3];
  for (int a = 0; a < 3; ++a) lo[a] = hi[a] = at(first->first, a);
  for (auto it = first; it != last; ++it)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], at(it->first, a));
      hi[a] = std::max(hi[a], at(it->first, a));
    }
  const std::size_t n_left = n / 2;
  const double total = std::accumulate(first, last, 0.0, [](double s, const auto& e) { return s + e.second; });
  const double share = total * double(n_left) / double(n);
  // Per axis, the cut between occupied coordinates whose work on the left is closest to the share
  // (ties: the first), with a brick on each side.
  const auto best_cut = [&](int axis, std::uint32_t* cut) {
    std::sort(first, last, [axis](const auto& a, const auto& b) {
      return at(a.first, axis) != at(b.first, axis) ? at(a.first, axis) < at(b.first, axis)
                                                     : a.first.packed() < b.first.packed();
    });
    double best = std::numeric_limits<double>::infinity(), before = 0;
    for (auto it = first; it != last;) {
      const std::uint32_t c = at(it->first, axis);
      if (c > lo[axis] && std::abs(before - share) < best) {
        best = std::abs(before - share);
        *cut = c;
      }
      for (; it != last && at(it->first, axis) == c; ++it) before += it->second;
    }
    return best;
  };
  // The longest axis (compact tiles: less surface, less halo), unless another balances the work
  // clearly better (by more than 2 % of it).
  int order[3] = {0, 1, 2};
  std::stable_sort(order, order + 3, [&](int a, int b) { return hi[a] - lo[a] > hi[b] - lo[b]; });
  if (hi[order[0]] == lo[order[0]]) {  // one occupied brick: it cannot be shared
    out.push_back(box);
    empty_boxes(n - 1);
    return;
  }
  double error[3];
  std::uint32_t cut[3] = {0, 0, 0};
  double least = std::numeric_limits<double>::infinity();
  for (int a : order) {
    error[a] = hi[a] > lo[a] ? best_cut(a, &cut[a]) : std::numeric_limits<double>::infinity();
    least = std::min(least, error[a]);
  }
  int axis = order[0];
  for (int a : order)
    if (error[a] <= least + 0.02 * total) {
      axis = a;
      break;
    }
  const std::uint32_t split_at = cut[axis];
  best_cut(axis, &cut[axis]);  // leaves [first, last) sorted along the axis
  auto mid = std::partition_point(first, last, [&](const auto& e) { return at(e.first, axis) < split_at; });
  BrickBox left = box, right = box;
  at(left.hi, axis) = split_at;
  at(right.lo, axis) = split_at;
  split(left, first, mid, n_left, out);
  split(right, mid, last, n - n_left, out);
}

}  // namespace

std::vector<BrickBox> cut_tiles(std::vector<std::pair<BrickCoord, double>> bricks, int brick_level, double target,
                                const BrickBox* within) {
  std::vector<BrickBox> out;
  bisect(within ? *within : BrickBox::whole(brick_level), bricks.begin(), bricks.end(), target, out);
  return out;
}

std::vector<BrickBox> split_tiles(std::vector<std::pair<BrickCoord, double>> bricks, int brick_level, std::size_t n) {
  if (n == 0) throw std::invalid_argument("split_tiles: at least one tile");
  std::vector<BrickBox> out;
  split(BrickBox::whole(brick_level), bricks.begin(), bricks.end(), n, out);
  return out;
}

bool empty_box(const BrickBox& b) { return !(b.lo.x < b.hi.x && b.lo.y < b.hi.y && b.lo.z < b.hi.z); }

std::size_t tile_of(const std::vector<BrickBox>& tiles, BrickCoord c) {
  for (std::size_t t = 0; t < tiles.size(); ++t)
    if (tiles[t].contains(c)) return t;
  return tiles.size();
}

}  // namespace sf
