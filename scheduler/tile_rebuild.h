#pragma once
// Rebuilding a damaged tile of a job's checkpoint (issue 6). A brick's field after the job's
// integrated depth maps is a pure function of those depth maps in the job's order (a cluster tile
// relies on the same property), so the brick is recomputed by integrating them into that brick
// alone, in a throw-away job inside the job directory, and its tile replaces the damaged one.
#include <cstddef>
#include <vector>

#include "engine/fusion.h"
#include "scheduler/job.h"
#include "storage/tile_store.h"

namespace sf {

struct TileRebuild {
  std::size_t depth_maps = 0;  // depth maps re-integrated
  double seconds = 0;
};

// Rebuilds the brick `damage` names into `job`'s checkpoint. `frames` is the job's list of depth
// maps when it has one (a cluster tile's), else every depth map of `source` in order. Runs in the
// caller's TBB arena. Throws InputError when the journal does not allow it (a brick of the tile
// under way in a sweep of tiles: Job::depth_maps_in_brick).
TileRebuild rebuild_tile(Job& job, const DamagedTile& damage, const FrameSource& source, const FusionOptions& options,
                         const std::vector<std::size_t>* frames);

}  // namespace sf
