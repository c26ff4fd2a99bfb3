#pragma once
// Where the Delaunay tetrahedralization of the voxels is known without computing it.
//
// A ramp's band is mostly a full lattice of one level: the 8 corners of a lattice cube of side h
// are voxels of that level. The cube's circumsphere (centre at the cube's centre, radius
// sqrt(3)/2 h) holds no other voxel of its own or a coarser level (those are lattice points:
// the nearest non-corner one is at sqrt(11)/2 h), and no finer one lies on it (a point a multiple
// of h/2^j from the centre at distance sqrt(3)/2 h has all offsets +-h/2: a corner). So when no
// finer voxel lies inside it, the cube is a Delaunay polytope of all voxels, and the symbolic
// perturbation cuts it into the same 6 tetrahedra as an isolated unit cube (its decisions depend
// on the lexicographic order of the corners, the same in every cube): an empty cube.
//
// A voxel whose 8 surrounding cubes of its level are all empty cubes has every incident cell
// inside them: it can stay out of the triangulation. The triangulation of the others (S') holds
// every other global cell (its ball is empty of all voxels, a fortiori of a subset). Its cells
// that are not global lie inside the empty cubes: inserting the left-out voxels replaces exactly
// the cells in conflict with them, and the cells that replace them are the left-out voxels'
// stars, cube cells; both sets tile the same region. A global cell that overlaps an empty cube is
// one of its 6 cells (the cube is a Delaunay polytope). So a cell of S' is global and not a cube
// cell iff its interior misses every empty cube, iff its centroid (an interior point) lies in no
// closed empty cube (covers()). No ball is needed to tell them apart.
#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include "engine/extract/delaunay.h"
#include "engine/extract/flat_map.h"

namespace sf::extract_detail {

// The unit cube's Delaunay cells under CGAL's symbolic perturbation, positively oriented, corners
// numbered x + 2y + 4z (tests/extract_cubes_test.cc checks them against CGAL).
inline constexpr std::array<std::array<std::uint8_t, 4>, 6> kCubeCells{
    {{0, 1, 2, 4}, {1, 2, 4, 6}, {1, 2, 6, 3}, {1, 3, 6, 5}, {1, 4, 5, 6}, {3, 5, 7, 6}}};

class EmptyCubes {
 public:
  // points: lattice points (level G) of a set of voxels with distinct positions, level[i] their
  // octree levels; `levels`: bit l set iff some voxel anywhere has level l. holds(L, lo, hi): the
  // set holds every voxel of level L in the closed lattice box [lo, hi] (a cube is only taken as
  // empty when the set can show it).
  using Holds = std::function<bool(int level, const std::int64_t lo[3], const std::int64_t hi[3])>;
  EmptyCubes(const std::vector<LatticePoint>& points, const std::vector<std::uint8_t>& level, int G,
             std::uint32_t levels, const Holds& holds);

  // Each empty cube's corners (point indices, corner x + 2y + 4z).
  const std::vector<std::array<std::uint32_t, 8>>& cubes() const { return corners_; }
  // Point i's incident cells all lie in empty cubes.
  bool interior(std::size_t i) const { return interior_[i] == 0xFF; }
  // Does the closed union of the empty cubes hold the centroid of the cell (point indices, positive
  // volume)? For a cell of the triangulation of the non-interior points: it is then a cube's cell
  // or not global; otherwise it is a global cell (see above).
  //
  // Such a cell has its four corners on one level, the level of the cubes that cover it: a closed
  // empty cube of level l holds no voxel but its 8 corners (the rest of it is inside the sphere),
  // so closed empty cubes of different levels are disjoint (one's corners would lie in the
  // other), and a cell of the first kind is a cube's cell, one of the second kind lies in the
  // union of the stars of the left-out voxels (one level's cubes per connected part) and has
  // their corners as vertices. So only that level is looked up, and a cell of mixed levels, or
  // with a corner that is no empty cube's, is not covered.
  bool covers(const Tet& t) const;
  // The same for any four points of the lattice, looked up at every level.
  bool covers(const LatticePoint& a, const LatticePoint& b, const LatticePoint& c, const LatticePoint& d) const;

 private:
  // 4 x the centroid of the four points is in a closed empty cube of level l.
  bool covers_at(int l, const std::int64_t centroid4[3]) const;

  const std::vector<LatticePoint>& points_;
  const std::vector<std::uint8_t>& level_;
  int G_;
  std::vector<std::array<std::uint32_t, 8>> corners_;
  FlatMap cube_at_;  // cube key (level, minimum corner) -> index in corners_
  std::uint32_t cube_levels_ = 0;  // bit l: some empty cube of level l
  std::vector<std::uint8_t> interior_;  // per point: bit c set iff it is corner c of an empty cube
};

}  // namespace sf::extract_detail
