#pragma once
// Delaunay tetrahedralization of the voxel positions (section 7.1). CGAL stays in delaunay.cc.
//
// Voxel positions lie on a primal octree lattice: almost every group of five points is
// cospherical. CGAL's Delaunay_triangulation_3 decides those cases by symbolic perturbation, so
// the triangulation is a function of the point set alone: insertion order and sequential vs
// parallel insertion do not change it (tests/extract_delaunay_test.cc checks this).
//
// The points are the voxels' integer coordinates at the finest level present (a similarity
// image of their world positions, so the same Delaunay complex, without the rounding of
// min + h * x). On integer input the orientation and in-sphere predicates are evaluated exactly in
// 64/128-bit integer arithmetic: lattice input makes almost every in-sphere test degenerate, and
// CGAL's floating-point filters would send each one to multi-precision arithmetic.
#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "engine/progress.h"

namespace sf::extract_detail {

// Four point indices. Cells are positively oriented: det[p1 - p0, p2 - p0, p3 - p0] > 0, so the
// face (p0, p1, p2) has its normal (p1 - p0) x (p2 - p0) pointing toward p3.
using Tet = std::array<std::uint32_t, 4>;

// Integer lattice coordinates, each in [0, kMaxLatticeCoordinate] (the voxel coordinate range
// of the deepest octree level), which keeps every predicate within 128 bits.
using LatticePoint = std::array<std::int32_t, 3>;
inline constexpr std::int32_t kMaxLatticeCoordinate = std::int32_t{1} << 18;

class DelaunayTetrahedralization {
 public:
  // points must be pairwise distinct and within range (throws std::invalid_argument otherwise).
  // parallel: CGAL's Parallel_tag insertion with a lock grid, in the calling TBB arena.
  // Reports "tetrahedralize".
  DelaunayTetrahedralization(const std::vector<LatticePoint>& points, bool parallel, const ProgressFn& progress);
  ~DelaunayTetrahedralization();
  DelaunayTetrahedralization(const DelaunayTetrahedralization&) = delete;
  DelaunayTetrahedralization& operator=(const DelaunayTetrahedralization&) = delete;

  // Finite cells (0 when the points are fewer than 4 or coplanar).
  std::size_t number_of_cells() const;
  // Calls visit once per finite cell, sequentially, in CGAL's storage order (not deterministic).
  void for_each_cell(const std::function<void(const Tet&)>& visit) const;
  // The same cells in consecutive batches of up to kCellBatch, so that the caller can process
  // each batch in parallel (CGAL's cell container can only be walked sequentially).
  static constexpr std::size_t kCellBatch = std::size_t{1} << 16;
  void for_each_cell_batch(const std::function<void(const Tet* cells, std::size_t count)>& visit) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The triangulation's own exact predicates on lattice points, for certifying its cells elsewhere.
// Sign of det[q - p, r - p, s - p] (positive: s sees p, q, r counterclockwise).
int lattice_orientation(const LatticePoint& p, const LatticePoint& q, const LatticePoint& r, const LatticePoint& s);
// For a positively oriented cell: +1 if t is inside its circumsphere, -1 if outside, decided on
// the sphere by CGAL's symbolic perturbation exactly as Delaunay_triangulation_3 does (so never 0).
int lattice_side_of_sphere(const LatticePoint* cell[4], const LatticePoint& t);

// All finite cells, each rotated by an even permutation so that its smallest index comes first,
// sorted. For tests and tools: the full list costs 16 bytes per cell.
std::vector<Tet> delaunay_tetrahedra(const std::vector<LatticePoint>& points, bool parallel);

}  // namespace sf::extract_detail
