#include "scheduler/tile_rebuild.h"

#include <chrono>
#include <filesystem>
#include <numeric>
#include <optional>
#include <string>

#include "engine/error.h"

namespace sf {

TileRebuild rebuild_tile(Job& job, const DamagedTile& damage, const FrameSource& source, const FusionOptions& options,
                         const std::vector<std::size_t>* frames) {
  const auto start = std::chrono::steady_clock::now();
  const std::optional<std::size_t> held = job.depth_maps_in_brick(damage.coord);
  if (!held)
    throw InputError(std::string(damage.what()) +
                     "; it cannot be rebuilt: its brick is in the tile of the sweep under way, and the journal does "
                     "not record which depth maps that tile took; remove the job folder and run again");
  const std::size_t n = *held;
  std::vector<std::size_t> list(n);
  if (frames) {
    if (n > frames->size()) throw InputError(job.dir().string() + ": job journal: more depth maps integrated than listed");
    list.assign(frames->begin(), frames->begin() + std::ptrdiff_t(n));
  } else {
    if (n > source.size()) throw InputError(job.dir().string() + ": job journal: more depth maps integrated than the input has");
    std::iota(list.begin(), list.end(), std::size_t{0});
  }
  const std::filesystem::path dir = job.dir() / "rebuild";
  std::filesystem::remove_all(dir);
  {
    JobOptions o;
    o.dir = dir;
    o.root = job.fixed_root();
    o.brick_level = job.fixed_brick_level();
    o.checkpoint_every = std::size_t(-1);
    o.checkpoint_seconds = 1e30;
    Job rebuild(o, "", "", "");
    const BrickBox region{damage.coord, {damage.coord.x + 1, damage.coord.y + 1, damage.coord.z + 1}};
    FusionHooks hooks;
    hooks.frames = &list;
    hooks.region = &region;
    hooks.stop_after_integration = true;
    hooks.count_fused_voxels = false;
    FusionStats stats;
    fuse(source, options, hooks, &stats, &rebuild);
    job.replace_tile(Job::field(dir), damage.coord);
  }
  std::filesystem::remove_all(dir);
  TileRebuild r;
  r.depth_maps = n;
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return r;
}

}  // namespace sf
