#pragma once
// Cluster runs (docs/cluster.md): a job cut into tiles that nodes integrate, regularize and
// extract independently, stage by stage (scheduler/cluster_stage.h), then one merge that writes
// the mesh (or, when the tiles only integrated, regularizes and extracts the union of their fields).
//
//   DIR/plan.json             the plan (written once by `scalefuse plan`, read by every tile run):
//                             root cube, brick level, per tile its box of bricks, estimated work
//                             and the depth maps (source indices) whose reach meets it
//   DIR/config.toml           the effective configuration
//   DIR/job.sqlite            the job's journal: inputs, and after the merge its field and extraction
//   DIR/cluster/tile-K/       tile K's own job (scheduler/job.h): its journal, checkpoints and brick
//                             tiles; only the process running tile K writes there
//
// Tiles share nothing while they run (a shared file system is read, each tile writes its own
// folder), so a Slurm array or MPI ranks can run them in any order, anywhere, at once. Each voxel sums its
// contributions in depth-map order in whichever tile holds it, so the mesh is byte-identical to a
// single-machine run's whatever the number of tiles.
#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

#include "engine/fusion.h"
#include "storage/brick_map.h"

namespace sf {

struct ClusterPlan {
  RootCube root;
  int brick_level = 0;
  std::size_t depth_maps = 0;  // fused by the job (after input.frame_step)
  std::size_t samples = 0;
  struct Tile {
    BrickBox box;
    double work = 0;                  // estimated bytes of its field
    std::vector<std::size_t> frames;  // source indices, in input order
  };
  std::vector<Tile> tiles;
};

ClusterPlan cluster_plan_of(const FusionPlan& plan);
// plan.json, written to a temporary name, synced and renamed.
void write_cluster_plan(const std::filesystem::path& job_dir, const ClusterPlan& plan);
// Throws InputError naming the file on a missing or malformed plan.
ClusterPlan read_cluster_plan(const std::filesystem::path& job_dir);

// Tile K's job folder.
std::filesystem::path tile_job_dir(const std::filesystem::path& job_dir, std::size_t tile);

// The tile to run from the environment: SLURM_ARRAY_TASK_ID (a Slurm array task), else
// JOB_COMPLETION_INDEX (a Kubernetes indexed job); -1 if neither is set. Throws InputError on a
// value that is not a tile number.
long tile_from_environment();

// Slurm batch scripts for a planned job: an array of one task per tile for each stage, each after
// the one before, and a merge that runs only if every task succeeded (afterok;
// --kill-on-invalid-dep cancels what follows a failure).
struct SlurmOptions {
  std::string scalefuse;      // the program, an absolute path every node can run
  std::string output;         // the mesh the merge writes
  std::string partition;      // empty: the cluster's default
  std::string account;
  std::string time = "24:00:00", merge_time = "24:00:00";
  int cpus = 8, merge_cpus = 0;  // merge_cpus 0: as cpus
  std::string memory = "16G", merge_memory;  // per task; merge_memory empty: as memory
  std::string memory_limit;   // --memory-limit of scalefuse; empty: 3/4 of --mem
  std::vector<std::string> extra;  // further #SBATCH lines, verbatim (e.g. "--constraint=avx2")
};
struct SlurmScripts {
  std::string tiles, merge, submit;  // tiles.sbatch, merge.sbatch, submit.sh
};
SlurmScripts slurm_scripts(const std::filesystem::path& job_dir, std::size_t tiles, const SlurmOptions& options);

}  // namespace sf
