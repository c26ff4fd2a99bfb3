#pragma once
// Is a cell of a window's Delaunay tetrahedralization (a subset of the voxels) a cell of the
// tetrahedralization of all voxels? Used by the brick-by-brick extraction (extract.cc): a cell is
// global iff no voxel outside the window lies in its circumsphere, on-sphere voxels decided by the
// same symbolic perturbation as the triangulation's (lattice_side_of_sphere).
#include <cstdint>
#include <functional>
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

// The voxels outside the window in one occupied cell of the summary (the caller loads them on
// demand: only cells that a sphere reaching out of the window meets are ever asked for).
using OutsidePoints = std::function<const std::vector<LatticePoint>&(std::uint64_t packed_cell)>;

enum class Certificate { kGlobal, kNotGlobal, kUnknown };

// Is a cell of the window's triangulation, with circumball `ball`, a cell of the global one? The
// window holds every voxel in the lattice box [lo, hi]; `outside` gives the others by occupied cell.
//  kGlobal     no voxel outside the window in or on the ball;
//  kNotGlobal  one inside: the cell is not global (and not one the brick owns: a cell
//              it owns has every vertex in the window);
//  kUnknown    a sliver's huge ball (more than 65536 rows of summary cells): decide in a wider
//              window.
// Voxels on the sphere are decided by CGAL's symbolic perturbation, as the global triangulation
// decides them.
Certificate certify(const Ball& ball, const LatticePoint* cell_points[4], const std::int64_t lo[3],
                    const std::int64_t hi[3], const OutsidePoints& outside, const Occupancy& occ);

}  // namespace sf::extract_detail
