#pragma once
// Each subcommand lives in its own cli/cmd_*.cc and registers itself on the top-level app.
// The callback it installs runs the command; errors propagate as exceptions to main(), which maps
// InputError to exit code 2 and everything else to 1.
#include <CLI/CLI.hpp>

#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/fusion.h"
#include "engine/input/skipping_source.h"
#include "engine/mesh.h"
#include "engine/parameters.h"

namespace sf::cli {

// The options of `fuse`, shared with `resume`.
struct FuseArgs {
  std::string input, output, config, export_vdb, stats_json, job, memory_limit;
  std::string format, colmap_maps, mve_depth, mve_image, mve_confidence, bbox, extract_mode, brick_size;
  std::vector<std::string> sets;
  std::vector<std::string> more_inputs;  // further input folders after `input` (a grown job)
  bool add = false;                      // scalefuse add: the inputs may extend the job's
  bool follow = false;                   // fuse --follow: the input folder is still being written
  std::string stop_file;                 // --follow ends when it exists (default: JOB/STOP)
  double settle_seconds = 2.0, poll_seconds = 1.0;
  int threads = 0;
  std::size_t checkpoint_every = 200;
  double checkpoint_seconds = 300;
  bool quiet = false, print_params = false;
  bool skip_bad = false;                 // --skip-bad (job.skip_bad)
  bool integrate_only = false;           // stop after the integration's checkpoint (resume extracts)
  // A cluster tile's run (scalefuse run-tile): only the plan's depth maps for the tile, only into
  // its bricks, in the plan's octree; stops once integrated.
  struct TileRun {
    std::size_t tile = 0;
    std::vector<std::size_t> frames;
    BrickBox region;
    RootCube root;
    int brick_level = 0;
    std::filesystem::path plan_file;  // JOB/plan.json, for messages
  };
  std::optional<TileRun> tile;
  // fuse --mpi --tiles N: plan N tiles, run them on MPI ranks, merge (docs/cluster.md).
  bool mpi = false;
  std::size_t tiles = 0;
};
void run_fuse(const FuseArgs& args);

// The fusion parameters of `args` (config file, shorthand flags, --set), checked; `params` holds
// them by name afterwards. Prints them unless quiet.
FusionOptions fusion_options(const FuseArgs& args, ParameterSet& params);
// The input folders of `args` as one source; `input_abs` gets their absolute names, one per line.
std::unique_ptr<FrameSource> open_inputs(const FuseArgs& args, const FusionOptions& options, std::string* input_abs);
// With job.skip_bad (the source is a SkippingSource): writes what was skipped to JOB/skipped.txt
// (removed when nothing was), prints it, and returns it; otherwise nothing.
std::vector<SkippedFrame> report_skipped(const FrameSource& source, const std::filesystem::path& job_dir);
// Parameters that shape the integrated field (a job refuses to resume when they change).
extern const std::vector<std::string> kIntegrationParameters;
std::size_t default_memory_limit();
void write_text_atomically(const std::filesystem::path& path, const std::string& text);
// Streams the mesh `produce` makes into `output` (under a temporary name until complete; refused
// before anything is written if it has no triangle) and links it into the job as mesh.ply.
// Returns (vertices, triangles).
// --stats: the statistics as JSON (written to a temporary name, then renamed); nothing if path is empty.
void write_stats_file(const std::string& path, const FusionStats& stats, std::size_t vertices, std::size_t triangles);
std::pair<std::size_t, std::size_t> write_job_mesh(const std::string& output, const std::filesystem::path& job_dir,
                                                   const std::function<void(MeshStream&)>& produce);
// The cluster commands (cli/cmd_cluster.cc, docs/cluster.md). `options` carries the job options
// (threads, memory limit, checkpoints, quiet, stats) of a tile's run or of the merge.
void run_plan(const FuseArgs& args, std::size_t tiles);
// tile < 0: from SLURM_ARRAY_TASK_ID or JOB_COMPLETION_INDEX.
// stage: "integrate" (then the tile's boundary) or a later one of tile_stages() (scheduler/cluster_stage.h).
void run_tile(const std::string& job_dir, long tile, const FuseArgs& options, const std::string& stage = "integrate");
void run_merge(const std::string& job_dir, const std::string& output, const FuseArgs& options);
// fuse --mpi (cli/mpi/fuse_mpi.cc; without MPI it throws InputError).
void run_fuse_mpi(const FuseArgs& args, std::size_t tiles);
// scalefuse resume DIR, with the output replaced when `output` is not empty.
void rerun_job(const std::string& dir, FuseArgs args, const std::string& more, const std::string& output);

// A job stopped by SIGINT/SIGTERM after checkpointing: main() prints the message and exits with
// 128 + the signal number, as a shell expects of a process ended by that signal.
class JobInterrupted : public std::runtime_error {
 public:
  JobInterrupted(const std::string& what, int signal) : std::runtime_error(what), signal(signal) {}
  int signal;
};
void add_job_options(CLI::App* cmd, FuseArgs& args);  // threads, memory, checkpoints, outputs

void add_fuse_command(CLI::App& app);
void add_synth_command(CLI::App& app);
void add_eval_command(CLI::App& app);
void add_job_commands(CLI::App& app);  // resume, status
void add_cluster_commands(CLI::App& app);  // plan, run-tile, merge, slurm

}  // namespace sf::cli
