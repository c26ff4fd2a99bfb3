#include "storage/voxel_key.h"

#include <gtest/gtest.h>

#include <cmath>

#include <random>

#include "engine/geometry.h"

namespace sf {

TEST(VoxelKey, RoundTripsEveryLevelAndExtremeCoordinates) {
  for (int level = 0; level <= kMaxLevel; ++level) {
    const std::uint32_t n = 1u << level;
    for (std::uint32_t x : {0u, 1u, n / 2, n}) {
      const VoxelKey k = VoxelKey::make(level, x, n - x, n);
      EXPECT_EQ(k.level(), level);
      EXPECT_EQ(k.x(), x);
      EXPECT_EQ(k.y(), n - x);
      EXPECT_EQ(k.z(), n);
    }
  }
}

TEST(VoxelKey, RandomRoundTrip) {
  std::mt19937 rng(7);
  for (int i = 0; i < 10000; ++i) {
    const int level = int(rng() % (kMaxLevel + 1));
    const std::uint32_t n = (1u << level) + 1;
    const std::uint32_t x = rng() % n, y = rng() % n, z = rng() % n;
    const VoxelKey k = VoxelKey::make(level, x, y, z);
    ASSERT_EQ(k.level(), level);
    ASSERT_EQ(k.x(), x);
    ASSERT_EQ(k.y(), y);
    ASSERT_EQ(k.z(), z);
  }
}

TEST(VoxelKey, BitLayoutIsAsDocumented) {
  // level 3, x=5, y=6, z=7: 3<<57 | 7<<38 | 6<<19 | 5
  const VoxelKey k = VoxelKey::make(3, 5, 6, 7);
  EXPECT_EQ(k.bits, (3ull << 57) | (7ull << 38) | (6ull << 19) | 5ull);
}

TEST(VoxelKey, CoarserTwinAndFiner) {
  const VoxelKey k = VoxelKey::make(4, 6, 10, 2);
  ASSERT_TRUE(k.has_coarser_twin());
  EXPECT_EQ(k.coarser_twin(), VoxelKey::make(3, 3, 5, 1));
  EXPECT_EQ(k.coarser_twin().finer(), k);
  EXPECT_FALSE(VoxelKey::make(4, 6, 11, 2).has_coarser_twin());
  EXPECT_FALSE(VoxelKey::make(0, 0, 0, 0).has_coarser_twin());
}

TEST(VoxelKey, OrderIsLevelThenZYX) {
  EXPECT_LT(VoxelKey::make(2, 4, 4, 4), VoxelKey::make(3, 0, 0, 0));
  EXPECT_LT(VoxelKey::make(3, 7, 7, 0), VoxelKey::make(3, 0, 0, 1));
  EXPECT_LT(VoxelKey::make(3, 7, 0, 1), VoxelKey::make(3, 0, 1, 1));
}

TEST(RootCube, PositionOfVoxels) {
  RootCube root{Eigen::Vector3d(1, 2, 3), 8.0};
  EXPECT_DOUBLE_EQ(root.cell_size(3), 1.0);
  const Eigen::Vector3d p = root.position(VoxelKey::make(3, 1, 2, 8));
  EXPECT_DOUBLE_EQ(p.x(), 2.0);
  EXPECT_DOUBLE_EQ(p.y(), 4.0);
  EXPECT_DOUBLE_EQ(p.z(), 11.0);
}

TEST(RootCube, CellSizeIsExactlyLdexpAtEveryLevel) {
  for (double size : {1.0, 2.2, 1.7599661946296694, 1e-3, 123.456})
    for (int level = 0; level <= kMaxLevel; ++level) {
      const RootCube root{Eigen::Vector3d::Zero(), size};
      EXPECT_EQ(root.cell_size(level), std::ldexp(size, -level));
    }
  const RootCube eight{Eigen::Vector3d::Zero(), 8.0};
  EXPECT_EQ(eight.cell_size(18), 8.0 / 262144.0);
}

TEST(VoxelKey, ValidVoxel) {
  EXPECT_TRUE(valid_voxel(2, 4, 0, 4));
  EXPECT_FALSE(valid_voxel(2, 5, 0, 4));
  EXPECT_FALSE(valid_voxel(2, -1, 0, 4));
  EXPECT_FALSE(valid_voxel(kMaxLevel + 1, 0, 0, 0));
}

}  // namespace sf
