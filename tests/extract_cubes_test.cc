// Empty lattice cubes (engine/extract/lattice_cubes.h): their cells are CGAL's, and the cells of
// the triangulation of the voxels outside them whose centroids no empty cube covers are every
// other cell of the full tetrahedralization and nothing else.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <set>

#include "engine/extract/delaunay.h"
#include "engine/extract/lattice_cubes.h"

namespace sf::extract_detail {
namespace {

// A cell as its sorted point indices (the orientation is checked separately).
std::array<std::uint32_t, 4> sorted(Tet t) {
  std::sort(t.begin(), t.end());
  return t;
}

std::set<std::array<std::uint32_t, 4>> all_cells(const std::vector<LatticePoint>& points) {
  std::set<std::array<std::uint32_t, 4>> out;
  for (const Tet& t : delaunay_tetrahedra(points, false)) out.insert(sorted(t));
  return out;
}

int orientation(const std::vector<LatticePoint>& p, const Tet& t) {
  return lattice_orientation(p[t[0]], p[t[1]], p[t[2]], p[t[3]]);
}

const EmptyCubes::Holds kHoldsAll = [](int, const std::int64_t*, const std::int64_t*) { return true; };

// Cells from empty cubes plus the uncovered cells of the triangulation of the other points, as the
// brick extraction computes them.
std::set<std::array<std::uint32_t, 4>> cube_path_cells(const std::vector<LatticePoint>& points,
                                                         const std::vector<std::uint8_t>& level, int G,
                                                         std::size_t* interior_count = nullptr) {
  std::uint32_t levels = 0;
  for (std::uint8_t l : level) levels |= 1u << l;
  const EmptyCubes cubes(points, level, G, levels, kHoldsAll);
  std::vector<LatticePoint> rest;
  std::vector<std::uint32_t> index;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!cubes.interior(i)) {
      index.push_back(std::uint32_t(i));
      rest.push_back(points[i]);
    }
  }
  if (interior_count) *interior_count = points.size() - rest.size();
  std::set<std::array<std::uint32_t, 4>> out;
  for (const Tet& local : delaunay_tetrahedra(rest, false)) {
    const Tet t{index[local[0]], index[local[1]], index[local[2]], index[local[3]]};
    if (!cubes.covers(t)) out.insert(sorted(t));
  }
  for (const auto& corner : cubes.cubes())
    for (const auto& c : kCubeCells) {
      const Tet t{corner[c[0]], corner[c[1]], corner[c[2]], corner[c[3]]};
      EXPECT_GT(orientation(points, t), 0);
      out.insert(sorted(t));
    }
  return out;
}

TEST(ExtractCubes, UnitCubeCellsAreCgals) {
  std::vector<LatticePoint> corners;
  for (int c = 0; c < 8; ++c) corners.push_back({5 * (c & 1) + 3, 5 * (c >> 1 & 1) + 3, 5 * (c >> 2 & 1) + 3});
  std::set<std::array<std::uint32_t, 4>> expected = all_cells(corners), got;
  for (const auto& c : kCubeCells) {
    const Tet t{c[0], c[1], c[2], c[3]};
    EXPECT_GT(orientation(corners, t), 0);
    got.insert(sorted(t));
  }
  EXPECT_EQ(got, expected);
}

TEST(ExtractCubes, FullLatticeIsAllCubesWithItsInnerPointsInterior) {
  // 4^3 points of one level (h = 2 on a level-G lattice): 27 cubes, 8 interior points (index 1, 2).
  const int G = 5, l = 4;
  std::vector<LatticePoint> points;
  std::vector<std::uint8_t> level;
  for (int z = 0; z < 4; ++z)
    for (int y = 0; y < 4; ++y)
      for (int x = 0; x < 4; ++x) {
        points.push_back({2 * (x + 1), 2 * (y + 1), 2 * (z + 1)});
        level.push_back(std::uint8_t(l));
      }
  const EmptyCubes cubes(points, level, G, 1u << l, kHoldsAll);
  EXPECT_EQ(cubes.cubes().size(), 27u);
  std::size_t interior = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const bool inner = points[i][0] >= 4 && points[i][0] <= 6 && points[i][1] >= 4 && points[i][1] <= 6 &&
                       points[i][2] >= 4 && points[i][2] <= 6;
    EXPECT_EQ(cubes.interior(i), inner) << i;
    interior += cubes.interior(i);
  }
  EXPECT_EQ(interior, 8u);
  // Every cell of the full triangulation lies in a cube, and the cubes' cells are exactly them.
  for (const Tet& t : delaunay_tetrahedra(points, false)) EXPECT_TRUE(cubes.covers(t));
  EXPECT_EQ(cube_path_cells(points, level, G), all_cells(points));
}

TEST(ExtractCubes, CoversCentroidsInTheClosedCubes) {
  // One empty cube [2, 4]^3 of level G - 1 (h = 2). A cell's centroid (x, 2.75, 3.5) with x on the
  // cube's face x = 4, inside, or just outside it.
  const int G = 4;
  std::vector<LatticePoint> points;
  std::vector<std::uint8_t> level;
  for (int c = 0; c < 8; ++c) {
    points.push_back({2 * (c & 1) + 2, 2 * (c >> 1 & 1) + 2, 2 * (c >> 2 & 1) + 2});
    level.push_back(G - 1);
  }
  const EmptyCubes cubes(points, level, G, 1u << (G - 1), kHoldsAll);
  ASSERT_EQ(cubes.cubes().size(), 1u);
  const auto covers = [&](int x9) {  // centroid x = (2 + x9 + 4 + 4) / 4
    return cubes.covers({2, 3, 3}, {x9, 3, 3}, {4, 2, 3}, {4, 3, 5});
  };
  EXPECT_TRUE(covers(6));   // x = 4: on the face
  EXPECT_TRUE(covers(5));   // x = 3.75
  EXPECT_FALSE(covers(7));  // x = 4.25
  // The cube's own cells: centroids inside.
  for (const auto& c : kCubeCells) EXPECT_TRUE(cubes.covers(points[c[0]], points[c[1]], points[c[2]], points[c[3]]));
  // Below the lattice's origin side of the cube: y = 1.75.
  EXPECT_FALSE(cubes.covers({2, 1, 3}, {6, 1, 3}, {4, 0, 3}, {4, 5, 5}));
}

TEST(ExtractCubes, AFinerVoxelInsideTheSphereSpoilsTheCube) {
  // Cube [0, 4]^3 of level G - 2 (h = 4): centre (2, 2, 2), radius 2 sqrt(3) = 3.46.
  const int G = 6;
  std::vector<LatticePoint> points;
  std::vector<std::uint8_t> level;
  for (int c = 0; c < 8; ++c) {
    points.push_back({4 * (c & 1) + 8, 4 * (c >> 1 & 1) + 8, 4 * (c >> 2 & 1) + 8});
    level.push_back(G - 2);
  }
  const auto cubes_with = [&](LatticePoint finer) {
    std::vector<LatticePoint> p = points;
    std::vector<std::uint8_t> lv = level;
    p.push_back(finer);
    lv.push_back(G);
    return EmptyCubes(p, lv, G, (1u << G) | (1u << (G - 2)), kHoldsAll).cubes().size();
  };
  EXPECT_EQ(cubes_with({8 + 5, 8 + 2, 8 + 2}), 0u);  // 3 from the centre: inside
  EXPECT_EQ(cubes_with({8 + 6, 8 + 2, 8 + 2}), 1u);  // 4 from the centre: outside
  EXPECT_EQ(cubes_with({8 + 2, 8 + 2, 8 + 2}), 0u);  // the centre
  // Unless the set is known to hold every finer voxel near the cube, no cube is taken as empty.
  const EmptyCubes unsure(points, level, G, (1u << G) | (1u << (G - 2)),
                          [](int, const std::int64_t*, const std::int64_t*) { return false; });
  EXPECT_TRUE(unsure.cubes().empty());
  EXPECT_EQ(EmptyCubes(points, level, G, 1u << (G - 2), kHoldsAll).cubes().size(), 1u);
}

TEST(ExtractCubes, CubesPlusCertifiedRestGiveTheFullTetrahedralization) {
  // Two levels with holes: a coarse lattice (h = 4) over the whole block and a fine one (h = 1)
  // in a corner, off the coarse lattice (so that fine voxels lie in the spheres of complete coarse
  // cubes); fine points kept with probability 0.98, coarse ones with 0.93 where no fine one is
  // (the finest voxel wins a position).
  const int G = 6;
  for (unsigned seed = 1; seed <= 6; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(0, 1);
    std::vector<LatticePoint> points;
    std::vector<std::uint8_t> level;
    std::set<LatticePoint> taken;
    for (int z = 5; z <= 15; ++z)
      for (int y = 5; y <= 15; ++y)
        for (int x = 5; x <= 15; ++x)
          if (u(rng) < 0.98) {
            points.push_back({x, y, z});
            level.push_back(G);
            taken.insert(points.back());
          }
    for (int z = 0; z <= 8; ++z)
      for (int y = 0; y <= 8; ++y)
        for (int x = 0; x <= 8; ++x) {
          const LatticePoint p{4 * x, 4 * y, 4 * z};
          if (!taken.count(p) && u(rng) < 0.93) {
            points.push_back(p);
            level.push_back(G - 2);
          }
        }
    std::size_t interior = 0;
    EXPECT_EQ(cube_path_cells(points, level, G, &interior), all_cells(points)) << "seed " << seed;
    EXPECT_GT(interior, points.size() / 10) << "seed " << seed;  // the test says something
  }
}

TEST(ExtractCubes, PointsInKeyOrderGiveTheSameCubes) {
  // A window's members come in key order (level, z, y, x) and skip the sort; the cubes, the
  // interior points and the covered cells must not depend on the order. Two levels with holes.
  const int G = 5;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<LatticePoint> points;
  std::vector<std::uint8_t> level;
  std::set<LatticePoint> taken;
  for (int z = 4; z <= 12; ++z)
    for (int y = 4; y <= 12; ++y)
      for (int x = 4; x <= 12; ++x)
        if (u(rng) < 0.95) {
          points.push_back({x, y, z});
          level.push_back(G);
          taken.insert(points.back());
        }
  for (int z = 0; z <= 8; ++z)
    for (int y = 0; y <= 8; ++y)
      for (int x = 0; x <= 8; ++x)
        if (!taken.count({2 * x, 2 * y, 2 * z}) && u(rng) < 0.95) {
          points.push_back({2 * x, 2 * y, 2 * z});
          level.push_back(G - 1);
        }
  std::vector<std::uint32_t> order(points.size());
  for (std::uint32_t i = 0; i < order.size(); ++i) order[i] = i;
  const auto key = [&](std::uint32_t i) {
    const int s = G - level[i];
    return std::array<std::int64_t, 4>{level[i], points[i][2] >> s, points[i][1] >> s, points[i][0] >> s};
  };
  std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return key(a) < key(b); });
  ASSERT_NE(order.front(), 0u);  // the original order is not key order: both paths run
  std::vector<LatticePoint> sorted_points;
  std::vector<std::uint8_t> sorted_level;
  for (std::uint32_t i : order) {
    sorted_points.push_back(points[i]);
    sorted_level.push_back(level[i]);
  }
  const std::uint32_t levels = (1u << G) | (1u << (G - 1));
  const EmptyCubes a(points, level, G, levels, kHoldsAll);
  const EmptyCubes b(sorted_points, sorted_level, G, levels, kHoldsAll);
  std::set<std::array<std::uint32_t, 8>> cubes_a, cubes_b;
  for (const auto& c : a.cubes()) cubes_a.insert(c);
  for (auto c : b.cubes()) {
    for (std::uint32_t& i : c) i = order[i];
    cubes_b.insert(c);
  }
  EXPECT_EQ(cubes_a, cubes_b);
  EXPECT_GT(cubes_a.size(), 100u);
  std::size_t interior = 0;
  for (std::size_t s = 0; s < order.size(); ++s) {
    EXPECT_EQ(a.interior(order[s]), b.interior(s)) << s;
    interior += b.interior(s);
  }
  EXPECT_GT(interior, 50u);
  // Cells with corners of two levels are never covered; a cube's own cells are.
  for (const auto& corner : a.cubes()) {
    for (const auto& c : kCubeCells) EXPECT_TRUE(a.covers(Tet{corner[c[0]], corner[c[1]], corner[c[2]], corner[c[3]]}));
  }
  const auto& corner = a.cubes().front();
  std::uint32_t other = 0;
  while (level[other] == level[corner[0]]) ++other;
  EXPECT_FALSE(a.covers(Tet{corner[0], corner[1], corner[2], other}));
}

}  // namespace
}  // namespace sf::extract_detail
