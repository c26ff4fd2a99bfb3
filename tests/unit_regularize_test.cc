// Section 6 on hand-built fields.
#include "engine/regularize.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <latch>
#include <map>
#include <memory>
#include <mutex>
#include <random>
#include <set>
#include <thread>

#include "storage/tile_store.h"
#include "test_util.h"

namespace sf {
namespace {
void put(BrickMap& m, VoxelKey k, float d, float w) {
  std::vector<Contribution> c{{k, d, w, {0, 0, 0}, false}};
  m.apply(c);
}
}  // namespace

TEST(Regularize, InterpolatesFromOneTwoFourOrEightCoarserVoxels) {
  BrickMap m(1);
  for (std::uint32_t z = 0; z < 2; ++z)
    for (std::uint32_t y = 0; y < 2; ++y)
      for (std::uint32_t x = 0; x < 2; ++x) put(m, VoxelKey::make(1, x, y, z), float(x + 2 * y + 4 * z), 1.0f);
  CoarseSample s;
  ASSERT_TRUE(interpolate_coarser(m, VoxelKey::make(2, 2, 0, 0), &s));  // coincides with (1,0,0)
  EXPECT_DOUBLE_EQ(s.distance, 1.0);
  ASSERT_TRUE(interpolate_coarser(m, VoxelKey::make(2, 1, 0, 0), &s));  // between 2
  EXPECT_DOUBLE_EQ(s.distance, 0.5);
  ASSERT_TRUE(interpolate_coarser(m, VoxelKey::make(2, 1, 1, 0), &s));  // between 4
  EXPECT_DOUBLE_EQ(s.distance, 1.5);
  ASSERT_TRUE(interpolate_coarser(m, VoxelKey::make(2, 1, 1, 1), &s));  // between 8
  EXPECT_DOUBLE_EQ(s.distance, 3.5);
  EXPECT_DOUBLE_EQ(s.weight, 1.0);
  EXPECT_FALSE(interpolate_coarser(m, VoxelKey::make(2, 3, 0, 0), &s));  // (1,0,0)-(2,0,0): missing
  EXPECT_FALSE(interpolate_coarser(m, VoxelKey::make(0, 0, 0, 0), &s));  // level 0 has no coarser
}

TEST(Regularize, BlendsDeletesAndRemovesDuplicates) {
  BrickMap m(1);
  put(m, VoxelKey::make(1, 0, 0, 0), 0.3f, 1.0f);
  put(m, VoxelKey::make(1, 1, 0, 0), 0.1f, 1.0f);
  put(m, VoxelKey::make(2, 1, 0, 0), 0.0f, 0.2f);   // between the two: coarse (0.2, 1)
  put(m, VoxelKey::make(2, 3, 0, 0), 0.05f, 0.05f); // coarse (2,0,0) missing, w < τ1: deleted
  put(m, VoxelKey::make(2, 5, 0, 0), 0.05f, 0.3f);  // missing coarse, τ1 <= w < τ0: kept as is
  put(m, VoxelKey::make(2, 2, 0, 0), -0.1f, 0.8f);  // confident, coincides with (1,1,0,0)
  RegularizeOptions opt;  // τ0 = 0.5, τ1 = 0.1
  const RegularizeStats st = regularize(m, opt, {});
  // Equations 4-5: k = (0.5 - 0.2) * min(1, 1/0.5) = 0.3, w = 0.5, d = (0 + 0.2 * 0.3) / 0.5 = 0.12.
  const VoxelData* v = m.find(VoxelKey::make(2, 1, 0, 0));
  ASSERT_NE(v, nullptr);
  EXPECT_NEAR(v->weight, 0.5, 1e-6);
  EXPECT_NEAR(v->distance, 0.12, 1e-6);
  EXPECT_EQ(m.find(VoxelKey::make(2, 3, 0, 0)), nullptr);
  v = m.find(VoxelKey::make(2, 5, 0, 0));
  ASSERT_NE(v, nullptr);
  EXPECT_FLOAT_EQ(v->weight, 0.3f);
  EXPECT_FLOAT_EQ(v->distance, 0.05f);
  // (1,1,0,0) coincides with (2,2,0,0): the coarser one goes; (1,0,0,0) has no finer twin: stays.
  EXPECT_EQ(m.find(VoxelKey::make(1, 1, 0, 0)), nullptr);
  EXPECT_NE(m.find(VoxelKey::make(1, 0, 0, 0)), nullptr);
  EXPECT_EQ(st.blended, 1u);
  EXPECT_EQ(st.deleted_unconfident, 1u);
  EXPECT_EQ(st.deleted_duplicates, 1u);
  EXPECT_EQ(st.voxels_after[1] + st.voxels_after[2], 4u);
}

TEST(Regularize, BlendsColourWithTheCoarseLevelsShare) {
  BrickMap m(1);
  auto put_coloured = [&](VoxelKey k, float d, float w, std::uint8_t r) {
    std::vector<Contribution> c{{k, d, w, {r, 0, 0}, true}};
    m.apply(c);
  };
  put_coloured(VoxelKey::make(1, 0, 0, 0), 0.3f, 1.0f, 100);
  put_coloured(VoxelKey::make(1, 1, 0, 0), 0.1f, 1.0f, 200);
  put_coloured(VoxelKey::make(2, 1, 0, 0), 0.0f, 0.2f, 0);  // between the two: coarse colour 150
  put(m, VoxelKey::make(1, 3, 0, 0), 0.3f, 1.0f);  // a colourless pair of coarse voxels
  put(m, VoxelKey::make(1, 4, 0, 0), 0.1f, 1.0f);
  put_coloured(VoxelKey::make(2, 7, 0, 0), 0.0f, 0.2f, 40);
  put_coloured(VoxelKey::make(1, 6, 0, 0), 0.3f, 1.0f, 60);
  put_coloured(VoxelKey::make(1, 7, 0, 0), 0.1f, 1.0f, 60);
  put(m, VoxelKey::make(2, 13, 0, 0), 0.0f, 0.2f);  // a colourless fine voxel between coloured ones
  RegularizeOptions opt;  // τ0 = 0.5, τ1 = 0.1
  regularize(m, opt, {});
  // k = 0.3 as above: colour (0 x 0.2 + 150 x 0.3) / 0.5 = 90, colour weight 0.5 = W.
  const VoxelData* v = m.find(VoxelKey::make(2, 1, 0, 0));
  ASSERT_NE(v, nullptr);
  EXPECT_NEAR(v->colour(0), 90.0f, 1.0f / 256);
  EXPECT_EQ(v->colour_share, VoxelData::kFullShare);
  // A coarse level without colour leaves the colour, and its weight 0.2 becomes 0.4 of W = 0.5.
  v = m.find(VoxelKey::make(2, 7, 0, 0));
  ASSERT_NE(v, nullptr);
  EXPECT_NEAR(v->weight, 0.5, 1e-6);
  EXPECT_EQ(v->colour(0), 40.0f);
  EXPECT_NEAR(v->colour_weight(), 0.2f, 1e-4f);
  // A colourless voxel takes the coarse colour 60 with weight k = 0.3, a share 0.6 of W = 0.5.
  v = m.find(VoxelKey::make(2, 13, 0, 0));
  ASSERT_NE(v, nullptr);
  EXPECT_EQ(v->colour(0), 60.0f);
  EXPECT_NEAR(v->colour_share, 0.6 * 65535, 1);
  EXPECT_NEAR(v->colour_weight(), 0.3f, 1e-4f);
}

TEST(Regularize, DuplicatesAcrossSeveralLevelsKeepTheFinest) {
  BrickMap m(0);
  put(m, VoxelKey::make(0, 1, 1, 1), 0.1f, 1.0f);
  put(m, VoxelKey::make(3, 8, 8, 8), 0.2f, 1.0f);  // same point, three levels finer, level 1-2 empty
  regularize(m, {0.0, 0.0}, {});
  EXPECT_EQ(m.find(VoxelKey::make(0, 1, 1, 1)), nullptr);
  EXPECT_NE(m.find(VoxelKey::make(3, 8, 8, 8)), nullptr);
}

namespace {
// A field over levels 0..7 around a sphere, dense enough that most voxels find their coarser
// neighbours, with weights spread over [0, 1.2) so that voxels are blended, deleted for lack of
// confidence and removed as duplicates at every level, brick corners and faces included.
void fill_shell(BrickMap& m, unsigned seed, const std::function<bool(VoxelKey)>& keep = nullptr) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  std::vector<Contribution> batch;
  for (int l = 0; l <= 7; ++l) {
    const std::uint32_t n = 1u << l;
    for (std::uint32_t z = 0; z <= n; ++z)
      for (std::uint32_t y = 0; y <= n; ++y)
        for (std::uint32_t x = 0; x <= n; ++x) {
          const double px = double(x) / n - 0.5, py = double(y) / n - 0.45, pz = double(z) / n - 0.55;
          const double r = std::sqrt(px * px + py * py + pz * pz) - 0.3;
          if (std::abs(r) > 3.0 / n + 0.02 || u(rng) < 0.1f) continue;
          Contribution c{VoxelKey::make(l, x, y, z), float(r), 1.2f * u(rng), {0, 0, 0}, true};
          for (auto& ch : c.colour) ch = std::uint8_t(255 * u(rng));
          if (!keep || keep(c.key)) batch.push_back(c);
        }
  }
  m.apply(batch);
}

std::map<std::uint64_t, VoxelData> field_of(const BrickMap& m) {
  std::map<std::uint64_t, VoxelData> out;
  for (Brick* b : m.bricks()) b->voxels.for_each([&](VoxelKey k, const VoxelData& v) { out[k.bits] = v; });
  return out;
}
}  // namespace

TEST(Regularize, BrickByBrickEqualsTheWholeFieldBitForBit) {
  BrickMap reference(0);
  fill_shell(reference, 7);
  const RegularizeOptions opt;  // τ0 = 0.5, τ1 = 0.1
  const RegularizeStats want = regularize(reference, opt, {});
  const auto expected = field_of(reference);
  ASSERT_GT(want.blended, 1000u);
  ASSERT_GT(want.deleted_unconfident, 100u);
  ASSERT_GT(want.deleted_duplicates, 1000u);
  const auto dir = test::scratch_dir("regularize-bricks");
  for (int brick_level : {0, 1, 2, 3, 5})
    for (bool spilled : {false, true}) {
      SCOPED_TRACE("brick level " + std::to_string(brick_level) + (spilled ? ", spilled" : ", in memory"));
      BrickMap m(brick_level);
      TileStore store(dir / ("tiles" + std::to_string(brick_level)));
      if (spilled) m.attach_store(&store, 1);
      fill_shell(m, 7);
      if (spilled) m.spill_all();
      std::map<std::uint64_t, VoxelData> got;
      std::set<std::uint64_t> bricks_seen;
      const RegularizeStats st = regularize_bricks(m, opt, {}, [&](BrickCoord c, std::vector<std::pair<VoxelKey, VoxelData>>&& v) {
        EXPECT_TRUE(bricks_seen.insert(c.packed()).second);
        for (const auto& [k, d] : v) {
          EXPECT_EQ(brick_of(k, brick_level).packed(), c.packed());
          got[k.bits] = d;
        }
      });
      ASSERT_EQ(got.size(), expected.size());
      for (const auto& [k, v] : expected) {
        const auto it = got.find(k);
        ASSERT_NE(it, got.end()) << VoxelKey{k}.level();
        ASSERT_EQ(std::memcmp(&it->second, &v, sizeof v), 0) << "level " << VoxelKey{k}.level();
      }
      EXPECT_EQ(st.blended, want.blended);
      EXPECT_EQ(st.deleted_unconfident, want.deleted_unconfident);
      EXPECT_EQ(st.deleted_duplicates, want.deleted_duplicates);
      for (int l = 0; l <= kMaxLevel; ++l) {
        EXPECT_EQ(st.voxels_before[l], want.voxels_before[l]);
        EXPECT_EQ(st.voxels_after[l], want.voxels_after[l]);
      }
    }
}

// A cluster's tiles: each holds some bricks' field, gives its boundary (regularize_boundary), and
// regularizes its bricks with every tile's boundary: the whole field's result, bit for bit.
TEST(Regularize, TilesWithEachOthersBoundaryEqualTheWholeField) {
  BrickMap reference(0);
  fill_shell(reference, 7);
  const RegularizeOptions opt;
  regularize(reference, opt, {});
  const auto expected = field_of(reference);
  const int B = 3;
  // Four tiles, cut at brick x = 4 and y = 3 (not a power of two).
  const auto tile_of = [&](VoxelKey k) {
    const BrickCoord c = brick_of(k, B);
    return (c.x < 4 ? 0 : 1) + (c.y < 3 ? 0 : 2);
  };
  std::vector<std::unique_ptr<BrickMap>> tiles;
  RegularizeBoundary boundary;
  std::map<std::uint64_t, std::vector<RawVoxel>> faces;
  std::size_t bricks = 0;
  for (int t = 0; t < 4; ++t) {
    tiles.push_back(std::make_unique<BrickMap>(B));
    fill_shell(*tiles.back(), 7, [&](VoxelKey k) { return tile_of(k) == t; });
    bricks += tiles.back()->brick_count();
    regularize_boundary(*tiles.back(), [&](BrickCoord c, std::vector<RawVoxel>&& low, std::vector<RawVoxel>&& f) {
      for (const RawVoxel& r : low) {
        EXPECT_LE(r.key.level(), B);
        boundary.coarse.push_back(r);
      }
      for (const RawVoxel& r : f) {
        EXPECT_GT(r.key.level(), B);
        EXPECT_EQ(brick_of(r.key, B).packed(), c.packed());
      }
      EXPECT_TRUE(faces.emplace(c.packed(), std::move(f)).second);
    });
  }
  ASSERT_GT(bricks, 100u);
  ASSERT_GT(boundary.coarse.size(), 10u);
  boundary.faces = [&](BrickCoord c, const std::function<void(const RawVoxel&)>& fn) {
    const auto it = faces.find(c.packed());
    if (it != faces.end())
      for (const RawVoxel& r : it->second) fn(r);
  };
  std::map<std::uint64_t, VoxelData> got;
  for (auto& tile : tiles)
    regularize_bricks(*tile, opt, {}, [&](BrickCoord, std::vector<std::pair<VoxelKey, VoxelData>>&& v) {
      for (const auto& [k, d] : v) EXPECT_TRUE(got.emplace(k.bits, d).second);
    }, nullptr, &boundary);
  ASSERT_EQ(got.size(), expected.size());
  for (const auto& [k, v] : expected) {
    const auto it = got.find(k);
    ASSERT_NE(it, got.end()) << VoxelKey{k}.level();
    ASSERT_EQ(std::memcmp(&it->second, &v, sizeof v), 0) << "level " << VoxelKey{k}.level();
  }
}

TEST(BrickMap, BrickOfVoxelsOfAllLevels) {
  // Brick level 2: 4 bricks per axis.
  EXPECT_EQ(brick_of(VoxelKey::make(4, 15, 0, 8), 2).x, 3u);
  EXPECT_EQ(brick_of(VoxelKey::make(4, 16, 0, 8), 2).x, 3u);  // upper root face -> last brick
  EXPECT_EQ(brick_of(VoxelKey::make(4, 4, 0, 8), 2).x, 1u);
  EXPECT_EQ(brick_of(VoxelKey::make(4, 4, 0, 8), 2).z, 2u);
  EXPECT_EQ(brick_of(VoxelKey::make(1, 1, 0, 0), 2).x, 2u);   // coarse voxel at the middle
}

TEST(VoxelTable, BlockShapeFollowsTheBrickLevel) {
  // Brick level 4: level 4 and coarser get single voxels, level 5 and finer 2^3 blocks in memory
  // (never straddling a brick: a brick holds 2^(l - 4) voxels of level l per axis); tiles keep
  // 4^3 blocks from level 6.
  EXPECT_EQ(block_log(2, 4), 0);
  EXPECT_EQ(block_log(4, 4), 0);
  EXPECT_EQ(block_log(5, 4), 1);
  EXPECT_EQ(block_log(6, 4), 1);
  EXPECT_EQ(block_log(12, 4), kMaxBlockLog);
  EXPECT_EQ(tile_block_log(4, 4), 0);
  EXPECT_EQ(tile_block_log(5, 4), 1);
  EXPECT_EQ(tile_block_log(6, 4), 2);
  EXPECT_EQ(tile_block_log(12, 4), kTileBlockLog);
  EXPECT_EQ(aligned_origin(VoxelKey::make(9, 13, 6, 7), 2), VoxelKey::make(9, 12, 4, 4));
  VoxelTable t(4);
  EXPECT_EQ(t.block_origin(VoxelKey::make(9, 13, 6, 7)), VoxelKey::make(9, 12, 6, 6));
  EXPECT_EQ(t.block_origin(VoxelKey::make(5, 13, 6, 7)), VoxelKey::make(5, 12, 6, 6));
  EXPECT_EQ(t.block_origin(VoxelKey::make(4, 13, 6, 7)), VoxelKey::make(4, 13, 6, 7));
  t.find_or_insert(VoxelKey::make(9, 13, 6, 7)).weight = 2;
  EXPECT_EQ(t.block_count(), 1u);
  EXPECT_EQ(t.find(VoxelKey::make(9, 12, 6, 7)), nullptr);  // same block, never written: absent
  ASSERT_NE(t.find(VoxelKey::make(9, 13, 6, 7)), nullptr);
  EXPECT_EQ(t.live_count(), 1u);
}

// Integration holds pointers into blocks while other blocks are made (voxel_table.h): the arena's
// chunks never move, however many blocks and index growths follow.
TEST(VoxelTable, PointersIntoBlocksOutliveGrowth) {
  VoxelTable t(4);
  const VoxelKey first = VoxelKey::make(10, 5, 6, 7);
  VoxelData* const held = &t.find_or_insert(first);
  held->weight = 1;
  const std::size_t bytes = t.memory_bytes();
  for (std::uint32_t i = 0; i < 20000; ++i) t.find_or_insert(VoxelKey::make(10, 64 + i % 200, i / 200, 9)).weight = 2;
  EXPECT_GT(t.memory_bytes(), 20 * bytes);  // many chunks and a much larger index since
  held->distance = 0.25f;
  held->weight = 3;
  ASSERT_NE(t.find(first), nullptr);
  EXPECT_EQ(t.find(first), held);
  EXPECT_EQ(t.find(first)->distance, 0.25f);
  EXPECT_EQ(t.live_count(), 20001u);
}

TEST(VoxelTable, GroupBlocksMapToTheirTileBlock) {
  // Voxel i of block o of a group (q = 8 o + i; o and i both x + 2 y + 4 z) against its place
  // (x + 4 y + 16 z) in the 4^3 tile block, worked out by hand.
  EXPECT_EQ(kGroupToTile[0], 0);
  EXPECT_EQ(kGroupToTile[1], 1);        // block 0, x 1
  EXPECT_EQ(kGroupToTile[8], 2);        // block 1 (x 2), voxel 0
  EXPECT_EQ(kGroupToTile[8 * 2 + 1], 9);   // block 2 (y 2), x 1: 1 + 4 * 2
  EXPECT_EQ(kGroupToTile[8 * 4 + 6], 52);  // block 4 (z 2), y 1 z 1: 4 * 1 + 16 * 3
  EXPECT_EQ(kGroupToTile[63], 63);
  for (int q = 0; q < 64; ++q) EXPECT_EQ(kTileToGroup[kGroupToTile[q]], q);
}

TEST(VoxelTable, BlocksMadeByTwoThreadsAtOnceAreOnePerPlace) {
  // Integration makes a group's blocks without the brick's lock (make_part_shared): two threads
  // making the same blocks at once must get the same block for each place, every voxel either
  // writes must be found after, and the bytes each reports added, with those of groups made
  // meanwhile under the lock, must sum to the table's growth. Each thread on its own cursor, then
  // both on cursor 0, which group() also carves from (under the lock, growing it without taking
  // the lock) while the other thread carves without it. Plain threads started together by a
  // latch, so that they run at once whatever the task scheduler would do.
  for (const unsigned second_cursor : {1u, 0u}) {
    SCOPED_TRACE(second_cursor);
    VoxelTable t(4);
    std::mutex lock;
    std::vector<BlockGroup*> groups;
    for (std::uint32_t i = 0; i < 4000; ++i) groups.push_back(t.group(VoxelKey::make(10, 4 * i, 0, 0), true));
    const std::size_t before = t.memory_bytes();
    std::vector<VoxelData*> made[2];
    std::int64_t grown[2] = {0, 0}, grown_by_groups = 0;
    std::latch start(2);
    auto make = [&](int side, unsigned cursor) {
      start.arrive_and_wait();
      std::uint32_t more = 0;
      for (BlockGroup* g : groups) {
        for (int o = 0; o < 8; ++o) {
          VoxelData* v = t.make_part_shared(*g, o, 1, &lock, cursor, &grown[side]);
          v[side].weight = float(side + 1);  // voxel 0 by one thread, voxel 1 by the other
          made[side].push_back(v);
        }
        if (side == 0) {  // a new group now and then, as integration makes them
          std::lock_guard held(lock);
          const std::size_t m = t.memory_bytes();
          t.group(VoxelKey::make(10, 4 * more++, 8, 0), true);
          grown_by_groups += std::int64_t(t.memory_bytes() - m);
        }
      }
    };
    std::thread a(make, 0, 0u), b(make, 1, second_cursor);
    a.join();
    b.join();
    EXPECT_EQ(made[0], made[1]);
    EXPECT_EQ(t.group_count(), 2 * groups.size());
    EXPECT_EQ(t.block_count(), groups.size() * 8);
    EXPECT_EQ(t.memory_bytes(), before + std::size_t(grown[0] + grown[1] + grown_by_groups));
    for (std::uint32_t i = 0; i < 4000; ++i)
      for (std::uint32_t x = 0; x < 4; x += 2)
        for (std::uint32_t y = 0; y < 4; y += 2)
          for (std::uint32_t z = 0; z < 4; z += 2) {
            const VoxelData* va = t.find(VoxelKey::make(10, 4 * i + x, y, z));
            const VoxelData* vb = t.find(VoxelKey::make(10, 4 * i + x + 1, y, z));
            ASSERT_TRUE(va && vb);
            EXPECT_EQ(va->weight, 1.0f);
            EXPECT_EQ(vb->weight, 2.0f);
          }
  }
}

TEST(VoxelTable, AMovedFromTableIsEmptyAndUsable) {
  VoxelTable a(4);
  a.find_or_insert(VoxelKey::make(10, 5, 6, 7)).weight = 3;
  VoxelTable b(std::move(a));
  EXPECT_EQ(a.group_count(), 0u);
  EXPECT_EQ(a.block_count(), 0u);
  EXPECT_EQ(a.memory_bytes(), 0u);
  a.find_or_insert(VoxelKey::make(10, 1, 2, 3)).weight = 1;  // carves a chunk of its own
  EXPECT_EQ(a.live_count(), 1u);
  ASSERT_NE(b.find(VoxelKey::make(10, 5, 6, 7)), nullptr);
  EXPECT_EQ(b.find(VoxelKey::make(10, 5, 6, 7))->weight, 3.0f);
  EXPECT_EQ(b.find(VoxelKey::make(10, 1, 2, 3)), nullptr);
  VoxelTable c(4);
  c = std::move(b);
  EXPECT_EQ(b.live_count(), 0u);
  EXPECT_EQ(c.live_count(), 1u);
}

TEST(VoxelTable, GrowsFindsAndCompacts) {
  VoxelTable t(4);
  for (std::uint32_t i = 0; i < 1000; ++i) t.find_or_insert(VoxelKey::make(10, i, i % 7, 3)).weight = float(i + 1);
  EXPECT_EQ(t.live_count(), 1000u);
  // Level 10 with brick level 4: blocks of 2^3 voxels, so x = 0..999 spans 500 blocks, and y = 0..6
  // four (z = 3 one): a block per distinct pair (x / 2, y / 2).
  std::set<std::pair<std::uint32_t, std::uint32_t>> blocks;
  for (std::uint32_t i = 0; i < 1000; ++i) blocks.insert({i / 2, (i % 7) / 2});
  EXPECT_EQ(t.block_count(), blocks.size());
  for (std::uint32_t i = 0; i < 1000; i += 2) t.find(VoxelKey::make(10, i, i % 7, 3))->weight = -1;
  // Blocks left with erased voxels only are dropped: those whose voxels all had even x.
  std::set<std::pair<std::uint32_t, std::uint32_t>> kept;
  for (std::uint32_t i = 1; i < 1000; i += 2) kept.insert({i / 2, (i % 7) / 2});
  t.compact();
  EXPECT_EQ(t.block_count(), kept.size());
  EXPECT_LT(kept.size(), blocks.size());
  EXPECT_EQ(t.live_count(), 500u);
  EXPECT_EQ(t.find(VoxelKey::make(10, 2, 2, 3)), nullptr);
  ASSERT_NE(t.find(VoxelKey::make(10, 3, 3, 3)), nullptr);
  EXPECT_FLOAT_EQ(t.find(VoxelKey::make(10, 3, 3, 3))->weight, 4.0f);
}

}  // namespace sf
