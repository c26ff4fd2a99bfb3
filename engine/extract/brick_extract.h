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
//   1 tetrahedralize  each brick X triangulates a window per owner level L (the level-l voxels
//                   within h(L) + n h(l) of its level-L voxels' box; split between the owners
//                   when too big for the budget), keeps the certified global cells it owns (coarsest vertex in X),
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
#include <cstddef>
#include <filesystem>
#include <memory>
#include <vector>

#include "engine/extract/extract.h"
#include "engine/geometry.h"
#include "engine/mesh.h"
#include "engine/progress.h"

namespace sf {

class BrickExtraction {
 public:
  // Scratch files go to `scratch` (created; removed when done). Of `memory_budget`, a quarter
  // holds decoded bricks for the windows and half the windows' triangulations in flight (a window
  // larger than that runs alone).
  BrickExtraction(std::filesystem::path scratch, const RootCube& root, int brick_level, const ExtractOptions& options,
                  std::size_t memory_budget);
  ~BrickExtraction();
  BrickExtraction(const BrickExtraction&) = delete;
  BrickExtraction& operator=(const BrickExtraction&) = delete;

  // Adds voxels of any bricks (each voxel once over all calls). Thread-safe.
  void add(const std::vector<SurfaceVoxel>& voxels);

  // Every voxel added, brick by brick (for the global extraction, when they are few enough).
  // No add() after this.
  std::vector<SurfaceVoxel> voxels() const;

  // Runs the passes in the calling TBB arena and streams the mesh to `out`. Throws InputError on
  // an invalid, duplicated or non-finite voxel, or when fewer than 4 voxels were added.
  void run(MeshStream& out, const ProgressFn& progress, ExtractStats* stats);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sf
