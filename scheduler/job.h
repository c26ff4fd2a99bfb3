#pragma once
// A fusion job on disk: the job directory that makes a long fusion resumable.
//
//   DIR/job.sqlite   the journal (SQLite, WAL, synchronous=FULL): effective configuration, input
//                    list with each depth map's file size and content hash, the last committed
//                    checkpoint (depth maps integrated, manifest brick -> tile generation), stage
//   DIR/tiles/       brick tiles (storage/tile_file.h), b_X_Y_Z.GEN.tile
//   DIR/scratch/     the brick extraction's mailboxes while it runs (storage/mailbox.h); the
//                    journal records the bricks each pass finished and their blobs, so that an
//                    interrupted extraction resumes brick by brick
//   DIR/mesh.ply     the final mesh (also linked or copied to the requested output)
//
// A checkpoint is committed in one SQLite transaction after its tiles are written and fsynced;
// tiles it refers to are never overwritten (generations only grow) and older ones are deleted
// only after the commit. So after a crash, kill -9 or power loss at any instant, the job holds a
// complete checkpoint, and resuming deletes whatever was written after it.
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "engine/error.h"
#include "engine/extract/brick_extract.h"
#include "engine/fusion.h"
#include "storage/tile_store.h"

struct sqlite3;

namespace sf {

// The job directory holds a job of other inputs or parameters (resuming it is refused).
class JobMismatch : public InputError {
 public:
  using InputError::InputError;
};

struct JobOptions {
  std::filesystem::path dir;
  std::size_t memory_limit = std::size_t{1} << 30;  // bytes of resident bricks
  std::size_t checkpoint_every = 200;               // integration steps (depth maps x tiles they reach)
  double checkpoint_seconds = 300;
  // Testing aid: the process kills itself (SIGKILL, no clean-up) once depth maps integrated + steps
  // of the sweep under way reach this, after any checkpoint due at that point. 0 = never.
  std::size_t kill_after = 0;
  // Testing aid: the same, sending itself SIGTERM. 0 = never.
  std::size_t term_after = 0;
  // Testing aid: SIGKILL right after the n-th commit of the extraction's progress. 0 = never.
  std::size_t kill_in_extraction = 0;
  // Testing aid: the same, sending itself SIGTERM. 0 = never.
  std::size_t term_in_extraction = 0;
  // `scalefuse add`: the inputs may extend the job's (its depth maps first, unchanged).
  bool allow_new_inputs = false;
  // fuse --follow: the input grows while the job runs (implies allow_new_inputs); recorded so
  // that `scalefuse resume` keeps the job's order of depth maps.
  bool follow = false;
  // A cluster tile's job (scheduler/cluster.h): the octree fixed by the plan, for a new job too.
  std::optional<RootCube> root;
  std::optional<int> brick_level;
};

struct JobStatus {
  std::string stage;  // "new", "integrating", "integrated", "extracting", "done"
  std::string input, output;  // input: the job's input folders, one per line
  std::size_t depth_maps = 0, integrated = 0, bricks = 0;
  // A sweep under way (sweep_tiles > 0): its tiles, the tile it is in, steps done.
  std::size_t sweep_tiles = 0, sweep_tile = 0, sweep_steps = 0;
  std::uint64_t tile_bytes = 0, journal_bytes = 0;
  std::string last_checkpoint;  // UTC time, empty if none
  bool follow = false;          // started by fuse --follow
  // The brick extraction under way: per pass (in order), the bricks it finished and whether it
  // is complete.
  struct ExtractPass {
    std::string pass;
    std::size_t bricks = 0;
    bool complete = false;
  };
  std::vector<ExtractPass> extraction;
};

class Job : public FusionJournal {
 public:
  // Opens DIR (creating it and its journal if new). `config` is the effective configuration text;
  // `input` (folders, one per line) and `output` are recorded so that `scalefuse resume DIR` can
  // run the job again.
  Job(JobOptions options, std::string config, std::string input, std::string output);
  ~Job() override;
  Job(const Job&) = delete;
  Job& operator=(const Job&) = delete;

  std::optional<RootCube> fixed_root() const override;
  std::optional<int> fixed_brick_level() const override;
  IntegrationProgress begin(const std::vector<FrameIdentity>& frames, const RootCube& root, BrickMap& map) override;
  void inputs_added(const std::vector<FrameIdentity>& frames, std::size_t from) override;
  void step_done(const IntegrationProgress& progress, BrickMap& map) override;
  void tile_done(const IntegrationProgress& progress, BrickMap& map) override;
  void reached(std::size_t from, const std::vector<BrickBox>& boxes) override;
  void integrated(const IntegrationProgress& progress, BrickMap& map) override;
  void interrupted(const IntegrationProgress& progress, BrickMap& map) override;
  ExtractJournal* extraction(const std::string& signature, const std::filesystem::path& scratch) override;
  // Records the finished mesh (already written to `mesh`); the extraction's record and scratch
  // files go.
  void finished(const std::filesystem::path& mesh);

  const std::filesystem::path& dir() const { return options_.dir; }
  std::size_t checkpoints_committed() const { return checkpoints_; }
  std::size_t memory_limit() const { return options_.memory_limit; }

  // Reads a job's status without changing it. Throws InputError if DIR holds no job.
  static JobStatus status(const std::filesystem::path& dir);
  // The depth maps a job has recorded, in its order (absolute file names).
  static std::vector<std::string> recorded_inputs(const std::filesystem::path& dir);
  // The configuration, input and output a job was started with (for `scalefuse resume`).
  static JobStatus recorded(const std::filesystem::path& dir, std::string* config);
  // The bricks of a job's last checkpoint and the tiles holding them (paths), and its highest
  // tile generation.
  struct Field {
    std::vector<ManifestEntry> manifest;
    std::vector<std::filesystem::path> tiles;
    std::uint64_t max_generation = 0;
  };
  static Field field(const std::filesystem::path& dir);

  // Makes the union of other jobs' fields (each brick in one of them) this job's integrated field:
  // their tiles are linked (copied where the file system cannot link) into this job's folder and
  // synced, then one transaction records them as the checkpoint of all `depth_maps` integrated.
  // For a job that has integrated nothing yet (a cluster plan's, before `scalefuse merge`).
  void adopt(const std::vector<Field>& fields, std::size_t depth_maps);
  // How many of the job's depth maps (the first ones, in its order) the last checkpoint's brick `c`
  // holds; nullopt for a brick of the tile under way in a sweep (the journal does not say which).
  std::optional<std::size_t> depth_maps_in_brick(BrickCoord c) const;
  // Of the job's first `n` depth maps, the positions (in the job's order) of those that can write
  // into a brick of `region`: their recorded reach meets it, or none was recorded (a job of an
  // earlier version, a cluster merge).
  std::vector<std::size_t> depth_maps_reaching(const BrickBox& region, std::size_t n) const;
  // Replaces the checkpoint's tile of brick `c` (found damaged) by the tile of `c` in `rebuilt`,
  // the field of a job that re-integrated the depth maps this job integrated into that brick
  // alone: linked under a new generation and committed in one transaction.
  void replace_tile(const Field& rebuilt, BrickCoord c);
  // Every tile of the last checkpoint that is missing or fails its checks, in brick order: each is
  // read and checked in full, in parallel in the caller's arena. A damaged tile seldom comes alone
  // (a bad sector, an interrupted copy), and finding them all at once lets them be rebuilt in one
  // pass over the depth maps (scheduler/tile_rebuild.h).
  std::vector<DamagedTile> damaged_tiles() const;

 private:
  void checkpoint(BrickMap& map, const char* stage);

  JobOptions options_;
  std::string config_, input_, output_;
  sqlite3* db_ = nullptr;
  int lock_fd_ = -1;
  std::unique_ptr<TileStore> store_;
  std::size_t since_checkpoint_ = 0, checkpoints_ = 0;
  IntegrationProgress progress_;  // as of the last step
  std::chrono::steady_clock::time_point last_checkpoint_;
  class Extraction;
  std::unique_ptr<Extraction> extraction_;
  std::filesystem::path scratch_;
};

// "1.5G", "800M", "64K", "1000000" -> bytes. Throws InputError naming `what`.
std::size_t parse_byte_size(const std::string& text, const std::string& what);

}  // namespace sf
