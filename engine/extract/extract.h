#pragma once
// Section 7: from scattered voxels of the regularized hSDF to a triangle mesh.
//   Delaunay tetrahedralization of the voxel positions (CGAL, parallel in the caller's arena) ->
//   deletion of tetrahedra with an edge between non-neighbouring voxels (7.1) ->
//   vertex snapping and Marching Tetrahedra without zero-area faces (7.2) -> indexed mesh.
#include <array>
#include <cstddef>
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
  void check() const;             // throws InputError on a bad value
};

struct ExtractStats {
  std::size_t voxels = 0, tetrahedra = 0, kept_tetrahedra = 0, snapped_voxels = 0;
  std::size_t triangles = 0, removed_components = 0, removed_triangles = 0;
};

// 7.1: are voxels a and b neighbours? With A the coarser (L(A) <= L(B)), b must lie within
// 2^(L(B)-L(A)) + n voxels of level L(B) from a's position, per axis.
bool are_neighbours(VoxelKey a, VoxelKey b, int n);

// Extracts the zero set. The output is deterministic for a given voxel set (independent of thread
// count and input order): vertices and faces are sorted by the voxel keys that define them.
// Runs its parallel work in the calling TBB arena.
Mesh extract_surface(const std::vector<SurfaceVoxel>& voxels, const RootCube& root, const ExtractOptions& options,
                     const ProgressFn& progress, ExtractStats* stats);

}  // namespace sf
