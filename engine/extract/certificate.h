#pragma once
// Is a cell of a window's Delaunay tetrahedralization (a subset of the voxels) a cell of the
// tetrahedralization of all voxels? Used by the brick-by-brick extraction (extract.cc): a cell is
// global iff no voxel outside the window lies in its circumsphere, on-sphere voxels decided by the
// same symbolic perturbation as the triangulation's (lattice_side_of_sphere).
#include <cstdint>
#include <utility>
#include <vector>

#include "engine/extract/delaunay.h"

namespace sf::extract_detail {

// The circumball of a positively oriented lattice cell (false if it is not): centre offsets from p0
// are N / D with exact 128-bit numerators, then long double; certify() keeps a margin far above
// that rounding.
struct Ball {
  long double centre[3], radius;
};
bool circumball(const LatticePoint* p[4], Ball* out);

// Where voxels are: the occupied cells of a coarse grid over the lattice (cell side `side`), a
// compact stand-in for the voxels outside a window.
struct Occupancy {
  std::int64_t side = 1;
  std::vector<std::uint64_t> cells;  // sorted packed cell coordinates
  static std::uint64_t pack(std::int64_t x, std::int64_t y, std::int64_t z) {
    return (std::uint64_t(z) << 42) | (std::uint64_t(y) << 21) | std::uint64_t(x);
  }
};

// The voxels gathered around a window but outside it, bucketed by occupancy cell.
struct Outsiders {
  std::vector<std::pair<std::uint64_t, LatticePoint>> points;  // (packed cell, point), sorted
};

enum class Certificate { kGlobal, kNotGlobal, kUnknown };

// Is a cell of the window's triangulation, with circumball `ball`, a cell of the global one? The
// window holds every voxel in the lattice box [lo, hi]; `gathered` (a larger box) every voxel of
// which not in the window is in `out`; beyond it only the occupancy summary is known.
//  kGlobal     no voxel outside the window in or on the ball;
//  kNotGlobal  one inside: the cell is not global (and not one the brick owns: a cell
//              it owns has every vertex in the window);
//  kUnknown    the ball meets an occupied cell beyond `gathered` (or is a sliver's huge ball):
//              decide in a wider window.
// Voxels on the sphere are decided by CGAL's symbolic perturbation, as the global triangulation
// decides them.
Certificate certify(const Ball& ball, const LatticePoint* cell_points[4], const std::int64_t lo[3],
                    const std::int64_t hi[3], const std::int64_t glo[3], const std::int64_t ghi[3], const Outsiders& out,
                    const Occupancy& occ);

}  // namespace sf::extract_detail
