#include "scheduler/tile_rebuild.h"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <map>
#include <optional>
#include <string>

#include "engine/error.h"

namespace sf {

TileRebuild rebuild_tiles(Job& job, const std::vector<DamagedTile>& damage, const FrameSource& source,
                          const FusionOptions& options, const std::vector<std::size_t>* frames) {
  const auto start = std::chrono::steady_clock::now();
  TileRebuild r;
  // Bricks by the number of the job's first depth maps they hold; all checked before any rebuild.
  std::map<std::size_t, std::vector<BrickCoord>> passes;
  for (const DamagedTile& d : damage) {
    const std::optional<std::size_t> held = job.depth_maps_in_brick(d.coord);
    if (!held)
      throw InputError(std::string(d.what()) +
                       "; it cannot be rebuilt: its brick is in the tile of the sweep under way, and the journal does "
                       "not record which depth maps that tile took; remove the job folder and run again");
    const std::size_t limit = frames ? frames->size() : source.size();
    if (*held > limit)
      throw InputError(job.dir().string() + ": job journal: more depth maps integrated than " +
                       (frames ? "listed" : "the input has"));
    passes[*held].push_back(d.coord);
    r.depth_maps.push_back(*held);
  }
  const std::filesystem::path dir = job.dir() / "rebuild";
  r.reaching.assign(damage.size(), 0);
  const std::size_t step = std::size_t(options.input.frame_step);
  for (const auto& [n, bricks] : passes) {
    BrickBox region;
    for (const BrickCoord& c : bricks) region.extend(c);
    // The depth maps that can write into the region, in the job's order (those that cannot would
    // change nothing there), as source indices: the job's list, or every step-th depth map.
    std::vector<std::size_t> list = job.depth_maps_reaching(region, n);
    for (std::size_t& i : list) i = frames ? (*frames)[i] : i * step;
    for (std::size_t i = 0; i < damage.size(); ++i)
      if (r.depth_maps[i] == n) r.reaching[i] = list.size();
    std::filesystem::remove_all(dir);
    {
      JobOptions o;
      o.dir = dir;
      o.root = job.fixed_root();
      o.brick_level = job.fixed_brick_level();
      o.memory_limit = job.memory_limit();
      o.checkpoint_every = std::size_t(-1);
      o.checkpoint_seconds = 1e30;
      Job rebuild(o, "", "", "");
      FusionHooks hooks;
      hooks.frames = &list;
      hooks.region = &region;
      hooks.stop_after_integration = true;
      hooks.count_fused_voxels = false;
      FusionStats stats;
      fuse(source, options, hooks, &stats, &rebuild);
      const Job::Field field = Job::field(dir);
      for (const BrickCoord& c : bricks) job.replace_tile(field, c);
    }
    std::filesystem::remove_all(dir);
    ++r.passes;
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return r;
}

}  // namespace sf
