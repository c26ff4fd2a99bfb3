#pragma once
// Section 7 brick by brick and out of core: the same mesh as extract_surface's global path (the
// same file, byte for byte), with memory bounded by one brick window per thread instead of the
// whole field. docs/architecture.md ("Extraction by bricks") has the proofs and a figure.
//
// Bricks are the cubes of an octree level B. The voxels arrive brick by brick (add) and go to
// scratch files; then passes over the bricks, each in parallel, exchange records through
// mailboxes (storage/mailbox.h, every record written once and read once):
//   0 prepare       sort each brick's voxels, check them, drop coarser coincident twins, index
//                   the bricks (occupancy summary, levels present)
//   1 tetrahedralize  per window group (octree cells of bricks with at most window_group_voxels
//                   voxels, or one brick), a window per owner level L (the level-l voxels
//                   within h(L) + n h(l) of the group's level-L voxels' box; split between the owners
//                   when too big for the budget) keeps the certified global cells each brick X
//                   owns (coarsest vertex in X),
//                   filtered by 7.1 and able to emit; posts them with their voxels, and posts
//                   7.2 snap offers (the closest crossing per voxel) to each voxel's brick
//   2 snap          each brick decides its voxels' snaps from all offers (as the global
//                   snapping's atomic minimum does)
//   3 march         each brick applies the snaps of its cells' voxels and marches its cells;
//                   each output vertex (named by voxel keys) is sent to its home brick (the brick
//                   of its lower voxel)
//   4 number        each home brick numbers its vertices in output order (voxel_set.h); bricks in
//                   Morton order then give global numbers; ranks go back to the requesters
//   5 faces         each brick turns its triangles into global indices, sends each to the home
//                   brick of its smallest vertex
//   6 sort          each home brick sorts its faces and cancels interior zero faces (both copies
//                   of such a face meet at the same home brick)
//   7 write         small components are removed (union-find over the vertex numbers, 8 bytes
//                   per vertex) and the mesh is streamed out, brick by brick in Morton order.
//
// With a journal (a job's), the extraction resumes brick by brick: a killed run's next run skips
// the bricks each pass finished and reads what they posted (ExtractJournal).
#include <cstddef>
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "engine/error.h"
#include "engine/extract/extract.h"
#include "engine/geometry.h"
#include "engine/mesh.h"
#include "engine/progress.h"
#include "storage/mailbox.h"

namespace sf {

// Where a brick extraction records its progress (the job's SQLite journal, scheduler/job.h).
// Passes run over items (bricks; for "regularize", the sources given to add); a commit records the
// items a pass finished and the mailbox blobs they posted, after the mailbox files are synced.
// A run that finds committed items skips them and reopens the mailboxes with the committed
// blobs, so its result is byte-identical to an uninterrupted run's.
class ExtractJournal {
 public:
  struct Record {
    std::string box;
    Mailbox::Blob blob;
  };
  // The item a pass commits when it is complete.
  static constexpr std::uint64_t kWholePass = ~std::uint64_t{0};

  virtual ~ExtractJournal() = default;
  // What earlier runs committed: (pass, item) finished, and mailbox blobs.
  virtual std::vector<std::pair<std::string, std::uint64_t>> finished() const = 0;
  virtual std::vector<Record> blobs() const = 0;
  // One transaction.
  virtual void commit(const std::string& pass, const std::vector<std::uint64_t>& items,
                      const std::vector<Record>& blobs) = 0;
  // Mailboxes no later pass reads: their blobs are dropped (the caller deletes the files after).
  virtual void forget(const std::vector<std::string>& boxes) = 0;
  // Seconds between commits while a pass runs (0: after every item).
  virtual double commit_seconds() const = 0;
};

// A cluster tile's part of a brick extraction (docs/cluster.md): one process per pass (a
// "stage"), every tile running it over the items of its own bricks, with the cluster engine's
// barrier between passes (Slurm dependencies, MPI rank 0's bookkeeping). Each tile posts to
// mailboxes in its own folder and, once it has finished a pass, writes `<pass>.blobs` there (what
// it posted, storage/mailbox.h); later passes read the union of every tile's mailboxes. Every
// record is posted by the item it belongs to, in the same order as on one machine, so the mesh is
// the single-machine mesh byte for byte.
struct ExtractShare {
  std::vector<std::filesystem::path> folders;  // every tile's exchange folder, by tile
  std::size_t tile = 0;                        // this process's tile; folders.size(): none (the merge)
  std::function<bool(std::uint64_t brick_code)> owns;  // whether a brick (Morton code) is this tile's
  std::string stage;                           // the pass to run, one of BrickExtraction::passes()
};

// A pass of a shared extraction has not been finished by some tile.
class StageNotReady : public InputError {
 public:
  using InputError::InputError;
};

class BrickExtraction {
 public:
  // The passes in order: "regularize" (add), then run()'s, the last one "write" (the stream).
  static const std::vector<std::string>& passes();

  // Scratch files go to `scratch` (created; removed when done, unless there is a journal: then
  // the journal's owner removes them). Of `memory_budget`, a quarter holds decoded bricks for the
  // windows and 40 % the windows' triangulations in flight (a window larger than that runs
  // alone; one larger than half of that is split between its owners where it can be).
  // With `share` (a cluster tile's stage), `scratch` is the tile's folder (share->folders[tile]);
  // throws StageNotReady naming a tile that has not finished an earlier pass.
  BrickExtraction(std::filesystem::path scratch, const RootCube& root, int brick_level, const ExtractOptions& options,
                  std::size_t memory_budget, ExtractJournal* journal = nullptr, const ExtractShare* share = nullptr);
  ~BrickExtraction();
  BrickExtraction(const BrickExtraction&) = delete;
  BrickExtraction& operator=(const BrickExtraction&) = delete;

  // Adds voxels of any bricks (each voxel once over all calls), all those of `source` (e.g. the
  // brick they were regularized in) at once. Thread-safe. Then all_added().
  void add(std::uint64_t source, const std::vector<SurfaceVoxel>& voxels);
  // Once *stop is set, each pass finishes the bricks in flight, commits what it finished to the
  // journal, and throws Interrupted (the write pass stops between bricks); a run of the same
  // journal resumes from there.
  void set_stop(const std::atomic<bool>* stop);
  // Commits the bricks added so far (a stopped regularization), before throwing Interrupted.
  void commit_added();
  // Whether an earlier run (of the journal) added `source` already / added everything.
  bool added_before(std::uint64_t source) const;
  bool all_added_before() const;
  void all_added();
  // Voxels added (after all_added()).
  std::size_t size() const;

  // Every voxel added, brick by brick (for the global extraction, when they are few enough).
  // No add() after this.
  std::vector<SurfaceVoxel> voxels() const;

  // Runs the passes in the calling TBB arena and streams the mesh to `out`. Throws InputError on
  // an invalid, duplicated or non-finite voxel, or when fewer than 4 voxels were added.
  // With a share: runs the stage's pass over this tile's bricks and returns (`out` and `stats`
  // untouched) unless the stage is "write".
  void run(MeshStream& out, const ProgressFn& progress, ExtractStats* stats);
  // With a share: whether this tile has finished the stage (its `<pass>.blobs` exists).
  bool stage_finished() const;

 private:
  void run_passes(MeshStream& out, const ProgressFn& progress, ExtractStats* stats);
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sf
