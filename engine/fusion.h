#pragma once
// The whole fusion, input -> triangles -> bricks -> hSDF -> regularized voxels -> tetrahedra -> mesh.
#include <array>
#include <atomic>
#include <stdexcept>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "engine/error.h"
#include "engine/extract/extract.h"
#include "engine/geometry.h"
#include "engine/input/frame_source.h"
#include "engine/integrate.h"
#include "engine/mesh.h"
#include "engine/parameters.h"
#include "engine/progress.h"
#include "engine/regularize.h"
#include "engine/triangulate.h"

namespace sf {

class ExtractJournal;

struct OctreeOptions {
  // Clip box "xmin,ymin,zmin,xmax,ymax,zmax" in world metres; empty: the data's bounding box.
  std::string bbox;
  double padding = 0.05;  // the root cube extends the data's largest extent by this fraction per side
  // 2^brick_level bricks per axis of the root cube; -1 (auto): the finest insertion level of the
  // data - 8 (bricks of 256 finest cells), clamped to [3, 10], so a brick stays small against the
  // memory budget however wide the scene is.
  int brick_level = -1;
  // > 0 (metres) and brick_level = -1: the coarsest brick level whose bricks are at most this wide.
  double brick_size = 0;
  void check() const;
};

struct FusionOptions {
  InputOptions input;
  TriangulateOptions triangulate;
  IntegrateOptions integrate;
  RegularizeOptions regularize;
  ExtractOptions extract;
  OctreeOptions octree;
  void check() const;
};

// Registers every parameter under its dotted name.
void register_parameters(ParameterSet& set, FusionOptions& options);

struct StageTime {
  std::string stage;
  double seconds = 0;
};

struct FusionStats {
  std::string format;
  std::size_t depth_maps = 0, samples = 0, triangles = 0, contributions = 0;
  std::size_t samples_outside_root = 0;  // fuse --follow: samples of later depth maps outside the root cube
  std::size_t resumed_at = 0;  // depth maps (+ sweep steps) already integrated by an earlier run of the job
  std::size_t tiles = 0;       // tiles of the last sweep (1: the whole field at once)
  std::size_t sweep_steps = 0; // (tile, depth map) integrations of this run
  std::size_t frame_reads = 0; // depth maps read for integration (once per tile they reach) and planning
  double plan_estimate_bytes = 0;  // the plan's estimate of the field's memory (last sweep)
  std::size_t field_bytes = 0;     // the field's memory when integrated (bricks measured when resident)
  int brick_level = 0;         // the one used (octree.brick_level, or chosen by auto)
  RootCube root;
  std::array<std::size_t, kMaxLevel + 1> voxels_fused{};        // after integration
  std::array<std::size_t, kMaxLevel + 1> voxels_regularized{};  // after section 6
  std::array<std::size_t, kMaxLevel + 1> triangles_per_level{};
  RegularizeStats regularize;
  ExtractStats extract;
  std::vector<StageTime> times;
  std::size_t peak_rss_bytes = 0;
  std::size_t peak_rss_integrate_bytes = 0;   // peak RSS when integration ended
  std::size_t peak_rss_regularize_bytes = 0;  // ... when regularization ended (before the tetrahedralization)
  SpillStats spill;                          // bricks spilled to and reloaded from tiles during integration
};

// Hooks that let the caller see the field (e.g. to export it) without the engine knowing formats.
struct FusionHooks {
  ProgressFn progress;
  // Set (e.g. by a signal handler) to stop at the next safe point and throw Interrupted: in
  // integration after the depth maps in flight (with a journal, then a checkpoint); in
  // regularization and the brick extraction after the bricks in flight (their progress is
  // committed to the journal's extraction record); in the global extraction between its steps;
  // while the mesh is written, between bricks (the temporary output is removed).
  const std::atomic<bool>* stop = nullptr;
  // Called once the integration is complete (and checkpointed).
  std::function<void()> integrated;
  std::function<void(const std::vector<SurfaceVoxel>&, const RootCube&)> on_regularized;
  // fuse --follow: the source grows; fuse() integrates what it holds, then asks the feed for more
  // until the feed ends. The root cube comes from octree.bbox or the depth maps present at the
  // start; later samples outside it are dropped (counted in FusionStats::samples_outside_root).
  // `stop` is not read while following: the feed watches for signals and ends.
  FrameFeed* follow = nullptr;
  // Stream the mesh here (e.g. a PlyStreamWriter) instead of returning it: the brick-by-brick
  // extraction never holds it whole.
  MeshStream* mesh_out = nullptr;
  // A folder for the extraction's scratch files (e.g. in the job directory); empty: a temporary
  // folder. Emptied when the extraction ends.
  std::filesystem::path scratch;
  // A cluster tile's run (scheduler/cluster.h): fuse only these depth maps (source indices, in
  // input order; input.frame_step is not applied) ...
  const std::vector<std::size_t>* frames = nullptr;
  // ... and integrate only into this box of bricks (the voxels of other bricks get nothing; those
  // inside exactly what a run over every depth map gives them). Use with stop_after_integration.
  const BrickBox* region = nullptr;
  // Return an empty mesh once the integration is checkpointed (fuse --integrate-only); the stats
  // then hold the integration's figures and, with count_fused_voxels, the fused voxels per level
  // (which reads every spilled brick back: a cluster tile's run leaves that to the merge).
  bool stop_after_integration = false;
  bool count_fused_voxels = true;
};

// Where an integration stands. Depth maps [0, integrated) are in every brick. A sweep over depth
// maps [integrated, sweep_end) runs tile by tile (scheduler/tile_plan.h): tiles [0, tile) hold
// them, tile `tile` holds the first `tile_frames` of those that reach it; `steps` counts the
// (tile, depth map) integrations of the sweep done so far.
struct IntegrationProgress {
  std::size_t integrated = 0;
  std::size_t sweep_end = 0;  // == integrated: no sweep under way
  std::vector<BrickBox> tiles;
  std::size_t tile = 0, tile_frames = 0, steps = 0;
  bool sweeping() const { return sweep_end > integrated; }
  // Depth maps every brick holds, counting the sweep's when it has one tile (then steps are
  // depth maps).
  std::size_t whole_frames() const { return integrated + (tiles.size() == 1 ? steps : 0); }
};

// What a job remembers of one depth map, to notice changed inputs on resume.
struct FrameIdentity {
  std::string name;            // the file it comes from
  std::uint64_t file_size = 0;  // bytes (0 if the name is not a file)
  std::uint64_t hash = 0;      // DepthFrame::content_hash()
};

// A journal of the integration that makes it resumable (implemented by scheduler/job: the job
// directory). fuse() calls it in this order: begin, step_done after each (tile, depth map)
// integration (between them: no other access to the map runs), integrated.
class FusionJournal {
 public:
  virtual ~FusionJournal() = default;
  // The root cube of an existing job (depth maps added later must land in the same octree);
  // nullopt for a new job, whose root comes from the data.
  virtual std::optional<RootCube> fixed_root() const = 0;
  // The brick level of an existing job (its tiles are cut that way); nullopt for a new job.
  virtual std::optional<int> fixed_brick_level() const { return std::nullopt; }
  // Restores the map from the last checkpoint and returns where it stands (all zero for a new
  // job). Throws InputError if the job was started on other inputs or another configuration.
  virtual IntegrationProgress begin(const std::vector<FrameIdentity>& frames, const RootCube& root, BrickMap& map) = 0;
  // The source grew (fuse --follow): depth maps [from, frames.size()) are new; record them.
  virtual void inputs_added(const std::vector<FrameIdentity>& frames, std::size_t from) = 0;
  // One more step is done; may spill bricks and commit a checkpoint of `progress`.
  virtual void step_done(const IntegrationProgress& progress, BrickMap& map) = 0;
  // A tile of a sweep of several is done and its bricks written: a checkpoint costs no more
  // writes now, and saves redoing the tile.
  virtual void tile_done(const IntegrationProgress& progress, BrickMap& map) = 0;
  // Depth maps [from, from + boxes.size()) of the job's order write only into the bricks of these
  // boxes (an empty box: none), as a sweep's plan found before integrating them; a damaged tile
  // is then rebuilt from the depth maps that reach its brick alone.
  virtual void reached(std::size_t from, const std::vector<BrickBox>& boxes) {
    (void)from;
    (void)boxes;
  }
  // Integration is complete: the final checkpoint.
  virtual void integrated(const IntegrationProgress& progress, BrickMap& map) = 0;
  // Integration stopped early (FusionHooks::stop): a checkpoint.
  virtual void interrupted(const IntegrationProgress& progress, BrickMap& map) = 0;
  // The record of a brick extraction of the integrated field, its mailboxes in `scratch`, so
  // that it resumes brick by brick (engine/extract/brick_extract.h). `signature` names the
  // parameters that shape its result; a record of other parameters or of an earlier field is
  // dropped (with the scratch files). nullptr: the journal keeps none.
  virtual ExtractJournal* extraction(const std::string& signature, const std::filesystem::path& scratch) {
    (void)signature;
    (void)scratch;
    return nullptr;
  }
};

// Runs the fusion in the calling TBB arena and returns the mesh (empty if streamed to
// hooks.mesh_out). Throws InputError on bad input. With a journal the
// integration resumes from, and checkpoints into, the journal's job.
Mesh fuse(const FrameSource& source, const FusionOptions& options, const FusionHooks& hooks, FusionStats* stats,
          FusionJournal* journal = nullptr);

// A cluster run's plan (docs/cluster.md): the octree a single-machine run of the same input and
// parameters uses (so that the meshes are the same), the brick grid split into tiles of about equal
// estimated work, and per tile the depth maps whose reach (frame_reach) meets it.
struct FusionPlan {
  RootCube root;
  int brick_level = 0;
  std::vector<std::size_t> frames;          // source indices fused (input.frame_step), in input order
  std::vector<FrameIdentity> identities;    // of each of `frames`
  std::size_t samples = 0;
  std::vector<BrickBox> tiles;              // a partition of the brick grid (some may be empty)
  std::vector<double> work;                 // per tile: the estimated bytes of its field
  std::vector<std::vector<std::size_t>> tile_frames;  // per tile: source indices, in input order
};
// Reads every depth map twice (bounds, then reach). Throws InputError on bad input.
FusionPlan plan_fusion(const FrameSource& source, const FusionOptions& options, std::size_t tiles,
                       const ProgressFn& progress);

// octree.brick_level = auto: the finest insertion level of the data minus 8, in [3, 10].
int auto_brick_level(const RootCube& root, double finest_footprint, const IntegrateOptions& integrate);

// The root cube for a set of sample bounds (see OctreeOptions).
RootCube root_cube_for(const Eigen::AlignedBox3d& data_bounds, double padding);
// Parses OctreeOptions::bbox; nullopt when empty. Throws InputError on a malformed box.
std::optional<Eigen::AlignedBox3d> parse_bbox(const std::string& text);

std::size_t peak_rss_bytes();

// What shapes the regularized voxels and the brick extraction's passes (a job's record of an
// extraction holds for this signature only).
std::string extraction_signature(const FusionOptions& options, int brick_level);
// A brick's regularized voxels as the extraction takes them (voxels without colour are grey).
std::vector<SurfaceVoxel> surface_voxels(const std::vector<std::pair<VoxelKey, VoxelData>>& brick);

}  // namespace sf
