// The Delaunay tetrahedralization of lattice points (massively cospherical) is unique: CGAL's
// symbolic perturbation makes it independent of insertion order and of parallel insertion.
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
