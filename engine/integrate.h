#pragma once
// Section 5: inserting a triangulated depth map into the hierarchical signed distance field.
//
// Each triangle goes to the level of equation 1 and `coarser_levels` coarser levels. A voxel of
// such a level receives the signed distance, along its line of sight, to the triangle that its
// line of sight hits. Because a triangulated depth map is a height field over the sensor plane,
// exactly one triangle owns each line of sight: we decide ownership in the sensor plane with edge
// functions evaluated identically by both triangles sharing an edge, so every voxel gets at most
// one contribution per depth map. That makes the accumulation order within a depth map irrelevant
// and the fused field independent of thread timing.
#include <cstddef>
#include <memory>
#include <vector>

#include "engine/depth_frame.h"
#include "engine/geometry.h"
#include "engine/triangulate.h"
#include "storage/brick_map.h"

namespace sf {

struct IntegrateOptions {
  double lambda = 1.0;        // sampling rate λ: cell size <= triangle footprint / λ (equation 1)
  double gamma = 4.0;         // ramp size factor γ: ramp = γ × cell size of the level, metres
  int coarser_levels = 4;     // insert each triangle into this many coarser levels too (paper: 4)
  // Coarser-level insertions reach at most this many times the triangle's own ramp (γ × its own
  // cell size) from the triangle; 0 reproduces the paper (the coarse level's full ramp). Bounds the
  // phantom surfaces that huge coarse ramps from opposite sides of thin objects create (NOTES.md):
  // on a noisy synthetic bunny (σ = 0.5 footprint, γ = 8) whole-object F@10mm goes 0.79 -> 0.95
  // from reach 4 to reach 1.
  double coarse_reach = 1.0;
  // Length of the ramp behind the surface, as a fraction of the ramp (1 = the paper's symmetric
  // ramp). A shorter back ramp keeps a view's negative distances from reaching through thin parts
  // of an object, where they cancel the other side's positive ones (phantom or lost surfaces).
  double behind = 1.0;
  // Triangles whose normal is within acos(min_cosine) of perpendicular to the line of sight carry
  // almost no weight (angle term) and span long ramps; they are skipped.
  double min_cosine = 0.05;
  int max_level = kMaxLevel;  // deepest octree level used
  // >= 0: a single-level VRIP baseline — every triangle goes to this level only, whatever its
  // footprint (for comparisons; not the paper's method). -1: off.
  int single_level = -1;
  void check() const;
};

struct IntegrateStats {
  std::size_t triangles = 0;       // triangles inserted
  std::size_t contributions = 0;   // voxel updates
  std::size_t triangles_per_level[kMaxLevel + 1] = {};  // by level of equation 1
  void add(const IntegrateStats& o);
};

// The tables the voxel-centric enumeration builds for a depth map (about 60 MB for 500 x 375),
// kept from one call to the next so that each depth map reuses the last one's memory: allocated
// afresh (above malloc's mmap threshold) they cost a page fault per 4 KiB every time, and a
// depth map is read once per plan tile that it reaches. For one caller at a time.
class IntegrateScratch {
 public:
  IntegrateScratch();
  ~IntegrateScratch();
  IntegrateScratch(const IntegrateScratch&) = delete;
  IntegrateScratch& operator=(const IntegrateScratch&) = delete;
  std::size_t bytes() const;  // the tables' capacity
  struct Tables;
  std::unique_ptr<Tables> tables;
  // The sample phase in four AVX2 lanes rather than two SSE2 ones (the same field either way);
  // true where the CPU has AVX2. Tests clear it to check the two-lane path.
  bool wide_lanes;
};

// Integrates one depth map into `map`. Runs parallel (tbb::parallel_for) in the calling arena.
// Uses the voxel-centric enumeration when the frame allows it (a perspective pixel grid), else
// the prism enumeration; both give the same field.
// With `region`, only voxels of the region's bricks are written (the field of a plan tile; the
// voxels outside get nothing, those inside exactly what the whole frame gives them).
IntegrateStats integrate_frame(const DepthFrame& frame, const std::vector<FrameTriangle>& triangles,
                               const RootCube& root, const IntegrateOptions& options, BrickMap& map,
                               const BrickBox* region = nullptr, IntegrateScratch* scratch = nullptr);

// The two enumerations, exposed for tests and benchmarks.
// Prisms: per triangle and level, the voxels of the truncated prism its lines of sight sweep
// (any sensor, any triangulation).
IntegrateStats integrate_frame_prisms(const DepthFrame& frame, const std::vector<FrameTriangle>& triangles,
                                      const RootCube& root, const IntegrateOptions& options, BrickMap& map,
                                      const BrickBox* region = nullptr);
// Voxel-centric: per image tile and level, every voxel of the tile's frustum slab is projected
// into the image and looked up in the pixel grid (perspective frames whose samples sit at pixel
// centres and whose triangles each span one pixel quad). Returns false, touching nothing, when the
// frame does not qualify.
bool integrate_frame_projective(const DepthFrame& frame, const std::vector<FrameTriangle>& triangles,
                                const RootCube& root, const IntegrateOptions& options, BrickMap& map,
                                IntegrateStats* stats, const BrickBox* region = nullptr,
                                IntegrateScratch* scratch = nullptr);

// Where a depth map can write, for planning (scheduler/tile_plan.h): every brick that any voxel
// it integrates can lie in (a superset: integrate_frame writes nothing elsewhere), and its surface
// cells, for estimating the field's size where depth maps overlap: per inserted level l, the
// level-(l - 3) cells its triangles cross, as the key of their first level-l voxel.
struct FrameReach {
  std::vector<std::uint64_t> bricks;  // BrickCoord::packed(), sorted, unique
  std::vector<VoxelKey> cells;        // sorted, unique
};
// `scratch` as for integrate_frame (the planning pass reads every depth map).
FrameReach frame_reach(const DepthFrame& frame, const std::vector<FrameTriangle>& triangles, const RootCube& root,
                       const IntegrateOptions& options, int brick_level, IntegrateScratch* scratch = nullptr);

// The contributions one triangle makes at one level (exposed for tests). `level_of_triangle` is
// the level of equation 1, used to bound coarser-level ramps.
void triangle_contributions(const DepthFrame& frame, const FrameTriangle& tri, int level, int level_of_triangle,
                            const RootCube& root, const IntegrateOptions& options, std::vector<Contribution>& out);

}  // namespace sf
