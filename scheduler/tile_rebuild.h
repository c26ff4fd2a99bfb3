#pragma once
// Rebuilding damaged tiles of a job's checkpoint (issue 6). A brick's field after the job's
// integrated depth maps is a pure function of those depth maps in the job's order (a cluster tile
// relies on the same property), so a brick is recomputed by integrating them into that brick
// alone, in a throw-away job inside the job directory, and its tile replaces the damaged one.
#include <cstddef>
#include <vector>

#include "engine/fusion.h"
#include "scheduler/job.h"
#include "storage/tile_store.h"

namespace sf {

struct TileRebuild {
  std::vector<std::size_t> depth_maps;  // per damaged tile, the depth maps re-integrated into its brick
  std::size_t passes = 0;               // passes over the depth maps
  std::vector<std::size_t> reaching;    // per damaged tile, those of them read: the ones reaching its pass's region
  double seconds = 0;
};

// Rebuilds the bricks `damage` names into `job`'s checkpoint. Reading and triangulating the depth
// maps is most of a rebuild's cost, so only those whose recorded reach meets the bricks are read
// (Job::depth_maps_reaching), and bricks that hold the same depth maps share one pass, whose
// region is their bounding box of bricks (at most the whole field: one integration). `frames` is
// the job's list of depth maps when it has one (a cluster tile's), else every depth map of
// `source` in order. Runs in the caller's TBB arena. Throws InputError, before changing anything,
// when the journal does not allow it for one of them (a brick of the tile under way in a sweep of
// tiles: Job::depth_maps_in_brick).
TileRebuild rebuild_tiles(Job& job, const std::vector<DamagedTile>& damage, const FrameSource& source,
                          const FusionOptions& options, const std::vector<std::size_t>* frames);

}  // namespace sf
