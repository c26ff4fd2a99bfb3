#include "engine/regularize.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "engine/error.h"
#include "engine/hsdf_math.h"

namespace sf {

void RegularizeOptions::check() const {
  if (!(tau0 >= 0)) throw InputError("regularize.tau0 must be >= 0");
  if (!(tau1 >= 0 && tau1 <= tau0)) throw InputError("regularize.tau1 must satisfy 0 <= tau1 <= tau0");
}

namespace {

using VoxelRef = std::pair<VoxelKey, VoxelData*>;
using Levels = std::vector<std::vector<VoxelRef>>;  // [level] -> voxels

// The one interpolation rule; find(key) gives the live voxel or null.
template <class Find>
bool interpolate(Find&& find, VoxelKey key, CoarseSample* out) {
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
        const VoxelData* v = find(VoxelKey::make(l - 1, lo[0] + dx, lo[1] + dy, lo[2] + dz));
        if (!v) return false;
        s.distance += share * v->distance;
        s.weight += share * v->weight;
        s.colour_weight += share * v->colour_weight();
        for (int k = 0; k < 3; ++k) s.colour[k] += share * v->colour(k);
      }
  *out = s;
  return true;
}

struct PhaseCounts {
  std::atomic<std::size_t> blended{0}, deleted_unconfident{0}, deleted_duplicates{0};
};

// Phase 1 (equations 4-5 and τ1) on the voxels of one level. Reads only the level below, which is
// final, so the result does not depend on scheduling. counted(key): whether the voxel counts in
// the statistics (a brick's window holds copies of its neighbours' voxels).
template <class Find, class Counted>
void blend_level(std::vector<VoxelRef>& vox, Find&& find, const RegularizeOptions& options, Counted&& counted,
                 PhaseCounts& counts) {
  const double tau0 = options.tau0, tau1 = options.tau1;
  tbb::parallel_for(std::size_t(0), vox.size(), [&](std::size_t i) {
    const VoxelKey key = vox[i].first;
    VoxelData& v = *vox[i].second;
    if (v.weight >= tau0) return;
    CoarseSample c;
    if (interpolate(find, key, &c) && c.weight > 0) {
      const DistanceWeight b = regularize_blend({v.distance, v.weight}, {c.distance, c.weight}, tau0);
      const double k = b.weight - v.weight;  // the coarse level's share
      float colour[3] = {v.colour(0), v.colour(1), v.colour(2)};
      double cw = v.colour_weight();
      if (k > 0 && c.colour_weight > 0) {
        for (int ch = 0; ch < 3; ++ch) colour[ch] = float((colour[ch] * cw + c.colour[ch] * k) / (cw + k));
        cw += k;
      }
      v.distance = float(b.distance);
      v.weight = float(b.weight);
      v.set_colour(colour, cw);  // the share of the new weight
      if (counted(key)) counts.blended.fetch_add(1, std::memory_order_relaxed);
    }
    if (v.weight < tau1) {
      v.weight = -1;  // erased
      if (counted(key)) counts.deleted_unconfident.fetch_add(1, std::memory_order_relaxed);
    }
  });
}

// Phase 2 on the voxels of one level: erased if any finer level holds a live voxel at the same
// position. Finer levels are done first.
template <class Find>
void remove_duplicates_level(std::vector<VoxelRef>& vox, Find&& find, PhaseCounts& counts) {
  tbb::parallel_for(std::size_t(0), vox.size(), [&](std::size_t i) {
    VoxelData& v = *vox[i].second;
    if (v.erased()) return;
    VoxelKey k = vox[i].first;
    for (int f = k.level() + 1; f <= kMaxLevel; ++f) {
      k = k.finer();
      if (find(k)) {
        v.weight = -1;
        counts.deleted_duplicates.fetch_add(1, std::memory_order_relaxed);
        return;
      }
    }
  });
}

Levels live_by_level(VoxelTable& t) {
  Levels levels(kMaxLevel + 1);
  t.for_each([&](VoxelKey k, VoxelData& v) { levels[std::size_t(k.level())].push_back({k, &v}); });
  return levels;
}

}  // namespace

bool interpolate_coarser(const BrickMap& map, VoxelKey key, CoarseSample* out) {
  return interpolate([&](VoxelKey k) { return map.find(k); }, key, out);
}

RegularizeStats regularize(BrickMap& map, const RegularizeOptions& options, const ProgressFn& progress) {
  RegularizeStats stats;
  // Voxels by level (pointers stay valid: no insertion happens during regularization).
  Levels levels(kMaxLevel + 1);
  for (Brick* b : map.bricks())
    b->voxels.for_each([&](VoxelKey k, VoxelData& v) { levels[k.level()].push_back({k, &v}); });
  for (int l = 0; l <= kMaxLevel; ++l) stats.voxels_before[l] = levels[l].size();

  const auto find = [&](VoxelKey k) { return map.find(k); };
  const auto all = [](VoxelKey) { return true; };
  PhaseCounts counts;
  for (int l = 0; l <= kMaxLevel; ++l) {
    blend_level(levels[l], find, options, all, counts);
    report(progress, "regularize", l + 1, 2 * (kMaxLevel + 1));
  }
  for (int l = kMaxLevel - 1; l >= 0; --l) {
    remove_duplicates_level(levels[l], find, counts);
    report(progress, "regularize", 2 * (kMaxLevel + 1) - l, 2 * (kMaxLevel + 1));
  }
  stats.blended = counts.blended;
  stats.deleted_unconfident = counts.deleted_unconfident;
  stats.deleted_duplicates = counts.deleted_duplicates;
  map.compact();
  for (Brick* b : map.bricks())
    b->voxels.for_each([&](VoxelKey k, const VoxelData&) { ++stats.voxels_after[k.level()]; });
  return stats;
}

// Brick by brick. Let B be the brick level. A voxel of level l > B interpolates level l-1 at most
// one level-l cell away per axis, so its whole chain of coarser dependencies down to level j > B
// reaches less than h_{j+1} + ... + h_l < h_j. Level-j positions lie on the h_j grid and brick
// faces on the coarser h_B grid: every voxel of level > B that the chain of a voxel of brick X
// touches lies in X's closed box, i.e. in X or on the lower faces of its 7 upper neighbours. Levels
// <= B sit on brick corners and are regularized first, all together (they are few).
void regularize_boundary(const BrickMap& map, const BoundarySink& sink) {
  const int B = map.brick_level();
  const std::vector<Brick*> bricks = map.bricks();
  std::mutex sink_mutex;
  tbb::parallel_for(std::size_t(0), bricks.size(), [&](std::size_t i) {
    VoxelTable scratch(B);
    const VoxelTable& t = map.field_of(*bricks[i], scratch);
    std::vector<RawVoxel> low, faces;
    t.for_each([&](VoxelKey k, const VoxelData& v) {
      const int l = k.level();
      if (l <= B) {
        low.push_back({k, v});
        return;
      }
      const std::uint32_t m = (1u << (l - B)) - 1;
      if ((k.x() & m) == 0 || (k.y() & m) == 0 || (k.z() & m) == 0) faces.push_back({k, v});
    });
    std::lock_guard lock(sink_mutex);
    sink(bricks[i]->coord, std::move(low), std::move(faces));
  });
}

RegularizeStats regularize_bricks(BrickMap& map, const RegularizeOptions& options, const ProgressFn& progress,
                                  const BrickSink& sink, const std::function<bool(BrickCoord)>& skip,
                                  const RegularizeBoundary* boundary) {
  const int B = map.brick_level();
  const std::vector<Brick*> bricks = map.bricks();
  RegularizeStats stats;
  std::mutex stats_mutex;  // also serializes the sink and progress

  // Pass 1: the voxels of levels <= B, and each brick's lower-face voxels of finer levels, raw
  // (read here, or given).
  VoxelTable coarse(B);
  std::unordered_map<std::uint64_t, std::vector<RawVoxel>> faces;  // packed brick -> its face voxels
  if (boundary) {
    for (const RawVoxel& r : boundary->coarse) coarse.find_or_insert(r.key) = r.data;
  } else {
    regularize_boundary(map, [&](BrickCoord c, std::vector<RawVoxel>&& low, std::vector<RawVoxel>&& f) {
      for (const RawVoxel& r : low) coarse.find_or_insert(r.key) = r.data;
      if (!f.empty()) faces[c.packed()] = std::move(f);
    });
  }
  const auto visit_faces = [&](BrickCoord N, const std::function<void(const RawVoxel&)>& fn) {
    if (boundary) return boundary->faces(N, fn);
    const auto it = faces.find(N.packed());
    if (it != faces.end())
      for (const RawVoxel& r : it->second) fn(r);
  };
  report(progress, "regularize", 1, double(bricks.size()) + 2);

  PhaseCounts coarse_counts;
  {
    const auto find = [&](VoxelKey k) {
      const VoxelData* v = coarse.find(k);
      return v && v->live() ? v : nullptr;
    };
    Levels levels = live_by_level(coarse);
    for (int l = 0; l <= B; ++l) blend_level(levels[l], find, options, [](VoxelKey) { return true; }, coarse_counts);
  }
  report(progress, "regularize", 2, double(bricks.size()) + 2);

  // Pass 2: each brick in its window: its own voxels, the final coarse voxels at its corners and
  // its upper neighbours' raw face voxels in its closed box; phase 1 above level B, phase 2, emit.
  PhaseCounts counts;
  std::size_t done = 0;
  tbb::parallel_for(std::size_t(0), bricks.size(), [&](std::size_t i) {
    const BrickCoord X = bricks[i]->coord;
    if (skip && skip(X)) {
      std::lock_guard lock(stats_mutex);
      report(progress, "regularize", double(++done + 2), double(bricks.size()) + 2);
      return;
    }
    VoxelTable window = map.take_field(*bricks[i]);
    std::size_t before[kMaxLevel + 1] = {}, after[kMaxLevel + 1] = {};
    window.for_each([&](VoxelKey k, VoxelData& v) {
      ++before[k.level()];
      if (k.level() <= B) v = VoxelData{};  // replaced by its final value below
    });
    const std::uint32_t xc[3] = {X.x, X.y, X.z};
    for (int corner = 0; corner < 8; ++corner)
      for (int j = 0; j <= B; ++j) {
        std::uint32_t c[3];
        bool on_grid = true;
        for (int a = 0; a < 3; ++a) {
          const std::uint32_t b = xc[a] + ((corner >> a) & 1);
          on_grid = on_grid && (b & ((1u << (B - j)) - 1)) == 0;
          c[a] = b >> (B - j);
        }
        if (!on_grid) continue;
        const VoxelKey k = VoxelKey::make(j, c[0], c[1], c[2]);
        const VoxelData* v = coarse.find(k);
        if (v && v->live()) window.find_or_insert(k) = *v;
      }
    const std::uint32_t last = (1u << B) - 1;
    for (int d = 1; d < 8; ++d) {
      if (((d & 1) && X.x == last) || ((d & 2) && X.y == last) || ((d & 4) && X.z == last)) continue;
      const BrickCoord N{X.x + (d & 1), X.y + ((d >> 1) & 1), X.z + ((d >> 2) & 1)};
      visit_faces(N, [&](const RawVoxel& r) {
        const VoxelKey k = r.key;
        const std::uint32_t m = (1u << (k.level() - B)) - 1;
        if ((d & 1) && (k.x() & m)) return;
        if ((d & 2) && (k.y() & m)) return;
        if ((d & 4) && (k.z() & m)) return;
        window.find_or_insert(k) = r.data;
      });
    }
    const auto find = [&](VoxelKey k) {
      const VoxelData* v = window.find(k);
      return v && v->live() ? v : nullptr;
    };
    const auto own = [&](VoxelKey k) { return brick_of(k, B).packed() == X.packed(); };
    Levels levels = live_by_level(window);
    for (int l = B + 1; l <= kMaxLevel; ++l) blend_level(levels[l], find, options, own, counts);
    for (int l = kMaxLevel - 1; l >= 0; --l) {
      std::erase_if(levels[l], [&](const VoxelRef& r) { return !own(r.first); });
      remove_duplicates_level(levels[l], find, counts);
    }
    std::vector<std::pair<VoxelKey, VoxelData>> out;
    for (int l = 0; l <= kMaxLevel; ++l)
      for (const VoxelRef& r : levels[l])
        if (r.second->live() && own(r.first)) {
          out.push_back({r.first, *r.second});
          ++after[l];
        }
    std::lock_guard lock(stats_mutex);
    for (int l = 0; l <= kMaxLevel; ++l) {
      stats.voxels_before[l] += before[l];
      stats.voxels_after[l] += after[l];
    }
    sink(X, std::move(out));
    report(progress, "regularize", double(++done + 2), double(bricks.size()) + 2);
  });
  stats.blended = coarse_counts.blended + counts.blended;
  stats.deleted_unconfident = coarse_counts.deleted_unconfident + counts.deleted_unconfident;
  stats.deleted_duplicates = counts.deleted_duplicates;
  return stats;
}

}  // namespace sf
