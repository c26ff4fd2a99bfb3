#pragma once
// A cluster tile's stages after its integration (docs/cluster.md): regularization and the brick
// extraction's passes run on the tiles as well, each tile over its own bricks, one process per
// stage with the cluster engine's barrier between stages (a Slurm array per stage with afterok,
// or MPI rank 0 starting a stage once every tile has finished the one before). The merge then
// only writes the mesh.
//
//   integrate        scalefuse run-tile (the tile's depth maps into its bricks), then its
//                    boundary: each brick's voxels of levels <= the brick level and its raw
//                    lower-face voxels (regularize_boundary), which neighbouring bricks of other
//                    tiles need  -> DIR/cluster/tile-K/boundary/
//   regularize       section 6 for the tile's bricks, with every tile's boundary; the survivors
//                    go to the extraction's mailboxes   -> DIR/cluster/tile-K/exchange/
//   prepare ... sort the brick extraction's passes over the tile's bricks (BrickExtraction with an
//                    ExtractShare)
//   (merge)          the last pass, "write": components and the stream of the mesh, on one node
//
// Each stage of a tile is resumable (the tile's job journal records the bricks it finished) and a
// finished stage is a no-op. The exchange files are the single-machine run's mailboxes split by
// the tile that posted them, so the mesh is byte-identical to a single-machine run's.
#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

#include "engine/fusion.h"
#include "engine/mesh.h"
#include "engine/progress.h"
#include "scheduler/cluster.h"

namespace sf {

// "integrate", "regularize", "prepare", ..., "sort": what run-tile --stage takes, in order.
const std::vector<std::string>& tile_stages();

// Tile K's folders.
std::filesystem::path tile_boundary_dir(const std::filesystem::path& job_dir, std::size_t tile);
std::filesystem::path tile_exchange_dir(const std::filesystem::path& job_dir, std::size_t tile);

struct TileStageContext {
  std::filesystem::path job_dir;  // the plan's
  ClusterPlan plan;
  FusionOptions options;          // the job's (DIR/config.toml)
  std::size_t memory_limit = std::size_t{1} << 30;  // bytes for bricks and windows
  double checkpoint_seconds = 300;  // a stage commits the bricks it finished at least every 30 s, or this
  std::size_t kill_in_extraction = 0;  // testing aid (JobOptions::kill_in_extraction)
  ProgressFn progress;
};

// Whether tile K has finished `stage` ("integrate": integrated and its boundary written).
bool tile_stage_finished(const TileStageContext& c, std::size_t tile, const std::string& stage);

// Writes tile K's boundary from its integrated field (a tile no depth map reaches: an empty
// one). Returns false if it was written before.
bool write_tile_boundary(const TileStageContext& c, std::size_t tile);

// Runs `stage` (after "integrate") for tile K. Returns false if the tile had finished it. Throws
// StageNotReady (an InputError) naming a tile that has not finished the stage before.
bool run_tile_stage(const TileStageContext& c, std::size_t tile, const std::string& stage);

// Whether every tile has finished every stage (then the merge only writes the mesh), and if not,
// the first stage some tile has not finished and those tiles.
struct StagesStatus {
  std::string pending;               // empty: all done
  std::vector<std::size_t> tiles;    // the tiles that have not finished it
};
StagesStatus tile_stages_status(const TileStageContext& c);

// The merge of tiles that ran every stage: the last pass, streaming the mesh.
void write_tiles_mesh(const TileStageContext& c, MeshStream& out, ExtractStats* stats);

}  // namespace sf
