#pragma once
// Section 6: regularizing the hSDF.
//  1. Coarse to fine: a voxel with weight w < tau0 is blended with the coarser level's field
//     interpolated at its position (equations 4-5), if every coarser voxel the interpolation needs
//     (1, 2, 4 or 8, by the parity of its coordinates) exists. The coarser level has already been
//     regularized and pruned. A voxel whose (blended) weight stays below tau1 is deleted.
//  2. Fine to coarse: at every position only the finest surviving voxel is kept.
#include <cstddef>
#include <functional>
#include <utility>
#include <vector>

#include "engine/progress.h"
#include "storage/brick_map.h"
#include "storage/voxel_key.h"

namespace sf {

struct RegularizeOptions {
  double tau0 = 0.5;  // saturation threshold τ0 (weight units); 0 disables blending
  double tau1 = 0.1;  // confidence threshold τ1 <= τ0: weaker voxels are deleted
  void check() const;
};

struct RegularizeStats {
  std::size_t blended = 0;            // voxels updated by equations 4-5
  std::size_t deleted_unconfident = 0;
  std::size_t deleted_duplicates = 0; // coarser voxels coinciding with a finer one
  std::size_t voxels_before[kMaxLevel + 1] = {};
  std::size_t voxels_after[kMaxLevel + 1] = {};
};

// Regularizes `map` in place (erased voxels are compacted away). Parallel in the calling arena;
// deterministic.
RegularizeStats regularize(BrickMap& map, const RegularizeOptions& options, const ProgressFn& progress);

// The regularized voxels of one brick, in level then storage order.
using BrickSink = std::function<void(BrickCoord brick, std::vector<std::pair<VoxelKey, VoxelData>>&& voxels)>;

// The same result voxel for voxel, brick by brick within a small window, so that the field never
// has to be in memory at once: each brick's field is read twice (once for its face voxels and
// levels <= the brick level, once to regularize it) and handed to `sink` (called one brick at a
// time, in no fixed order). Resident bricks are moved out of `map`, spilled ones read from their
// tiles (which stay). Parallel in the calling arena. Bricks `skip` accepts are not handed to the
// sink (a resumed job has them already) and are left out of the stats.
//
// The two reads can run in different processes (a cluster's tiles, engine/cluster_stage.h): the
// first, regularize_boundary, gives each brick's raw voxels that other bricks' regularization
// needs; regularize_bricks then takes everyone's (`boundary`) instead of reading them itself.
struct RawVoxel {
  VoxelKey key;
  VoxelData data;
};
struct RegularizeBoundary {
  std::vector<RawVoxel> coarse;  // every brick's voxels of levels <= the brick level
  // Visits the lower-face voxels (of levels > the brick level) of a brick (none if it is absent).
  std::function<void(BrickCoord, const std::function<void(const RawVoxel&)>&)> faces;
};
RegularizeStats regularize_bricks(BrickMap& map, const RegularizeOptions& options, const ProgressFn& progress,
                                  const BrickSink& sink, const std::function<bool(BrickCoord)>& skip = nullptr,
                                  const RegularizeBoundary* boundary = nullptr);

// Each brick of `map` (read, not changed; in parallel): its voxels of levels <= the brick level
// and its raw lower-face voxels of finer levels (a local coordinate 0 on some axis), to `sink`
// (called one brick at a time, in no fixed order).
using BoundarySink = std::function<void(BrickCoord brick, std::vector<RawVoxel>&& coarse, std::vector<RawVoxel>&& faces)>;
void regularize_boundary(const BrickMap& map, const BoundarySink& sink);

// Interpolates (distance, weight, colour) of the coarser level at voxel `key`'s position; false if a
// required coarser voxel is missing. Exposed for tests.
struct CoarseSample {
  double distance = 0, weight = 0;
  double colour[3] = {0, 0, 0};
  double colour_weight = 0;
};
bool interpolate_coarser(const BrickMap& map, VoxelKey key, CoarseSample* out);

}  // namespace sf
