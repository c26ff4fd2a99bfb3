// The integration plan (scheduler/tile_plan.h): brick boxes, their voxel ranges, the cut into
// tiles, and integration restricted to a tile, which must give each voxel exactly what the whole
// depth map gives it.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <set>

#include "engine/depth_frame.h"
#include "engine/integrate.h"
#include "engine/triangulate.h"
#include "scheduler/tile_plan.h"
#include "storage/brick_map.h"

namespace sf {
namespace {

// A tilted, wavy depth map with a discontinuity, colours and confidences, seen off-axis.
DepthFrame wavy_frame() {
  DepthFrame f;
  f.name = "wavy";
  f.width = 37;
  f.height = 29;
  f.sensor.fx = 30;
  f.sensor.fy = 33;
  f.sensor.cx = 18.2;
  f.sensor.cy = 14.9;
  const Eigen::Vector3d C(0.31, -0.23, 0.07);
  const Eigen::Vector3d z = Eigen::Vector3d(0.45, 0.6, 1).normalized(), x = Eigen::Vector3d::UnitY().cross(z).normalized();
  f.sensor.R.row(0) = x;
  f.sensor.R.row(1) = z.cross(x);
  f.sensor.R.row(2) = z;
  f.sensor.t = -f.sensor.R * C;
  std::vector<float> depth(f.size());
  for (int r = 0; r < f.height; ++r)
    for (int c = 0; c < f.width; ++c)
      depth[r * f.width + c] = float(1.2 + 0.03 * c + 0.05 * std::sin(0.7 * r) + (c > 22 ? 0.5 : 0.0));
  fill_perspective_samples(f, depth, false);
  f.confidence.resize(f.size());
  for (std::size_t i = 0; i < f.size(); ++i) f.confidence[i] = float(0.5 + 0.5 * std::cos(0.1 * double(i)));
  return f;
}

// Every voxel of `a` is in `b` with the same bits, and the counts agree.
void expect_same_field(const BrickMap& a, const BrickMap& b) {
  std::size_t n = 0;
  for (Brick* br : a.bricks())
    br->voxels.for_each([&](VoxelKey k, const VoxelData& v) {
      const VoxelData* w = b.find(k);
      ASSERT_NE(w, nullptr) << "level " << k.level() << " voxel " << k.x() << "," << k.y() << "," << k.z();
      EXPECT_EQ(v.distance, w->distance);
      EXPECT_EQ(v.weight, w->weight);
      ++n;
    });
  EXPECT_EQ(n, b.voxel_count());
}

}  // namespace

TEST(BrickBox, VoxelRangeIsWhereBrickOfPutsTheVoxels) {
  // By hand: 4 bricks per axis (brick level 2), bricks 1..2 along x. Level 4 has 16 cells: voxels
  // 4..11. Level 1 has voxels 0, 1, 2 at bricks 0, 2 and 4 -> the last brick (3): only voxel 1.
  const BrickBox box{{1, 0, 0}, {3, 4, 4}};
  std::int64_t first, last;
  box.voxel_range(4, 2, 0, &first, &last);
  EXPECT_EQ(first, 4);
  EXPECT_EQ(last, 11);
  box.voxel_range(1, 2, 0, &first, &last);
  EXPECT_EQ(first, 1);
  EXPECT_EQ(last, 1);
  box.voxel_range(4, 2, 1, &first, &last);  // up to the root's upper face, which the last brick holds
  EXPECT_EQ(first, 0);
  EXPECT_EQ(last, 16);
  // Against brick_of, for every level, box and voxel along one axis.
  const int B = 3;
  for (int level = 0; level <= 6; ++level)
    for (std::uint32_t lo = 0; lo < 8; ++lo)
      for (std::uint32_t hi = lo + 1; hi <= 8; ++hi) {
        const BrickBox b{{lo, 0, 0}, {hi, 8, 8}};
        b.voxel_range(level, B, 0, &first, &last);
        for (std::uint32_t c = 0; c <= (1u << level); ++c) {
          const bool in = b.contains(brick_of(VoxelKey::make(level, c, 0, 0), B));
          EXPECT_EQ(in, std::int64_t(c) >= first && std::int64_t(c) <= last)
              << "level " << level << " box " << lo << ".." << hi << " voxel " << c;
        }
      }
}

TEST(BrickBox, ExtendHoldsEveryBrickAndMeetsNeedsASharedBrick) {
  BrickBox box;
  EXPECT_TRUE(box.empty());
  box.extend({3, 1, 4});
  EXPECT_FALSE(box.empty());
  EXPECT_EQ(box.lo.x, 3u); EXPECT_EQ(box.lo.y, 1u); EXPECT_EQ(box.lo.z, 4u);
  EXPECT_EQ(box.hi.x, 4u); EXPECT_EQ(box.hi.y, 2u); EXPECT_EQ(box.hi.z, 5u);
  box.extend({0, 5, 4});  // by hand: x 0..3, y 1..5, z 4 -> [0,4) x [1,6) x [4,5)
  EXPECT_EQ(box.lo.x, 0u); EXPECT_EQ(box.lo.y, 1u); EXPECT_EQ(box.lo.z, 4u);
  EXPECT_EQ(box.hi.x, 4u); EXPECT_EQ(box.hi.y, 6u); EXPECT_EQ(box.hi.z, 5u);
  EXPECT_TRUE(box.contains({2, 3, 4}));
  EXPECT_FALSE(box.contains({2, 3, 5}));
  // Sharing brick (3, 5, 4) meets; touching along x (x 4..) or z (z 5..) does not; nor does the empty box.
  EXPECT_TRUE(box.meets(BrickBox{{3, 5, 4}, {9, 9, 9}}));
  EXPECT_TRUE((BrickBox{{3, 5, 4}, {9, 9, 9}}).meets(box));
  EXPECT_FALSE(box.meets(BrickBox{{4, 0, 0}, {9, 9, 9}}));
  EXPECT_FALSE(box.meets(BrickBox{{0, 0, 5}, {9, 9, 9}}));
  EXPECT_FALSE(box.meets(BrickBox{}));
}

TEST(TilePlan, EstimatesBrickBytesFromSurfaceCells) {
  // Per surface cell: 0.3 x (8 x 8 x 1.5 level-l cells) x (1 + 0.5) x 8 ramp cells x 35 bytes
  // = 0.3 x 96 x 12 x 35 = 12096 bytes (mvs preset: gamma 8, behind 0.5).
  IntegrateOptions o;
  o.gamma = 8;
  o.behind = 0.5;
  const int brick_level = 3;  // a level-8 brick spans 32 voxels per axis
  const std::vector<VoxelKey> cells = {VoxelKey::make(8, 1, 1, 1), VoxelKey::make(8, 2, 1, 1),
                                       VoxelKey::make(8, 40, 1, 1)};
  const auto estimate = estimate_brick_bytes(cells, brick_level, o, {{BrickCoord{0, 0, 0}, 1000}},
                                             {BrickCoord{2, 0, 0}.packed()});
  ASSERT_EQ(estimate.size(), 3u);
  std::map<std::uint32_t, double> by_x;
  for (const auto& [c, bytes] : estimate) {
    EXPECT_EQ(c.y, 0u);
    EXPECT_EQ(c.z, 0u);
    by_x[c.x] = bytes;
  }
  EXPECT_NEAR(by_x.at(0), 2 * 12096.0 + 1000, 1e-6);  // two cells and the bytes it already holds
  EXPECT_NEAR(by_x.at(1), 12096.0, 1e-6);
  EXPECT_EQ(by_x.at(2), 0.0);  // reached, but no surface cell: listed with nothing
}

TEST(TilePlan, CutsTheLongestAxisAtTheWeightedMedian) {
  // Four bricks in a row along y, weights 1, 1, 1, 3, target 3: the median splits {y 0..2} from
  // {y 3}; the first half (3) fits. The grid is 8 bricks per axis; tiles cover it all.
  std::vector<std::pair<BrickCoord, double>> bricks = {
      {{2, 0, 5}, 1.0}, {{2, 1, 5}, 1.0}, {{2, 2, 5}, 1.0}, {{2, 3, 5}, 3.0}};
  const std::vector<BrickBox> tiles = cut_tiles(bricks, 3, 3.0);
  ASSERT_EQ(tiles.size(), 2u);
  EXPECT_EQ(tiles[0].lo.y, 0u);
  EXPECT_EQ(tiles[0].hi.y, 3u);
  EXPECT_EQ(tiles[1].lo.y, 3u);
  EXPECT_EQ(tiles[1].hi.y, 8u);
  EXPECT_EQ(tiles[0].hi.x, 8u);
  EXPECT_EQ(tile_of(tiles, {2, 2, 5}), 0u);
  EXPECT_EQ(tile_of(tiles, {7, 7, 7}), 1u);
  // One brick heavier than the target is a tile of its own; everything fits one tile.
  EXPECT_EQ(cut_tiles({{{1, 1, 1}, 10.0}}, 3, 1.0).size(), 1u);
  EXPECT_EQ(cut_tiles(bricks, 3, 6.0).size(), 1u);
}

TEST(TilePlan, EveryBrickLiesInExactlyOneTileWithinTheTarget) {
  std::vector<std::pair<BrickCoord, double>> bricks;
  for (std::uint32_t z = 0; z < 16; ++z)
    for (std::uint32_t y = 0; y < 16; ++y)
      for (std::uint32_t x = 0; x < 16; ++x)
        if ((x * 7 + y * 3 + z * 5) % 4 == 0) bricks.push_back({{x, y, z}, 1.0 + (x + y) % 3});
  const std::vector<BrickBox> tiles = cut_tiles(bricks, 4, 40.0);
  EXPECT_GT(tiles.size(), 10u);
  std::vector<double> load(tiles.size(), 0.0);
  for (const auto& [c, w] : bricks) {
    int holders = 0;
    for (const BrickBox& t : tiles) holders += t.contains(c);
    EXPECT_EQ(holders, 1);
    load[tile_of(tiles, c)] += w;
  }
  for (double l : load) EXPECT_LE(l, 40.0);
}

TEST(TilePlan, SplitsIntoExactlyNTilesOfEqualWork) {
  // Four bricks along x with work 1, 1, 1, 3 into 2 tiles: the share is 3, reached exactly by
  // cutting before x = 3 (left 3, right 3), not at the middle coordinate.
  std::vector<std::pair<BrickCoord, double>> row = {{{0, 4, 4}, 1.0}, {{1, 4, 4}, 1.0}, {{2, 4, 4}, 1.0}, {{3, 4, 4}, 3.0}};
  std::vector<BrickBox> two = split_tiles(row, 3, 2);
  ASSERT_EQ(two.size(), 2u);
  EXPECT_EQ(two[0].lo.x, 0u);
  EXPECT_EQ(two[0].hi.x, 3u);
  EXPECT_EQ(two[1].lo.x, 3u);
  EXPECT_EQ(two[1].hi.x, 8u);
  // 3 tiles: 1 left (share 2: cut at x = 2, work 2), 2 right ({x 2} work 1 and {x 3} work 3).
  std::vector<BrickBox> three = split_tiles(row, 3, 3);
  ASSERT_EQ(three.size(), 3u);
  EXPECT_EQ(three[0].hi.x, 2u);
  EXPECT_EQ(three[1].lo.x, 2u);
  EXPECT_EQ(three[1].hi.x, 3u);
  EXPECT_EQ(three[2].lo.x, 3u);
  // More tiles than occupied bricks: the rest are empty boxes, and still every brick has one tile.
  std::vector<BrickBox> many = split_tiles(row, 3, 6);
  ASSERT_EQ(many.size(), 6u);
  int empty = 0;
  for (const BrickBox& b : many) empty += empty_box(b);
  EXPECT_EQ(empty, 2);
  // The order of the input does not matter.
  std::vector<std::pair<BrickCoord, double>> reversed(row.rbegin(), row.rend());
  const std::vector<BrickBox> again = split_tiles(reversed, 3, 3);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(again[i].lo.packed(), three[i].lo.packed());
    EXPECT_EQ(again[i].hi.packed(), three[i].hi.packed());
  }
}

TEST(TilePlan, SplitTilesPartitionTheGridAndBalanceTheWork) {
  std::vector<std::pair<BrickCoord, double>> bricks;
  double total = 0;
  for (std::uint32_t z = 0; z < 16; ++z)
    for (std::uint32_t y = 0; y < 16; ++y)
      for (std::uint32_t x = 0; x < 16; ++x)
        if ((x * 7 + y * 3 + z * 5) % 4 == 0) {
          const double w = 1.0 + (x < 4 ? 20.0 : 0.0);  // a dense corner: balance by work, not by volume
          bricks.push_back({{x, y, z}, w});
          total += w;
        }
  for (std::size_t n : {1u, 2u, 3u, 5u, 8u}) {
    const std::vector<BrickBox> tiles = split_tiles(bricks, 4, n);
    ASSERT_EQ(tiles.size(), n);
    std::vector<double> load(n, 0.0);
    for (std::uint32_t z = 0; z < 16; ++z)
      for (std::uint32_t y = 0; y < 16; ++y)
        for (std::uint32_t x = 0; x < 16; ++x) {
          int holders = 0;
          for (const BrickBox& t : tiles) holders += t.contains({x, y, z});
          ASSERT_EQ(holders, 1) << "brick " << x << " " << y << " " << z << ", " << n << " tiles";
        }
    for (const auto& [c, w] : bricks) load[tile_of(tiles, c)] += w;
    for (double l : load) EXPECT_NEAR(l, total / double(n), 0.15 * total / double(n)) << n << " tiles";
  }
}

TEST(TilePlan, CutsWithinARegion) {
  const BrickBox region{{4, 0, 0}, {8, 8, 8}};
  std::vector<std::pair<BrickCoord, double>> bricks = {{{4, 1, 1}, 2.0}, {{7, 1, 1}, 2.0}};
  const std::vector<BrickBox> tiles = cut_tiles(bricks, 3, 2.0, &region);
  ASSERT_EQ(tiles.size(), 2u);
  for (const BrickBox& t : tiles) {
    EXPECT_GE(t.lo.x, 4u);
    EXPECT_LE(t.hi.x, 8u);
  }
  EXPECT_EQ(tile_of(tiles, {3, 1, 1}), tiles.size());  // outside the region
}

TEST(TilePlan, IntegratingTileByTileGivesTheWholeFieldAndReachCoversIt) {
  const DepthFrame f = wavy_frame();
  const auto tris = triangulate(f, {});
  const RootCube root{Eigen::Vector3d(-1, -1, 0), 3.3};
  IntegrateOptions opt;
  opt.gamma = 4.0;
  opt.coarser_levels = 3;
  for (bool prisms : {false, true}) {
    const int B = 4;
    BrickMap whole(B), tiled(B);
    if (prisms)
      integrate_frame_prisms(f, tris, root, opt, whole);
    else
      integrate_frame(f, tris, root, opt, whole);
    ASSERT_GT(whole.voxel_count(), 1000u);
    const FrameReach reach = frame_reach(f, tris, root, opt, B);
    std::set<std::uint64_t> reached(reach.bricks.begin(), reach.bricks.end());
    std::vector<std::pair<BrickCoord, double>> weights;
    for (Brick* b : whole.bricks()) {
      EXPECT_TRUE(reached.count(b->coord.packed())) << "a brick the depth map writes is missing from its reach";
      weights.push_back({b->coord, double(b->voxels.live_count())});
    }
    EXPECT_FALSE(reach.cells.empty());
    const std::vector<BrickBox> tiles = cut_tiles(weights, B, double(whole.voxel_count()) / 5);
    ASSERT_GE(tiles.size(), 4u);
    for (const BrickBox& t : tiles) {
      if (prisms)
        integrate_frame_prisms(f, tris, root, opt, tiled, &t);
      else
        integrate_frame(f, tris, root, opt, tiled, &t);
    }
    expect_same_field(whole, tiled);
  }
}

}  // namespace sf
