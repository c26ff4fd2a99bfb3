// The Delaunay tetrahedralization of lattice points (massively cospherical) is unique: CGAL's
// symbolic perturbation makes it independent of insertion order and of parallel insertion.
#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <Eigen/Dense>
#include <algorithm>
#include <random>

#include "engine/extract/delaunay.h"
#include "storage/voxel_key.h"

namespace sf {
namespace {

using extract_detail::delaunay_tetrahedra;
using extract_detail::DelaunayTetrahedralization;
using extract_detail::LatticePoint;
using extract_detail::Tet;

using KeyTet = std::array<std::uint64_t, 4>;

LatticePoint lattice_point(VoxelKey k) { return {std::int32_t(k.x()), std::int32_t(k.y()), std::int32_t(k.z())}; }

// The cells as sorted voxel-key quadruples, sorted: comparable across point orders.
std::vector<KeyTet> key_cells(const std::vector<VoxelKey>& keys, bool parallel) {
  std::vector<LatticePoint> points;
  for (VoxelKey k : keys) points.push_back(lattice_point(k));
  std::vector<KeyTet> out;
  for (const Tet& t : delaunay_tetrahedra(points, parallel)) {
    KeyTet k{keys[t[0]].bits, keys[t[1]].bits, keys[t[2]].bits, keys[t[3]].bits};
    std::sort(k.begin(), k.end());
    out.push_back(k);
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<VoxelKey> lattice(int level, int n, std::uint32_t offset) {
  std::vector<VoxelKey> keys;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) keys.push_back(VoxelKey::make(level, offset + x, offset + y, offset + z));
  return keys;
}

double det(const std::vector<LatticePoint>& p, const Tet& t) {
  Eigen::Matrix3d m;
  for (int c = 0; c < 3; ++c)
    for (int r = 0; r < 3; ++r) m(r, c) = double(p[t[c + 1]][r] - p[t[0]][r]);
  return m.determinant();
}

TEST(ExtractDelaunay, FullLatticeIsPositivelyOrientedAndFillsTheCube) {
  // The 6x6x6 lattice: every cell positively oriented, cells tile the 5^3 cube exactly.
  const std::vector<VoxelKey> keys = lattice(4, 6, 3);
  std::vector<LatticePoint> p;
  for (VoxelKey k : keys) p.push_back(lattice_point(k));
  const DelaunayTetrahedralization dt(p, false, nullptr);
  double volume = 0;
  std::size_t cells = 0;
  dt.for_each_cell([&](const Tet& t) {
    const double d = det(p, t);
    EXPECT_GT(d, 0);  // CGAL's positive orientation is det[p1-p0, p2-p0, p3-p0] > 0
    volume += d / 6;
    ++cells;
  });
  EXPECT_EQ(cells, dt.number_of_cells());
  EXPECT_NEAR(volume, 125.0, 1e-9);
  // Every lattice cube is split into 5 or 6 tetrahedra: 125 cubes.
  EXPECT_GE(cells, 5u * 125u);
  EXPECT_LE(cells, 6u * 125u);
}

TEST(ExtractDelaunay, PerturbedInSphereAgreesWithTheTriangulation) {
  // A 4x4x4 lattice (every cube's corners cospherical) plus a coarser level's points: every cell
  // of the triangulation has every other point outside its sphere under the symbolic
  // perturbation, which decides many points lying exactly on it; a cell that is not Delaunay has
  // a point inside.
  std::vector<LatticePoint> p;
  for (VoxelKey k : lattice(5, 4, 10)) p.push_back(lattice_point(k));
  for (VoxelKey k : lattice(4, 3, 4)) p.push_back({2 * std::int32_t(k.x()), 2 * std::int32_t(k.y()), 2 * std::int32_t(k.z())});
  std::sort(p.begin(), p.end());
  p.erase(std::unique(p.begin(), p.end()), p.end());
  const DelaunayTetrahedralization dt(p, false, nullptr);
  std::size_t on_sphere = 0, cells = 0;
  dt.for_each_cell([&](const Tet& t) {
    ++cells;
    const LatticePoint* c[4] = {&p[t[0]], &p[t[1]], &p[t[2]], &p[t[3]]};
    EXPECT_GT(extract_detail::lattice_orientation(*c[0], *c[1], *c[2], *c[3]), 0);
    Eigen::Vector3d centre;  // to count the degenerate tests
    {
      Eigen::Matrix3d a;
      Eigen::Vector3d b;
      for (int r = 0; r < 3; ++r) {
        for (int k = 0; k < 3; ++k) a(r, k) = 2.0 * ((*c[r + 1])[k] - (*c[0])[k]);
        double n1 = 0, n0 = 0;
        for (int k = 0; k < 3; ++k) {
          n1 += double((*c[r + 1])[k]) * (*c[r + 1])[k];
          n0 += double((*c[0])[k]) * (*c[0])[k];
        }
        b(r) = n1 - n0;
      }
      centre = a.colPivHouseholderQr().solve(b);
    }
    const double r2 = (Eigen::Vector3d((*c[0])[0], (*c[0])[1], (*c[0])[2]) - centre).squaredNorm();
    for (std::size_t i = 0; i < p.size(); ++i) {
      if (i == t[0] || i == t[1] || i == t[2] || i == t[3]) continue;
      if (std::abs((Eigen::Vector3d(p[i][0], p[i][1], p[i][2]) - centre).squaredNorm() - r2) < 1e-6) ++on_sphere;
      ASSERT_LT(extract_detail::lattice_side_of_sphere(c, p[i]), 0) << "cell " << cells << ", point " << i;
    }
  });
  EXPECT_GT(on_sphere, 100u) << "degenerate cases are the normal case on a lattice";
  // The cube spanned by three far corners of the fine lattice holds lattice points inside.
  const LatticePoint a{10, 10, 10}, b{13, 10, 10}, c{10, 13, 10}, d{10, 10, 13}, inner{11, 11, 11};
  const LatticePoint* big[4] = {&a, &b, &c, &d};
  ASSERT_GT(extract_detail::lattice_orientation(a, b, c, d), 0);
  EXPECT_GT(extract_detail::lattice_side_of_sphere(big, inner), 0);
}

TEST(ExtractDelaunay, UniqueOnLatticeSubsets) {
  // A 6x6x6 lattice with a third of the points removed (holes make many different cospherical
  // configurations), and a larger 16^3 one for the parallel insertion to have work.
  std::mt19937 rng(7);
  for (int n : {6, 16}) {
    std::vector<VoxelKey> keys = lattice(5, n, 2);
    std::shuffle(keys.begin(), keys.end(), rng);
    keys.resize(keys.size() * 2 / 3);
    SCOPED_TRACE("n = " + std::to_string(n));
    const std::vector<KeyTet> reference = key_cells(keys, false);
    ASSERT_GT(reference.size(), keys.size());
    for (int shuffle = 0; shuffle < 3; ++shuffle) {
      std::vector<VoxelKey> shuffled = keys;
      std::shuffle(shuffled.begin(), shuffled.end(), rng);
      EXPECT_EQ(key_cells(shuffled, false), reference) << "sequential, shuffle " << shuffle;
      tbb::task_arena arena(2);
      std::vector<KeyTet> parallel;
      arena.execute([&] { parallel = key_cells(shuffled, true); });
      EXPECT_EQ(parallel, reference) << "parallel, shuffle " << shuffle;
    }
  }
}

// Our traits replace CGAL's in-sphere and orientation predicates and decide cospherical cases
// themselves; stock CGAL (Epick's filtered predicates, Delaunay_triangulation_3's own symbolic
// perturbation) must build the same cells. Mixed levels (spacings 1, 2, 4 lattice units) give
// cospherical configurations of many shapes, not only unit cubes.
TEST(ExtractDelaunay, SameCellsAsStockCgal) {
  using K = CGAL::Exact_predicates_inexact_constructions_kernel;
  using Vb = CGAL::Triangulation_vertex_base_with_info_3<std::uint32_t, K>;
  using Tds = CGAL::Triangulation_data_structure_3<Vb>;
  using Stock = CGAL::Delaunay_triangulation_3<K, Tds>;
  using IndexTet = std::array<std::uint32_t, 4>;
  const auto sorted = [](IndexTet t) {
    std::sort(t.begin(), t.end());
    return t;
  };
  std::mt19937 rng(11);
  for (int round = 0; round < 6; ++round) {
    // Levels 6, 7, 8 of the same 16^3 region of the level-8 lattice, each thinned at random;
    // a position taken by a coarser level is not repeated.
    std::vector<LatticePoint> points;
    for (int level : {6, 7, 8}) {
      const int step = 1 << (8 - level), n = 16 / step;
      std::vector<LatticePoint> l;
      for (int z = 0; z < n; ++z)
        for (int y = 0; y < n; ++y)
          for (int x = 0; x < n; ++x) l.push_back({x * step, y * step, z * step});
      std::shuffle(l.begin(), l.end(), rng);
      l.resize(l.size() / std::size_t(2 + round % 3));
      for (const LatticePoint& p : l)
        if (std::find(points.begin(), points.end(), p) == points.end()) points.push_back(p);
    }
    SCOPED_TRACE("round " + std::to_string(round) + ", " + std::to_string(points.size()) + " points");
    std::vector<std::pair<K::Point_3, std::uint32_t>> with_info;
    for (std::size_t i = 0; i < points.size(); ++i)
      with_info.emplace_back(K::Point_3(points[i][0], points[i][1], points[i][2]), std::uint32_t(i));
    const Stock stock(with_info.begin(), with_info.end());
    std::vector<IndexTet> expected;
    for (auto c = stock.finite_cells_begin(); c != stock.finite_cells_end(); ++c)
      expected.push_back(sorted({c->vertex(0)->info(), c->vertex(1)->info(), c->vertex(2)->info(), c->vertex(3)->info()}));
    std::vector<IndexTet> ours;
    for (const Tet& t : delaunay_tetrahedra(points, false)) ours.push_back(sorted(t));
    std::sort(expected.begin(), expected.end());
    std::sort(ours.begin(), ours.end());
    ASSERT_GT(expected.size(), points.size());
    EXPECT_EQ(ours, expected);
  }
}

TEST(ExtractDelaunay, FewOrCoplanarPoints) {
  EXPECT_TRUE(delaunay_tetrahedra({}, false).empty());
  EXPECT_TRUE(delaunay_tetrahedra({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, false).empty());
  EXPECT_TRUE(delaunay_tetrahedra({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}}, true).empty());
  EXPECT_EQ(delaunay_tetrahedra({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, false).size(), 1u);
  EXPECT_THROW(delaunay_tetrahedra({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 0}}, false), std::invalid_argument);
  EXPECT_THROW(delaunay_tetrahedra({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, -1}}, false), std::invalid_argument);
}

}  // namespace
}  // namespace sf
