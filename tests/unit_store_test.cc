// The out-of-core brick map: spilling under a tiny budget changes no voxel; a checkpoint restores
// exactly; a job directory takes one process at a time; sizes parse.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "engine/depth_frame.h"
#include "engine/error.h"
#include "engine/integrate.h"
#include "engine/triangulate.h"
#include "scheduler/job.h"
#include "storage/brick_map.h"
#include "storage/tile_store.h"
#include "tests/test_util.h"

namespace sf {
namespace {

// A wavy surface seen from `angle` around the y axis, 64x48 pixels.
DepthFrame wavy_view(double angle) {
  DepthFrame f;
  f.name = "wavy";
  f.width = 64;
  f.height = 48;
  f.sensor.fx = f.sensor.fy = 60;
  f.sensor.cx = 32;
  f.sensor.cy = 24;
  const Eigen::Vector3d C(2 * std::sin(angle), 0.1, -2 * std::cos(angle));
  const Eigen::Vector3d z = (-C).normalized(), x = Eigen::Vector3d::UnitY().cross(z).normalized();
  f.sensor.R.row(0) = x;
  f.sensor.R.row(1) = z.cross(x);
  f.sensor.R.row(2) = z;
  f.sensor.t = -f.sensor.R * C;
  std::vector<float> depth(f.size());
  for (int r = 0; r < f.height; ++r)
    for (int c = 0; c < f.width; ++c) depth[r * f.width + c] = float(1.8 + 0.05 * std::sin(0.3 * c) * std::cos(0.2 * r));
  fill_perspective_samples(f, depth, false);
  return f;
}

void expect_same_field(BrickMap& a, BrickMap& b) {
  std::size_t n = 0;
  for (Brick* br : a.bricks())
    br->voxels.for_each([&](VoxelKey k, const VoxelData& v) {
      const VoxelData* w = b.find(k);
      ASSERT_NE(w, nullptr);
      EXPECT_EQ(v.distance, w->distance);
      EXPECT_EQ(v.weight, w->weight);
      ++n;
    });
  EXPECT_EQ(n, b.voxel_count());
  EXPECT_GT(n, 1000u);
}

}  // namespace

TEST(BrickStore, SpillingUnderATinyBudgetChangesNoVoxel) {
  const auto dir = test::scratch_dir("store-spill");
  const RootCube root{Eigen::Vector3d(-1.5, -1.5, -1.5), 3.0};
  TileStore store(dir / "tiles");
  BrickMap plain(3), spilled(3);
  spilled.attach_store(&store, 1);  // one byte: every brick spills after every depth map
  for (int i = 0; i < 4; ++i) {
    const DepthFrame f = wavy_view(0.3 * i);
    const auto tris = triangulate(f, {});
    integrate_frame(f, tris, root, {}, plain);
    spilled.next_epoch();
    integrate_frame(f, tris, root, {}, spilled);
    spilled.enforce_limit();
    EXPECT_EQ(spilled.resident_bytes(), 0u);
  }
  // The running count of resident bytes (what enforce_limit reads) matches a recount; under a
  // budget of half the field, spilling stops at 7/8 of the budget.
  auto recount = [](BrickMap& m) {
    std::size_t n = 0;
    for (Brick* b : m.bricks())
      if (b->resident) n += b->voxels.memory_bytes() + sizeof(Brick);
    return n;
  };
  {
    BrickMap half(3);
    TileStore store2(dir / "tiles2");
    std::size_t full = 0;
    for (int i = 0; i < 4; ++i) {
      const DepthFrame f = wavy_view(0.3 * i);
      integrate_frame(f, triangulate(f, {}), root, {}, half);
      full = half.resident_bytes();
    }
    EXPECT_EQ(full, recount(half));
    EXPECT_GT(full, 100000u);
    half.attach_store(&store2, full / 2);
    half.enforce_limit();
    EXPECT_EQ(half.resident_bytes(), recount(half));
    EXPECT_LE(half.resident_bytes(), full / 2 - full / 16);
    EXPECT_GT(half.resident_bytes(), full / 4);
    // Reloaded bricks hold their voxels packed (a tile's reader carves from one chunk at a time
    // and sizes the index once), so they may take less than integration left them with.
    half.load_all();
    EXPECT_EQ(half.resident_bytes(), recount(half));
    EXPECT_LE(half.resident_bytes(), full);
    EXPECT_GT(half.resident_bytes(), full / 2);
  }
  EXPECT_GT(spilled.spill_stats().spilled, 10u);
  EXPECT_GT(spilled.spill_stats().reloaded, 10u);
  spilled.load_all();
  expect_same_field(plain, spilled);
  // Only the newest tile of each brick is left (no checkpoint holds older ones).
  std::size_t files = 0;
  for (auto& e : std::filesystem::directory_iterator(dir / "tiles")) files += e.is_regular_file() ? 1 : 0;
  EXPECT_EQ(files, spilled.brick_count());
}

TEST(BrickStore, CheckpointRestoresExactlyAndDropsLaterTiles) {
  const auto dir = test::scratch_dir("store-checkpoint");
  const RootCube root{Eigen::Vector3d(-1.5, -1.5, -1.5), 3.0};
  TileStore store(dir / "tiles");
  BrickMap map(3), reference(3);
  map.attach_store(&store, std::size_t{1} << 30);
  const DepthFrame f0 = wavy_view(0), f1 = wavy_view(0.5);
  integrate_frame(f0, triangulate(f0, {}), root, {}, map);
  integrate_frame(f0, triangulate(f0, {}), root, {}, reference);
  const std::vector<ManifestEntry> manifest = map.write_checkpoint();
  map.checkpoint_committed();
  const std::uint64_t max_generation = map.max_generation();
  // Work after the checkpoint, spilled to disk, then "a crash".
  map.next_epoch();
  integrate_frame(f1, triangulate(f1, {}), root, {}, map);
  map.attach_store(&store, 1);
  map.enforce_limit();
  std::set<std::pair<std::uint64_t, std::uint64_t>> keep;
  for (const auto& e : manifest) keep.insert({e.coord.packed(), e.generation});
  EXPECT_GT(store.remove_all_except(keep), 0u);
  BrickMap restored(3);
  restored.attach_store(&store, std::size_t{1} << 30);
  restored.restore(manifest, max_generation);
  restored.load_all();
  expect_same_field(reference, restored);
}

TEST(Job, ASecondProcessOnTheSameJobIsRefused) {
  const auto dir = test::scratch_dir("job-lock");
  JobOptions o;
  o.dir = dir / "job";
  Job first(o, "a = 1\n", "in", "out.ply");
  test::expect_input_error([&] { Job second(o, "a = 1\n", "in", "out.ply"); }, "job", "another scalefuse process");
}

// A rebuild reads only the depth maps whose recorded reach meets the damaged bricks; one with no
// record (a job of an earlier version, a cluster merge) may reach anything.
TEST(Job, DepthMapsReachingARegionFollowTheRecordedReach) {
  const auto dir = test::scratch_dir("job-reach");
  JobOptions o;
  o.dir = dir / "job";
  Job job(o, "a = 1\n", "in", "out.ply");
  // Depth maps 1..4 planned: 1 reaches bricks x,y,z in [0,2), 2 only brick (5,5,5), 3 nothing,
  // 4 bricks [2,4) x [0,1) x [0,1). Depth map 0 and 5 have no record.
  job.reached(1, {BrickBox{{0, 0, 0}, {2, 2, 2}}, BrickBox{{5, 5, 5}, {6, 6, 6}}, BrickBox{}, BrickBox{{2, 0, 0}, {4, 1, 1}}});
  const BrickBox brick_1_1_1{{1, 1, 1}, {2, 2, 2}};
  EXPECT_EQ(job.depth_maps_reaching(brick_1_1_1, 6), (std::vector<std::size_t>{0, 1, 5}));
  EXPECT_EQ(job.depth_maps_reaching(brick_1_1_1, 2), (std::vector<std::size_t>{0, 1}));  // the first 2 only
  // Boxes that touch without overlapping do not meet: [0,2) and [2,4) along x.
  const BrickBox brick_2_0_0{{2, 0, 0}, {3, 1, 1}};
  EXPECT_EQ(job.depth_maps_reaching(brick_2_0_0, 6), (std::vector<std::size_t>{0, 4, 5}));
  const BrickBox both{{1, 0, 0}, {6, 6, 6}};
  EXPECT_EQ(job.depth_maps_reaching(both, 6), (std::vector<std::size_t>{0, 1, 2, 4, 5}));
  // Planned again (a resumed sweep): the record is replaced, not added to.
  job.reached(2, {BrickBox{{1, 1, 1}, {2, 2, 2}}});
  EXPECT_EQ(job.depth_maps_reaching(brick_1_1_1, 6), (std::vector<std::size_t>{0, 1, 2, 5}));
}

TEST(Job, ByteSizes) {
  EXPECT_EQ(parse_byte_size("1.5G", "x"), std::size_t(1.5 * 1024 * 1024 * 1024));
  EXPECT_EQ(parse_byte_size("800M", "x"), std::size_t(800) * 1024 * 1024);
  EXPECT_EQ(parse_byte_size("64K", "x"), 65536u);
  EXPECT_EQ(parse_byte_size("12", "x"), 12u);
  EXPECT_THROW(parse_byte_size("abc", "x"), InputError);
  EXPECT_THROW(parse_byte_size("-1G", "x"), InputError);
  EXPECT_THROW(parse_byte_size("1X", "--memory-limit"), InputError);
}

}  // namespace sf
