// Brick tiles on disk: round trip, byte-identical output whatever the insertion order, and every
// kind of damage detected with the tile's name.
#include "storage/tile_file.h"

#include <gtest/gtest.h>

#include <fstream>
#include <iterator>
#include <random>
#include <unistd.h>
#include <vector>

#include "engine/error.h"
#include "test_util.h"

namespace sf {
using namespace test;
namespace {

// Voxels of levels 2 (coarser than the brick level 3: single-voxel blocks), 4 (2^3 blocks) and 9
// (4^3 blocks), all in brick (2, 0, 2) of brick level 3.
std::vector<std::pair<VoxelKey, VoxelData>> sample_voxels() {
  std::vector<std::pair<VoxelKey, VoxelData>> v;
  auto add = [&](int level, std::uint32_t x, std::uint32_t y, std::uint32_t z, float d, float w) {
    VoxelData data;
    data.distance = d;
    data.weight = w;
    data.colour[0] = 10 * w;
    data.colour[1] = 200;
    data.colour[2] = d;
    data.colour_weight = w / 2;
    v.push_back({VoxelKey::make(level, x, y, z), data});
  };
  add(2, 1, 0, 1, 0.25f, 1.5f);
  add(4, 4, 0, 5, -0.01f, 0.3f);
  add(4, 5, 1, 4, 0.02f, 2.0f);
  for (std::uint32_t i = 0; i < 60; ++i) add(9, 128 + i, 3 + i % 5, 128 + (7 * i) % 60, 0.001f * float(i), 0.1f + float(i));
  add(9, 191, 63, 191, -0.5f, 0.01f);
  return v;
}

void fill(VoxelTable& t, const std::vector<std::pair<VoxelKey, VoxelData>>& voxels) {
  for (const auto& [k, d] : voxels) t.find_or_insert(k) = d;
}

std::vector<char> bytes_of(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::vector<char>(std::istreambuf_iterator<char>(in), {});
}

}  // namespace

TEST(Tile, RoundTripKeepsEveryVoxelAndIsIndependentOfInsertionOrder) {
  const auto dir = scratch_dir("tile_round_trip");
  const auto voxels = sample_voxels();
  for (const auto& [k, d] : voxels) {
    const BrickCoord b = brick_of(k, 3);
    ASSERT_EQ(b.x, 2u);
    ASSERT_EQ(b.y, 0u);
    ASSERT_EQ(b.z, 2u);
  }
  VoxelTable a(3);
  fill(a, voxels);
  const std::uint64_t size = write_tile(dir / "a.tile", {2, 0, 2}, a);
  EXPECT_EQ(size, std::filesystem::file_size(dir / "a.tile"));
  EXPECT_FALSE(std::filesystem::exists(dir / ("a.tile.tmp." + std::to_string(::getpid()))));

  auto shuffled = voxels;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(7));
  VoxelTable b(3);
  fill(b, shuffled);
  write_tile(dir / "b.tile", {2, 0, 2}, b);
  EXPECT_EQ(bytes_of(dir / "a.tile"), bytes_of(dir / "b.tile"));

  VoxelTable back(3);
  const BrickCoord c = read_tile(dir / "a.tile", back);
  EXPECT_EQ(c.x, 2u);
  EXPECT_EQ(c.z, 2u);
  EXPECT_EQ(back.live_count(), voxels.size());
  for (const auto& [k, d] : voxels) {
    const VoxelData* v = back.find(k);
    ASSERT_NE(v, nullptr);
    EXPECT_EQ(v->distance, d.distance);
    EXPECT_EQ(v->weight, d.weight);
    for (int ch = 0; ch < 3; ++ch) EXPECT_EQ(v->colour[ch], d.colour[ch]);
    EXPECT_EQ(v->colour_weight, d.colour_weight);
  }
  // Compression: 64 mostly empty 4^3 blocks of 24-byte voxels shrink well.
  EXPECT_LT(size, 0.5 * double(a.block_count() * 64 * 24));

  VoxelTable empty(3), empty_back(3);
  write_tile(dir / "empty.tile", {0, 0, 0}, empty);
  read_tile(dir / "empty.tile", empty_back);
  EXPECT_EQ(empty_back.block_count(), 0u);
}

TEST(Tile, EveryFlippedByteIsDetectedAndNamesTheTile) {
  const auto dir = scratch_dir("tile_damage");
  VoxelTable t(3);
  fill(t, sample_voxels());
  const auto good = dir / "brick_2_0_2.tile";
  write_tile(good, {2, 0, 2}, t);
  const std::vector<char> original = bytes_of(good);
  // Every header byte and a spread of payload bytes.
  std::vector<std::size_t> positions;
  for (std::size_t i = 0; i < 64; ++i) positions.push_back(i);
  for (std::size_t i = 64; i < original.size(); i += 7) positions.push_back(i);
  positions.push_back(original.size() - 1);
  for (std::size_t pos : positions) {
    std::vector<char> bytes = original;
    bytes[pos] ^= 0x10;
    const auto bad = dir / "flipped.tile";
    {
      std::ofstream out(bad, std::ios::binary);
      out.write(bytes.data(), std::streamsize(bytes.size()));
    }
    VoxelTable r(3);
    try {
      read_tile(bad, r);
      ADD_FAILURE() << "flipped byte " << pos << " not detected";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("flipped.tile: damaged tile"), std::string::npos) << e.what();
    }
  }
  EXPECT_GT(positions.size(), 80u);
}

// A job written before checksums moved to XXH3 (tile format 1: FNV-1a, otherwise the same bytes)
// resumes: its tiles still read. A tile of a later format is refused by name, not as damage.
TEST(Tile, FormatOneTilesStillReadAndLaterFormatsAreRefused) {
  const auto dir = scratch_dir("tile_versions");
  VoxelTable t(3);
  fill(t, sample_voxels());
  const auto path = dir / "v2.tile";
  write_tile(path, {2, 0, 2}, t);
  std::vector<char> bytes = bytes_of(path);
  auto rewrite = [&](std::uint32_t version, std::uint64_t (*checksum)(const void*, std::size_t)) {
    std::vector<char> b = bytes;
    unsigned char* h = reinterpret_cast<unsigned char*>(b.data());
    auto put = [](unsigned char* p, std::uint64_t v, int n) {
      for (int i = 0; i < n; ++i) p[i] = static_cast<unsigned char>(v >> (8 * i));
    };
    put(h + 8, version, 4);
    put(h + 48, checksum(h + 64, b.size() - 64), 8);
    put(h + 56, checksum(h, 56), 8);
    return b;
  };
  auto write_bytes = [](const std::filesystem::path& p, const std::vector<char>& b) {
    std::ofstream out(p, std::ios::binary);
    out.write(b.data(), std::streamsize(b.size()));
  };
  EXPECT_EQ(bytes[8], 2);  // this build writes format 2
  auto fnv = [](const void* d, std::size_t n) { return fnv1a64(d, n); };
  auto xxh3 = [](const void* d, std::size_t n) { return tile_checksum(2, d, n); };
  // The payload checksum really changed: FNV-1a and XXH3 differ on these bytes.
  ASSERT_NE(fnv(bytes.data() + 64, bytes.size() - 64), xxh3(bytes.data() + 64, bytes.size() - 64));
  write_bytes(dir / "v1.tile", rewrite(1, fnv));
  VoxelTable a(3), b(3);
  read_tile(path, a);
  read_tile(dir / "v1.tile", b);
  EXPECT_EQ(b.live_count(), a.live_count());
  for (const auto& [k, d] : sample_voxels()) {
    ASSERT_NE(b.find(k), nullptr);
    EXPECT_EQ(b.find(k)->distance, d.distance);
  }
  // Format 1 with XXH3 checksums, or format 2 with FNV-1a ones, is damage.
  write_bytes(dir / "mixed.tile", rewrite(1, xxh3));
  VoxelTable r(3);
  expect_input_error([&] { read_tile(dir / "mixed.tile", r); }, "mixed.tile", "header checksum mismatch");
  write_bytes(dir / "mixed2.tile", rewrite(2, fnv));
  expect_input_error([&] { read_tile(dir / "mixed2.tile", r); }, "mixed2.tile", "header checksum mismatch");
  write_bytes(dir / "v3.tile", rewrite(3, xxh3));
  expect_input_error([&] { read_tile(dir / "v3.tile", r); }, "v3.tile", "format version 3, this build reads 1 to 2");
}

TEST(Tile, TruncationWrongMagicAndWrongBrickLevelAreRefused) {
  const auto dir = scratch_dir("tile_refusals");
  VoxelTable t(3);
  fill(t, sample_voxels());
  const auto path = dir / "t.tile";
  write_tile(path, {2, 0, 2}, t);
  const std::vector<char> bytes = bytes_of(path);
  auto write_bytes = [&](const std::filesystem::path& p, std::size_t n) {
    std::ofstream out(p, std::ios::binary);
    out.write(bytes.data(), std::streamsize(n));
  };
  write_bytes(dir / "short.tile", bytes.size() - 3);
  VoxelTable r(3);
  expect_input_error([&] { read_tile(dir / "short.tile", r); }, "short.tile", "truncated");
  write_bytes(dir / "header.tile", 20);
  expect_input_error([&] { read_tile(dir / "header.tile", r); }, "header.tile", "shorter than its 64-byte header");
  write_text(dir / "text.tile", std::string(100, 'x'));
  expect_input_error([&] { read_tile(dir / "text.tile", r); }, "text.tile", "wrong magic");
  VoxelTable other_level(4);
  expect_input_error([&] { read_tile(path, other_level); }, "t.tile", "brick level 3, the job uses 4");
  expect_input_error([&] { read_tile(dir / "missing.tile", r); }, "missing.tile", "cannot open tile");
}

}  // namespace sf

namespace sf {

TEST(TileBuffers, ReusesMappingsAndKeepsNoMoreThanItsBudget) {
  constexpr std::size_t MiB = std::size_t{1} << 20;
  TileBuffers pool(3 * MiB);
  // Sizes round up to whole MiB, so similar tiles share a mapping.
  TileBuffers::Mapping a = pool.take(100);
  EXPECT_EQ(a.capacity, MiB);
  a.data[MiB - 1] = 7;  // the whole capacity is writable
  pool.give_back(a);
  EXPECT_EQ(pool.retained_bytes(), MiB);
  const TileBuffers::Mapping again = pool.take(500000);
  EXPECT_EQ(again.data, a.data);
  EXPECT_EQ(pool.retained_bytes(), 0u);
  const TileBuffers::Mapping two = pool.take(MiB + 1);  // none kept is large enough: a new one
  EXPECT_EQ(two.capacity, 2 * MiB);
  const TileBuffers::Mapping third = pool.take(MiB);
  EXPECT_NE(third.data, again.data);
  pool.give_back(again);
  pool.give_back(two);
  EXPECT_EQ(pool.retained_bytes(), 3 * MiB);
  // Over the budget, the smallest kept mappings go first: 1 + 1 + 2 MiB -> 1 + 2 MiB.
  pool.give_back(third);
  EXPECT_EQ(pool.retained_bytes(), 3 * MiB);
  EXPECT_EQ(pool.take(2 * MiB).capacity, 2 * MiB);  // the large one was kept
  // A mapping larger than the whole budget is never kept.
  pool.give_back(pool.take(4 * MiB));
  EXPECT_EQ(pool.retained_bytes(), MiB);

  TileBuffers none(0);
  none.give_back(none.take(10));
  EXPECT_EQ(none.retained_bytes(), 0u);
}

TEST(Tile, ReusedBuffersChangeNoByteOfATile) {
  const auto dir = test::scratch_dir("tile_buffers");
  // A large, poorly compressible brick, then a small one written and read through buffers the
  // large one left full of its own bytes.
  VoxelTable large(3), small(3);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0.01f, 1.f);
  for (std::uint32_t x = 128; x < 192; ++x)
    for (std::uint32_t y = 0; y < 64; ++y)
      for (std::uint32_t z = 128; z < 192; ++z) {
        VoxelData& v = large.find_or_insert(VoxelKey::make(9, x, y, z));
        v.distance = u(rng), v.weight = u(rng), v.colour_weight = u(rng);
      }
  fill(small, sample_voxels());
  TileBuffers pool(std::size_t{64} << 20);
  const std::uint64_t large_bytes = write_tile(dir / "large.tile", {2, 0, 2}, large, false, &pool);
  EXPECT_GT(large_bytes, std::uint64_t{1} << 20);  // its buffers outgrow the smallest mapping
  const std::size_t kept = pool.retained_bytes();
  EXPECT_GE(kept, std::size_t{2} << 20);  // its raw and compressed images, both kept
  write_tile(dir / "small_pool.tile", {2, 0, 2}, small, false, &pool);
  write_tile(dir / "small.tile", {2, 0, 2}, small);
  EXPECT_EQ(bytes_of(dir / "small_pool.tile"), bytes_of(dir / "small.tile"));
  EXPECT_EQ(pool.retained_bytes(), kept);  // the small tile took no new mapping

  VoxelTable large_back(3), small_back(3);
  read_tile(dir / "large.tile", large_back, &pool);
  EXPECT_EQ(large_back.live_count(), large.live_count());
  read_tile(dir / "small.tile", small_back, &pool);
  EXPECT_EQ(small_back.live_count(), small.live_count());
  small.for_each([&](VoxelKey k, const VoxelData& d) {
    const VoxelData* v = small_back.find(k);
    ASSERT_NE(v, nullptr);
    EXPECT_EQ(v->distance, d.distance);
    EXPECT_EQ(v->weight, d.weight);
  });
}

}  // namespace sf
