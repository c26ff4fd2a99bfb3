#pragma once
// Section 7: from scattered voxels of the regularized hSDF to a triangle mesh.
//   Delaunay tetrahedralization of the voxel positions (CGAL, parallel in the caller's arena) ->
//   deletion of tetrahedra with an edge between non-neighbouring voxels (7.1) ->
//   vertex snapping and Marching Tetrahedra without zero-area faces (7.2) -> indexed mesh.
//
// Glossary
//   voxel index   rank of a voxel in key order (keys sort by level, then z, y, x). Every identity
//                 below is made of voxel indices, so sorting by them sorts by voxel keys.
//   crossing      the zero of the linear interpolant on an edge whose two voxels have distances of
//                 strictly opposite signs; identified by the voxel pair (lo, hi), lo < hi.
//   zero voxel    a voxel whose distance is exactly 0 (given, or snapped); identified by (i, i).
//   snapping      7.2: a voxel whose crossing on some edge lies closer than snap_fraction (of that
//                 edge) is moved onto the crossing: position, colour, weight and scale become the
//                 crossing's interpolated values and its distance becomes 0.
//
// Marching Tetrahedra with exact zeros (n-, n0, n+ = vertices below, on, above zero):
//   (1,0,3) (3,0,1) (1,1,2) (2,1,1) (1,2,1)  one triangle
//   (2,0,2)                                  two triangles (the quad split along its shorter
//                                            diagonal; ties: the diagonal holding the smallest
//                                            vertex identity)
//   (1,3,0)                                  the zero face, see below
//   everything else                          nothing: (4,0,0) (0,0,4) (3,1,0) (0,1,3) (2,2,0)
//                                            (0,2,2) (0,3,1) (0,4,0) only touch zero in a vertex,
//                                            an edge, a face seen from the positive side, or are
//                                            entirely zero
//   A face whose three voxels are zero is emitted by the tetrahedron on its negative side (the
//   fourth vertex negative), oriented away from it, unless the tetrahedron on the other side of
//   the face also has a negative fourth vertex: then the face lies inside the solid and neither
//   emits it. The output is thus the boundary of the region {distance < 0} of the kept complex,
//   and every face is emitted at most once. A triangle always has three distinct vertex
//   identities on distinct edges / vertices of its tetrahedron, so none is degenerate by
//   construction (snapping can still move a zero voxel, which is how it removes tiny triangles).
//   Orientation: the normal (v1 - v0) x (v2 - v0) points toward positive distance (outside); it
//   is derived from the orientation of the Delaunay tetrahedron, so it is consistent over the
//   whole mesh even where snapping moved vertices.
#include <array>
#include <cstddef>
#include <string>
#include <vector>

#include "engine/geometry.h"
#include "engine/mesh.h"
#include "engine/progress.h"
#include "storage/voxel_key.h"

namespace sf {

// A voxel that survived regularization. Positive distance = in front of the surface (outside).
struct SurfaceVoxel {
  VoxelKey key;
  float distance = 0;                  // metres
  float weight = 0;                    // confidence
  std::array<float, 3> colour{0, 0, 0};  // 0..255
};

struct ExtractOptions {
  int neighbourhood_n = 2;        // n of section 7.1 (voxels at the finer level)
  double snap_fraction = 0.2;     // 7.2: snap a voxel onto a crossing closer than this edge fraction; 0 = off
  std::size_t min_component_triangles = 0;  // drop connected components smaller than this; 0 = keep all
  // Insert the points with CGAL's parallel (Parallel_tag, lock grid) insertion when the calling
  // arena has more than one thread and there are at least this many voxels. The triangulation is
  // the same either way; 0 = parallel whenever the arena allows it.
  std::size_t parallel_min_voxels = 20000;
  // Brick by brick: the tetrahedralization's windows cover octree cells of bricks holding at most
  // this many voxels (one brick when it holds more), so that the halo each window needs around its
  // owners (h(L) + n h(l) per level) is a small part of it. 0: one brick per window group. The
  // mesh does not depend on it.
  std::size_t window_group_voxels = std::size_t{1} << 19;
  // "global" | "bricks" | "auto": the fusion sets brick_level to its field's brick level for
  // "bricks", and for "auto" when the global tetrahedralization (kDelaunayBytesPerVoxel per voxel)
  // would not fit the memory limit.
  std::string mode = "auto";
  // >= 0: extract brick by brick, out of core (bricks of this octree level; brick_extract.h);
  // the file is the same. -1: one global triangulation.
  int brick_level = -1;
  void check() const;             // throws InputError on a bad value
};

// The global Delaunay tetrahedralization's peak memory per voxel (CGAL cells and vertices, measured).
inline constexpr std::size_t kDelaunayBytesPerVoxel = 550;

struct ExtractStats {
  // voxels: triangulated; tetrahedra: finite Delaunay cells; kept_tetrahedra: cells left by 7.1;
  // snapped_voxels: moved onto a crossing (7.2).
  std::size_t voxels = 0, tetrahedra = 0, kept_tetrahedra = 0, snapped_voxels = 0;
  // triangles: in the output; removed_*: dropped by min_component_triangles.
  std::size_t triangles = 0, removed_components = 0, removed_triangles = 0;
  // Voxels dropped because a finer voxel of the input sits at the same position (section 6's last
  // pass keeps the finest); not counted in `voxels`.
  std::size_t coincident_voxels = 0;
  // Zero faces with negative voxels on both sides (inside the solid), emitted by neither side.
  std::size_t interior_zero_faces = 0;
  // Brick by brick: windows triangulated (one or more per brick, by owner level), points
  // triangulated over all windows (each voxel is in its own brick's windows and in the halos of
  // some others), windows redone with a wider halo because a sliver's circumsphere was too big to
  // certify, windows split in halves between their owners to fit the memory budget. tetrahedra
  // and kept_tetrahedra then count the cells each brick owns in its windows, less the triangulated
  // cells inside empty cubes (lattice_cubes.h: a cube's, or not global).
  // window_cells_rejected: candidate cells a brick owned in its window that the certificate
  // showed not to be global (a voxel outside the window inside their circumsphere).
  // window_voxels_in_cubes: window voxels inside empty lattice cubes (lattice_cubes.h), whose
  // cells are known and which are not triangulated; window_points counts the others.
  std::size_t windows = 0, window_points = 0, windows_regrown = 0, windows_split = 0, window_cells_rejected = 0;
  std::size_t window_voxels_in_cubes = 0;
  // Brick by brick, resumed from a job's journal: items (bricks) an earlier run had finished, over
  // regularization and the passes, that this run skipped.
  std::size_t resumed_items = 0;
  bool by_brick = false;  // which tetrahedralization ran
  // Brick by brick: wall seconds of each pass this run ran (a pass an earlier run finished is not
  // listed), then "write" for the PLY; in order.
  std::vector<std::pair<std::string, double>> pass_seconds;
};

// 7.1: are voxels a and b neighbours? With A the coarser (L(A) <= L(B)), b must lie within
// 2^(L(B)-L(A)) + n voxels of level L(B) from a's position, per axis.
bool are_neighbours(VoxelKey a, VoxelKey b, int n);

// Extracts the zero set.
//  - The triangulation is built on the voxels' integer lattice coordinates at the finest level
//    present (exact, and the same complex as their world positions); output positions are
//    interpolated from RootCube::position in double.
//  - Deterministic for a given voxel set, independent of thread count, input order and brick
//    level: vertices are named by the voxel keys that define them (a zero voxel's key, or a
//    crossing's key pair, lower key first) and ordered by the Morton code of the lower voxel's
//    position, then by name (voxel_set.h); each face is rotated so that its smallest vertex index
//    comes first (orientation kept), and faces are sorted.
//  - Every vertex carries colour (interpolated, rounded), confidence (interpolated weight) and
//    scale (interpolated cell size).
//  - Runs its parallel work in the calling TBB arena. Time and memory are dominated by the
//    Delaunay tetrahedralization (about 550 bytes per voxel at the peak, freed before marching).
//  - Throws InputError on an invalid key, a duplicated key, or a non-finite distance, weight or
//    colour.
Mesh extract_surface(const std::vector<SurfaceVoxel>& voxels, const RootCube& root, const ExtractOptions& options,
                     const ProgressFn& progress, ExtractStats* stats);

}  // namespace sf
