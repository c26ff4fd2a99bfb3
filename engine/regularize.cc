#include "engine/regularize.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <vector>

#include "engine/error.h"
#include "engine/hsdf_math.h"

namespace sf {

void RegularizeOptions::check() const {
  if (!(tau0 >= 0)) throw InputError("regularize.tau0 must be >= 0");
  if (!(tau1 >= 0 && tau1 <= tau0)) throw InputError("regularize.tau1 must satisfy 0 <= tau1 <= tau0");
}

bool interpolate_coarser(const BrickMap& map, VoxelKey key, CoarseSample* out) {
  const int l = key.level();
  if (l == 0) return false;
  // Per axis: an even coordinate coincides with one coarser voxel, an odd one lies halfway
  // between two.
  std::uint32_t lo[3], cnt[3];
  const std::uint32_t c[3] = {key.x(), key.y(), key.z()};
  for (int a = 0; a < 3; ++a) {
    lo[a] = c[a] / 2;
    cnt[a] = (c[a] & 1u) ? 2 : 1;
  }
  CoarseSample s;
  const double share = 1.0 / double(cnt[0] * cnt[1] * cnt[2]);
  for (std::uint32_t dz = 0; dz < cnt[2]; ++dz)
    for (std::uint32_t dy = 0; dy < cnt[1]; ++dy)
      for (std::uint32_t dx = 0; dx < cnt[0]; ++dx) {
        const VoxelData* v = map.find(VoxelKey::make(l - 1, lo[0] + dx, lo[1] + dy, lo[2] + dz));
        if (!v) return false;
        s.distance += share * v->distance;
        s.weight += share * v->weight;
        s.colour_weight += share * v->colour_weight;
        for (int k = 0; k < 3; ++k) s.colour[k] += share * v->colour[k];
      }
  *out = s;
  return true;
}

RegularizeStats regularize(BrickMap& map, const RegularizeOptions& options, const ProgressFn& progress) {
  RegularizeStats stats;
  // Voxels by level (pointers stay valid: no insertion happens during regularization).
  std::vector<std::vector<std::pair<VoxelKey, VoxelData*>>> levels(kMaxLevel + 1);
  for (Brick* b : map.bricks())
    b->voxels.for_each([&](VoxelKey k, VoxelData& v) { levels[k.level()].push_back({k, &v}); });
  for (int l = 0; l <= kMaxLevel; ++l) stats.voxels_before[l] = levels[l].size();

  const double tau0 = options.tau0, tau1 = options.tau1;
  std::atomic<std::size_t> blended{0}, deleted{0};
  for (int l = 0; l <= kMaxLevel; ++l) {
    auto& vox = levels[l];
    tbb::parallel_for(std::size_t(0), vox.size(), [&](std::size_t i) {
      const VoxelKey key = vox[i].first;
      VoxelData& v = *vox[i].second;
      if (v.weight >= tau0) return;
      CoarseSample c;
      // Reads only level l-1, which is final: the result does not depend on scheduling.
      if (interpolate_coarser(map, key, &c) && c.weight > 0) {
        const DistanceWeight b = regularize_blend({v.distance, v.weight}, {c.distance, c.weight}, tau0);
        const double k = b.weight - v.weight;  // the coarse level's share
        if (k > 0 && c.colour_weight > 0) {
          const double cw = v.colour_weight + k;
          for (int ch = 0; ch < 3; ++ch) v.colour[ch] = float((v.colour[ch] * v.colour_weight + c.colour[ch] * k) / cw);
          v.colour_weight = float(cw);
        }
        v.distance = float(b.distance);
        v.weight = float(b.weight);
        blended.fetch_add(1, std::memory_order_relaxed);
      }
      if (v.weight < tau1) {
        v.weight = -1;  // erased
        deleted.fetch_add(1, std::memory_order_relaxed);
      }
    });
    report(progress, "regularize", l + 1, 2 * (kMaxLevel + 1));
  }
  stats.blended = blended;
  stats.deleted_unconfident = deleted;

  // Fine to coarse: drop a voxel if any finer level holds a live voxel at its position.
  std::atomic<std::size_t> dups{0};
  for (int l = kMaxLevel - 1; l >= 0; --l) {
    auto& vox = levels[l];
    tbb::parallel_for(std::size_t(0), vox.size(), [&](std::size_t i) {
      VoxelData& v = *vox[i].second;
      if (v.erased()) return;
      VoxelKey k = vox[i].first;
      for (int f = l + 1; f <= kMaxLevel; ++f) {
        k = k.finer();
        if (levels[f].empty()) continue;
        if (map.find(k)) {
          v.weight = -1;
          dups.fetch_add(1, std::memory_order_relaxed);
          return;
        }
      }
    });
    report(progress, "regularize", 2 * (kMaxLevel + 1) - l, 2 * (kMaxLevel + 1));
  }
  stats.deleted_duplicates = dups;
  map.compact();
  for (Brick* b : map.bricks())
    b->voxels.for_each([&](VoxelKey k, const VoxelData&) { ++stats.voxels_after[k.level()]; });
  return stats;
}

}  // namespace sf
