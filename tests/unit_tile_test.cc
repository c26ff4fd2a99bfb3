// Brick tiles on disk: round trip, byte-identical output whatever the insertion order, and every
// kind of damage detected with the tile's name.
#include "storage/tile_file.h"
#include "storage/byte_planes.h"

#include <gtest/gtest.h>
#include <lz4.h>
#include <xxhash.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>
#include <fstream>
#include <iterator>
#include <map>
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
    const float colour[3] = {10 * w, 200, 100 * d};
    data.set_colour(colour, w / 2);
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

// A table's voxels as the tile format lays out blocks (docs/formats.md): 2^k voxels per axis with
// k = clamp(level - brick_level, 0, 2), x fastest, by origin key; whatever blocks the table keeps
// in memory.
struct TileBlock {
  VoxelKey origin;
  int log;
  std::array<VoxelData, 64> data{};
};
std::vector<TileBlock> tile_blocks(const VoxelTable& t) {
  std::map<std::uint64_t, TileBlock> by_origin;
  t.for_each_block([&](VoxelKey o, int log, const VoxelData* d) {
    const std::uint32_t edge = 1u << log;
    for (std::uint32_t z = 0, i = 0; z < edge; ++z)
      for (std::uint32_t y = 0; y < edge; ++y)
        for (std::uint32_t x = 0; x < edge; ++x, ++i) {
          if (d[i].weight == 0) continue;
          const int k = std::clamp(o.level() - t.brick_level(), 0, 2);
          const std::uint32_t vx = o.x() + x, vy = o.y() + y, vz = o.z() + z, m = ~((1u << k) - 1);
          const VoxelKey origin = VoxelKey::make(o.level(), vx & m, vy & m, vz & m);
          TileBlock& b = by_origin[origin.bits];
          b.origin = origin;
          b.log = k;
          b.data[(((vz - origin.z()) << k | (vy - origin.y())) << k) | (vx - origin.x())] = d[i];
        }
  });
  std::vector<TileBlock> out;
  for (const auto& [bits, b] : by_origin) out.push_back(b);
  return out;
}
std::vector<char> bytes_of(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::vector<char>(std::istreambuf_iterator<char>(in), {});
}

}  // namespace

// Byte planes of 16-byte units, worked by hand for two units: unit 0 is bytes 0..15, unit 1 is
// 100..115, so plane b is {b, 100 + b}; and a round trip through the vector path (16 units at a
// time) and the byte path (the 5 left over) on 37 units.
TEST(BytePlanes, PlaneBHoldsByteBOfEveryUnit) {
  unsigned char two[32], planes[32], back[32];
  for (int i = 0; i < 16; ++i) two[i] = static_cast<unsigned char>(i), two[16 + i] = static_cast<unsigned char>(100 + i);
  to_byte_planes(two, 2, planes);
  for (int b = 0; b < 16; ++b) {
    EXPECT_EQ(planes[2 * b], b);
    EXPECT_EQ(planes[2 * b + 1], 100 + b);
  }
  from_byte_planes(planes, 2, back);
  EXPECT_TRUE(std::equal(two, two + 32, back));
  constexpr std::size_t n = 37;
  std::vector<unsigned char> units(16 * n), p(16 * n), u(16 * n);
  std::mt19937 rng(3);
  for (unsigned char& c : units) c = static_cast<unsigned char>(rng());
  to_byte_planes(units.data(), n, p.data());
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t b = 0; b < 16; ++b) ASSERT_EQ(p[b * n + i], units[i * 16 + b]) << "unit " << i << " byte " << b;
  from_byte_planes(p.data(), n, u.data());
  EXPECT_EQ(u, units);
}

TEST(Tile, ABlockWithoutVoxelsSurvivesARoundTrip) {
  // A group made but never written (one 4^3 block of the tile with an empty mask) is read back as
  // a group, so that the brick's tile is the same whether or not it was spilled and reloaded; as
  // with the 4^3 table, which made the block.
  const auto dir = scratch_dir("tile_empty_block");
  const auto voxels = sample_voxels();
  VoxelTable a(3);
  fill(a, voxels);
  const VoxelKey near = voxels[3].first;  // level 9, in brick (2, 0, 2)
  const VoxelKey empty = VoxelKey::make(near.level(), near.x() ^ 32, near.y(), near.z());
  ASSERT_EQ(brick_of(empty, 3).x, 2u);
  ASSERT_GE(empty.level() - 3, kTileBlockLog) << "a level whose groups are eight blocks";
  ASSERT_EQ(a.group(empty, false), nullptr);
  const std::size_t groups = a.group_count();
  a.group(empty, true);
  write_tile(dir / "a.tile", {2, 0, 2}, a);
  VoxelTable back(3);
  read_tile(dir / "a.tile", back);
  EXPECT_EQ(back.group_count(), groups + 1);
  EXPECT_EQ(back.live_count(), voxels.size());
  write_tile(dir / "back.tile", {2, 0, 2}, back);
  EXPECT_EQ(bytes_of(dir / "a.tile"), bytes_of(dir / "back.tile"));
}

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
    for (int ch = 0; ch < 3; ++ch) EXPECT_EQ(v->colour_fixed[ch], d.colour_fixed[ch]);
    EXPECT_EQ(v->colour_share, d.colour_share);
  }
  // Compression: 64 mostly empty 4^3 blocks of 16-byte voxels shrink well.
  EXPECT_LT(size, 0.5 * double(tile_blocks(a).size() * 64 * 16));

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
namespace {

// A tile of format 1 or 2 (24-byte voxels: six float32), 3 (every voxel of a block in 16 bytes),
// 4 (a presence mask per block, the present voxels in 16 bytes; one LZ4 block) or 5 to 7 (the same
// raw payload in a chunk; 6 compresses its byte planes, 7 their halves apart), laid out here from
// the format's description rather than by this build's writer, which writes only the current format. With `colour`, every voxel's record of format 1-2 carries that float
// colour and colour weight instead of its own.
std::vector<char> wrap_tile(std::uint32_t version, BrickCoord coord, int brick_level, std::size_t block_count,
                            const std::vector<unsigned char>& raw);
// Byte planes of 16-byte units as the format describes them (byte b of unit i at b n + i), or back
// (`to_planes` false), a byte at a time: the tests' oracle, independent of storage/byte_planes.
std::vector<unsigned char> planes_by_hand(const std::vector<unsigned char>& in, bool to_planes) {
  std::vector<unsigned char> out = in;  // a tail short of a unit stays as it is
  const std::size_t n = in.size() / 16;
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t b = 0; b < 16; ++b) {
      if (to_planes)
        out[b * n + i] = in[i * 16 + b];
      else
        out[i * 16 + b] = in[b * n + i];
    }
  return out;
}

// Little-endian fields, as the tile format stores them.
void set_le(unsigned char* p, std::uint64_t v, int n) {
  for (int i = 0; i < n; ++i) p[i] = static_cast<unsigned char>(v >> (8 * i));
}
void put_le(std::vector<unsigned char>& out, std::uint64_t v, int n) {
  out.resize(out.size() + std::size_t(n));
  set_le(out.data() + out.size() - std::size_t(n), v, n);
}
template <typename Byte>
std::uint64_t get_le(const Byte* p, int n) {
  std::uint64_t v = 0;
  for (int i = 0; i < n; ++i) v |= std::uint64_t(static_cast<unsigned char>(p[i])) << (8 * i);
  return v;
}

// A tile of format 5 to 7 around raw chunks given one by one (sizes, checksums all valid), laid out
// from the format's description: each chunk behind its raw and stored sizes and the XXH3-64 of its
// stored bytes, LZ4 (at acceleration 4) of its raw bytes (5) or of their byte planes (6), or (7)
// the planes' first half at acceleration 4 and their second at 16, behind the u32 stored size of
// the first; the header's payload checksum is that of the chunk headers.
std::vector<char> chunked_tile(std::uint32_t version, BrickCoord coord, int brick_level, std::uint32_t block_count,
                               const std::vector<std::vector<unsigned char>>& chunks);

struct FloatColour {
  float colour[3];
  float weight;
};
std::vector<char> legacy_tile(std::uint32_t version, BrickCoord coord, const VoxelTable& t,
                              const FloatColour* colour = nullptr) {
  const std::vector<TileBlock> blocks = tile_blocks(t);
  std::vector<unsigned char> raw;
  auto put_float = [&](float f) {
    std::uint32_t u;
    std::memcpy(&u, &f, 4);
    put_le(raw, u, 4);
  };
  for (const TileBlock& b : blocks) {
    put_le(raw, b.origin.bits, 8);
    std::uint64_t mask = 0;
    for (std::size_t i = 0; i < (std::size_t{1} << (3 * b.log)); ++i) mask |= std::uint64_t(b.data[i].weight != 0) << i;
    if (version >= 4) put_le(raw, mask, 8);
    for (std::size_t i = 0; i < (std::size_t{1} << (3 * b.log)); ++i) {
      const VoxelData& v = b.data[i];
      if (version >= 4 && !(mask >> i & 1)) continue;
      put_float(v.distance);
      put_float(v.weight);
      if (version >= 3) {
        for (int c = 0; c < 3; ++c) put_le(raw, v.colour_fixed[c], 2);
        put_le(raw, v.colour_share, 2);
        continue;
      }
      for (int c = 0; c < 3; ++c) put_float(colour ? colour->colour[c] : v.colour(c));
      put_float(colour ? colour->weight : v.colour_weight());
    }
  }
  if (version >= 5)
    return chunked_tile(version, coord, t.brick_level(), std::uint32_t(blocks.size()),
                        raw.empty() ? std::vector<std::vector<unsigned char>>{} : std::vector<std::vector<unsigned char>>{raw});
  return wrap_tile(version, coord, t.brick_level(), blocks.size(), raw);
}

// A tile of format `version`: the 64-byte header (its own checksum computed here) and the stored payload.
std::vector<char> tile_bytes(std::uint32_t version, BrickCoord coord, int brick_level, std::size_t block_count,
                             std::uint64_t raw_bytes, const std::vector<unsigned char>& stored,
                             std::uint64_t payload_checksum) {
  std::vector<unsigned char> h;
  for (char c : std::string("SFTILE1\n")) h.push_back(static_cast<unsigned char>(c));
  put_le(h, version, 4);
  put_le(h, std::uint32_t(brick_level), 4);
  put_le(h, coord.x, 4);
  put_le(h, coord.y, 4);
  put_le(h, coord.z, 4);
  put_le(h, block_count, 4);
  put_le(h, raw_bytes, 8);
  put_le(h, stored.size(), 8);
  put_le(h, payload_checksum, 8);
  put_le(h, tile_checksum(version, h.data(), 56), 8);
  std::vector<char> out(h.begin(), h.end());
  out.insert(out.end(), stored.begin(), stored.end());
  return out;
}

// A tile of format 1 to 4 around the raw payload `raw` (LZ4, sizes, checksums all valid).
std::vector<char> wrap_tile(std::uint32_t version, BrickCoord coord, int brick_level, std::size_t block_count,
                            const std::vector<unsigned char>& raw) {
  std::vector<unsigned char> stored(std::size_t(LZ4_compressBound(int(raw.size()))));
  stored.resize(std::size_t(LZ4_compress_default(reinterpret_cast<const char*>(raw.data()),
                                                 reinterpret_cast<char*>(stored.data()), int(raw.size()),
                                                 int(stored.size()))));
  return tile_bytes(version, coord, brick_level, block_count, raw.size(), stored,
                    tile_checksum(version, stored.data(), stored.size()));
}

// A chunked tile around chunks already packed, each given as its raw size and stored bytes: each
// framed by its header (sizes and the XXH3-64 of the stored bytes), the payload checksum that of
// the chunk headers. Whether the stored bytes are sound is the caller's to choose.
struct PackedChunk {
  std::size_t raw_n;
  std::vector<unsigned char> stored;
};
std::vector<char> framed_tile(std::uint32_t version, BrickCoord coord, int brick_level, std::uint32_t block_count,
                              const std::vector<PackedChunk>& chunks) {
  std::vector<unsigned char> stored, chunk_headers;
  std::uint64_t raw_bytes = 0;
  for (const auto& [raw_n, packed] : chunks) {
    std::vector<unsigned char> header;
    put_le(header, raw_n, 4);
    put_le(header, packed.size(), 4);
    put_le(header, XXH3_64bits(packed.data(), packed.size()), 8);
    chunk_headers.insert(chunk_headers.end(), header.begin(), header.end());
    stored.insert(stored.end(), header.begin(), header.end());
    stored.insert(stored.end(), packed.begin(), packed.end());
    raw_bytes += raw_n;
  }
  return tile_bytes(version, coord, brick_level, block_count, raw_bytes, stored,
                    XXH3_64bits(chunk_headers.data(), chunk_headers.size()));
}

std::vector<char> chunked_tile(std::uint32_t version, BrickCoord coord, int brick_level, std::uint32_t block_count,
                               const std::vector<std::vector<unsigned char>>& chunks) {
  std::vector<PackedChunk> packed_chunks;
  for (const auto& raw : chunks) {
    const std::vector<unsigned char> input = version >= 6 ? planes_by_hand(raw, true) : raw;
    auto lz4 = [](const unsigned char* data, std::size_t size, int acceleration) {
      std::vector<unsigned char> out(static_cast<std::size_t>(LZ4_compressBound(int(size))));
      out.resize(std::size_t(LZ4_compress_fast(reinterpret_cast<const char*>(data), reinterpret_cast<char*>(out.data()),
                                               int(size), int(out.size()), acceleration)));
      return out;
    };
    std::vector<unsigned char> packed;
    if (version >= 7) {
      const std::size_t half = input.size() / 2;
      const std::vector<unsigned char> field = lz4(input.data(), half, 4), colour = lz4(input.data() + half, half, 16);
      put_le(packed, field.size(), 4);
      packed.insert(packed.end(), field.begin(), field.end());
      packed.insert(packed.end(), colour.begin(), colour.end());
    } else {
      packed = lz4(input.data(), input.size(), 4);
    }
    packed_chunks.push_back({raw.size(), std::move(packed)});
  }
  return framed_tile(version, coord, brick_level, block_count, packed_chunks);
}

void write_bytes(const std::filesystem::path& p, const std::vector<char>& b) {
  std::ofstream out(p, std::ios::binary);
  out.write(b.data(), std::streamsize(b.size()));
}

}  // namespace

TEST(Tile, OlderFormatsStillReadAndLaterFormatsAreRefused) {
  const auto dir = scratch_dir("tile_versions");
  VoxelTable t(3);
  fill(t, sample_voxels());
  const auto path = dir / "v7.tile";
  write_tile(path, {2, 0, 2}, t);
  const std::vector<char> bytes = bytes_of(path);
  EXPECT_EQ(bytes[8], 7);  // this build writes format 7
  // ... byte for byte as the format's description lays it out.
  EXPECT_EQ(bytes, legacy_tile(7, {2, 0, 2}, t));
  // Format 3's 16-byte voxels against formats 1-2's 24: the same voxels, a smaller raw payload;
  // format 4 keeps the present voxels only, behind a u64 mask per block.
  const std::vector<char> v2 = legacy_tile(2, {2, 0, 2}, t);
  const std::vector<char> v3 = legacy_tile(3, {2, 0, 2}, t);
  auto raw_size = [](const std::vector<char>& b) { return get_le(b.data() + 32, 8); };
  const std::size_t n_blocks = tile_blocks(t).size();
  const std::uint64_t records = n_blocks == 0 ? 0 : (raw_size(v2) - 8 * n_blocks) / 24;
  EXPECT_EQ(raw_size(v3), 8 * n_blocks + 16 * records);
  // Blocks: one at level 2 (1 voxel), one at level 4 (2^3), and at level 9 the 4^3 blocks the 61
  // voxels fall in; 64 voxels are present, far fewer than the records of format 3.
  EXPECT_EQ(raw_size(bytes), 16 * n_blocks + 16 * sample_voxels().size());
  EXPECT_LT(raw_size(bytes), raw_size(v3) / 4);
  write_bytes(dir / "v3.tile", v3);
  write_bytes(dir / "v2.tile", v2);
  write_bytes(dir / "v1.tile", legacy_tile(1, {2, 0, 2}, t));
  // Format 4 is format 6's raw payload in one LZ4 block; format 5 compressed the chunk's raw bytes.
  const std::vector<char> v4 = legacy_tile(4, {2, 0, 2}, t);
  EXPECT_EQ(raw_size(v4), raw_size(bytes));
  write_bytes(dir / "v4.tile", v4);
  const std::vector<char> v5 = legacy_tile(5, {2, 0, 2}, t);
  EXPECT_EQ(raw_size(v5), raw_size(bytes));
  write_bytes(dir / "v5.tile", v5);
  // Format 6 is format 7's planes as one LZ4 block.
  const std::vector<char> v6 = legacy_tile(6, {2, 0, 2}, t);
  EXPECT_EQ(raw_size(v6), raw_size(bytes));
  EXPECT_NE(std::vector<char>(v6.begin() + 64, v6.end()), std::vector<char>(bytes.begin() + 64, bytes.end()));
  write_bytes(dir / "v6.tile", v6);
  for (const char* name : {"v1.tile", "v2.tile", "v3.tile", "v4.tile", "v5.tile", "v6.tile", "v7.tile"}) {
    SCOPED_TRACE(name);
    VoxelTable b(3);
    read_tile(dir / name, b);
    EXPECT_EQ(b.live_count(), t.live_count());
    // The colour of a float voxel comes back exact: its fixed point was written as a float.
    for (const auto& [k, d] : sample_voxels()) {
      const VoxelData* v = b.find(k);
      ASSERT_NE(v, nullptr);
      EXPECT_EQ(v->distance, d.distance);
      EXPECT_EQ(v->weight, d.weight);
      for (int c = 0; c < 3; ++c) EXPECT_EQ(v->colour_fixed[c], d.colour_fixed[c]);
      EXPECT_EQ(v->colour_share, d.colour_share);
    }
  }
  // A format-2 voxel with any float colour: the nearest 1/256 step (12.3 x 256 = 3148.8 -> 3149;
  // 300 is no colour and clamps to the largest step), and the colour weight as a share of the
  // weight (0.5 / 2 x 65535 = 16383.75 -> 16384).
  VoxelTable one(3);
  const VoxelKey key = VoxelKey::make(9, 130, 5, 140);
  one.find_or_insert(key).weight = 2.0f;
  const FloatColour odd{{12.3f, 0.0f, 300.0f}, 0.5f};
  write_bytes(dir / "odd.tile", legacy_tile(2, {2, 0, 2}, one, &odd));
  VoxelTable odd_back(3);
  read_tile(dir / "odd.tile", odd_back);
  const VoxelData& v = *odd_back.find(key);
  EXPECT_EQ(v.colour_fixed[0], 3149);
  EXPECT_EQ(v.colour_fixed[1], 0);
  EXPECT_EQ(v.colour_fixed[2], 65535);
  EXPECT_EQ(v.colour_share, 16384);
  EXPECT_FLOAT_EQ(v.colour_weight(), 2.0f * 16384.0f / 65535.0f);
  EXPECT_FLOAT_EQ(v.colour(0), 3149.0f / 256.0f);
  // Format 1 with XXH3 checksums, or format 2 with FNV-1a ones, is damage.
  auto rewrite = [&](std::vector<char> b, std::uint32_t version, std::uint64_t (*checksum)(const void*, std::size_t)) {
    unsigned char* h = reinterpret_cast<unsigned char*>(b.data());
    set_le(h + 8, version, 4);
    set_le(h + 48, checksum(h + 64, b.size() - 64), 8);
    set_le(h + 56, checksum(h, 56), 8);
    return b;
  };
  auto fnv = [](const void* d, std::size_t n) { return fnv1a64(d, n); };
  auto xxh3 = [](const void* d, std::size_t n) { return tile_checksum(2, d, n); };
  // The payload checksum really changed: FNV-1a and XXH3 differ on these bytes.
  ASSERT_NE(fnv(v2.data() + 64, v2.size() - 64), xxh3(v2.data() + 64, v2.size() - 64));
  VoxelTable r(3);
  write_bytes(dir / "mixed.tile", rewrite(v2, 1, xxh3));
  expect_input_error([&] { read_tile(dir / "mixed.tile", r); }, "mixed.tile", "header checksum mismatch");
  write_bytes(dir / "mixed2.tile", rewrite(v2, 2, fnv));
  expect_input_error([&] { read_tile(dir / "mixed2.tile", r); }, "mixed2.tile", "header checksum mismatch");
  // A format-2 payload labelled format 3 is misread as 16-byte voxels: its length gives it away.
  write_bytes(dir / "relabelled.tile", rewrite(v2, 3, xxh3));
  expect_input_error([&] { read_tile(dir / "relabelled.tile", r); }, "relabelled.tile", "damaged tile");
  // A format-3 payload labelled format 4 reads its first voxel as a presence mask: refused.
  write_bytes(dir / "relabelled3.tile", rewrite(v3, 4, xxh3));
  expect_input_error([&] {
    VoxelTable fresh(3);
    read_tile(dir / "relabelled3.tile", fresh);
  }, "relabelled3.tile", "damaged tile");
  write_bytes(dir / "v8.tile", rewrite(bytes, 8, xxh3));
  expect_input_error([&] {
    VoxelTable fresh(3);
    read_tile(dir / "v8.tile", fresh);
  }, "v8.tile", "format version 8, this build reads 1 to 7");
}

// Format 4 stores a mask of the present voxels per block: erased voxels (weight < 0) are present
// and come back; absent ones (weight 0) are left out and read back as zeros; a mask that marks a
// voxel beyond the block, or a stored record with weight 0, is damage.
TEST(Tile, PresenceMaskKeepsErasedVoxelsAndRefusesImpossibleMasks) {
  const auto dir = scratch_dir("tile_presence");
  VoxelTable t(3);
  const VoxelKey live = VoxelKey::make(9, 130, 5, 140), erased = VoxelKey::make(9, 131, 5, 140),
                 absent = VoxelKey::make(9, 128, 5, 140);
  t.find_or_insert(live) = VoxelData{0.5f, 2.0f, {256, 512, 768}, 65535};
  t.find_or_insert(erased).weight = -1.0f;
  t.find_or_insert(absent).distance = 7.0f;  // weight 0: absent, whatever else it holds
  const VoxelKey negative_zero = VoxelKey::make(9, 129, 6, 141);
  t.find_or_insert(negative_zero).weight = -0.0f;  // 0 too
  write_tile(dir / "t.tile", {2, 0, 2}, t);
  VoxelTable back(3);
  read_tile(dir / "t.tile", back);
  ASSERT_EQ(back.block_count(), 1u);
  EXPECT_EQ(back.find(live)->distance, 0.5f);
  EXPECT_EQ(back.find(live)->colour_fixed[2], 768);
  EXPECT_EQ(back.find(erased)->weight, -1.0f);
  EXPECT_EQ(back.find(absent), nullptr);
  EXPECT_EQ(back.find(negative_zero), nullptr);
  EXPECT_EQ(back.find_or_insert(absent).distance, 0.0f);

  // One 4^3 block of level 9 at origin (128, 4, 140): voxel 2 + 4 * 1 + 16 * 0 = 6 is (130, 5, 140).
  auto raw_of = [](std::uint64_t origin, std::uint64_t mask, const std::vector<VoxelData>& records) {
    std::vector<unsigned char> raw;
    auto put = [&](std::uint64_t v, int n) {
      for (int i = 0; i < n; ++i) raw.push_back(static_cast<unsigned char>(v >> (8 * i)));
    };
    put(origin, 8);
    put(mask, 8);
    for (const VoxelData& v : records) {
      std::uint32_t u;
      std::memcpy(&u, &v.distance, 4);
      put(u, 4);
      std::memcpy(&u, &v.weight, 4);
      put(u, 4);
      for (int c = 0; c < 3; ++c) put(v.colour_fixed[c], 2);
      put(v.colour_share, 2);
    }
    return raw;
  };
  const std::uint64_t origin = VoxelKey::make(9, 128, 4, 140).bits;
  const VoxelData one{0.25f, 1.0f, {0, 0, 0}, 0};
  write_bytes(dir / "hand.tile", wrap_tile(4, {2, 0, 2}, 3, 1, raw_of(origin, std::uint64_t{1} << 6, {one})));
  VoxelTable hand(3);
  read_tile(dir / "hand.tile", hand);
  ASSERT_NE(hand.find(live), nullptr);
  EXPECT_EQ(hand.find(live)->distance, 0.25f);
  EXPECT_EQ(hand.live_count(), 1u);

  write_bytes(dir / "absent.tile", wrap_tile(4, {2, 0, 2}, 3, 1, raw_of(origin, 1, {VoxelData{}})));
  expect_input_error([&] {
    VoxelTable fresh(3);
    read_tile(dir / "absent.tile", fresh);
  }, "absent.tile", "stores an absent voxel");
  write_bytes(dir / "short.tile", wrap_tile(4, {2, 0, 2}, 3, 1, raw_of(origin, 3, {one})));
  expect_input_error([&] {
    VoxelTable fresh(3);
    read_tile(dir / "short.tile", fresh);
  }, "short.tile", "runs past the payload");
  // A level-4 block is 2^3 voxels: bit 8 lies beyond it.
  const std::uint64_t small = VoxelKey::make(4, 4, 0, 4).bits;
  write_bytes(dir / "beyond.tile", wrap_tile(4, {2, 0, 2}, 3, 1, raw_of(small, std::uint64_t{1} << 8, {one})));
  expect_input_error([&] {
    VoxelTable fresh(3);
    read_tile(dir / "beyond.tile", fresh);
  }, "beyond.tile", "marks voxels beyond its size");
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
  expect_input_error([&] {
    VoxelTable fresh(3);
    read_tile(dir / "short.tile", fresh);
  }, "short.tile", "truncated");
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
        v.distance = u(rng), v.weight = u(rng);
        for (std::uint16_t& c : v.colour_fixed) c = std::uint16_t(rng());
        v.colour_share = std::uint16_t(rng());
      }
  fill(small, sample_voxels());
  TileBuffers pool(std::size_t{64} << 20);
  const std::uint64_t large_bytes = write_tile(dir / "large.tile", {2, 0, 2}, large, false, &pool);
  EXPECT_GT(large_bytes, std::uint64_t{1} << 20);  // its buffers outgrow the smallest mapping
  const std::size_t kept = pool.retained_bytes();
  EXPECT_GE(kept, std::size_t{2} << 20);  // its raw and compressed chunk buffers, both kept
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

namespace {

// The raw chunks of a tile's bytes of format 5 to 7 (each decompressed; the planes of a chunk of
// format 6 or 7 put back into units).
std::vector<std::vector<unsigned char>> raw_chunks(const std::vector<char>& tile) {
  auto get32 = [&](std::size_t at) { return std::uint32_t(get_le(tile.data() + at, 4)); };
  std::vector<std::vector<unsigned char>> out;
  for (std::size_t at = 64; at < tile.size();) {
    const std::uint32_t raw_n = get32(at), stored_n = get32(at + 4);
    std::vector<unsigned char> raw(raw_n);
    if (get32(8) >= 7) {  // two halves of the planes, behind the first's stored size
      const std::uint32_t field = get32(at + 16);
      const char* packed = tile.data() + at + 20;
      EXPECT_EQ(LZ4_decompress_safe(packed, reinterpret_cast<char*>(raw.data()), int(field), int(raw_n / 2)),
                int(raw_n / 2));
      EXPECT_EQ(LZ4_decompress_safe(packed + field, reinterpret_cast<char*>(raw.data() + raw_n / 2),
                                    int(stored_n - 4 - field), int(raw_n / 2)),
                int(raw_n / 2));
    } else {
      EXPECT_EQ(LZ4_decompress_safe(tile.data() + at + 16, reinterpret_cast<char*>(raw.data()), int(stored_n), int(raw_n)),
                int(raw_n));
    }
    if (get32(8) >= 6) raw = planes_by_hand(raw, false);
    out.push_back(std::move(raw));
    at += 16 + stored_n;
  }
  return out;
}

}  // namespace

// Format 5 cuts the raw payload of format 4 into chunks of whole blocks, each at most 256 KiB and
// compressed on its own, so that a brick of any size is written and read through buffers of one
// chunk. A chunk that claims more than 1 MiB, a block cut by a chunk's end, or counts that
// disagree with the header are damage, and a damaged tile leaves its table empty.
TEST(Tile, ChunksHoldWholeBlocksOfTheRawPayload) {
  const auto dir = scratch_dir("tile_chunks");
  VoxelTable t(3);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.01f, 1.f);
  // 48^3 voxels of level 9 (12^3 full 4^3 blocks of 1040 raw bytes: 1.8 MB raw) and a few others.
  for (std::uint32_t x = 128; x < 176; ++x)
    for (std::uint32_t y = 0; y < 48; ++y)
      for (std::uint32_t z = 128; z < 176; ++z) {
        VoxelData& v = t.find_or_insert(VoxelKey::make(9, x, y, z));
        v.distance = u(rng), v.weight = u(rng);
        v.colour_fixed[0] = std::uint16_t(rng());
      }
  fill(t, sample_voxels());
  write_tile(dir / "t.tile", {2, 0, 2}, t);
  const std::vector<char> bytes = bytes_of(dir / "t.tile");
  const auto chunks = raw_chunks(bytes);
  // 1728 blocks of 1040 bytes and a few small ones: 252 full blocks fit 256 KiB, so 7 chunks.
  ASSERT_EQ(chunks.size(), 7u);
  std::vector<unsigned char> joined;
  for (std::size_t i = 0; i < chunks.size(); ++i) {
    EXPECT_LE(chunks[i].size(), std::size_t{256} << 10);
    if (i + 1 < chunks.size()) {
      EXPECT_GT(chunks[i].size(), (std::size_t{256} << 10) - 1040) << "a chunk ends early only when the next block does not fit";
    }
    joined.insert(joined.end(), chunks[i].begin(), chunks[i].end());
  }
  // The writer's tile is the format's description laid out here, byte for byte.
  EXPECT_EQ(bytes, chunked_tile(7, {2, 0, 2}, 3, std::uint32_t(tile_blocks(t).size()), chunks));
  // Joined, the chunks are format 4's raw payload, byte for byte.
  const std::vector<char> v4 = legacy_tile(4, {2, 0, 2}, t);
  std::vector<unsigned char> v4_raw(joined.size());
  ASSERT_EQ(LZ4_decompress_safe(v4.data() + 64, reinterpret_cast<char*>(v4_raw.data()), int(v4.size() - 64),
                                int(v4_raw.size())),
            int(joined.size()));
  EXPECT_EQ(joined, v4_raw);
  VoxelTable back(3);
  read_tile(dir / "t.tile", back);
  EXPECT_EQ(back.live_count(), t.live_count());
  t.for_each([&](VoxelKey k, const VoxelData& d) {
    const VoxelData* v = back.find(k);
    ASSERT_NE(v, nullptr);
    EXPECT_EQ(v->distance, d.distance);
    EXPECT_EQ(v->colour_fixed[0], d.colour_fixed[0]);
  });
  // The same raw bytes cut elsewhere at block boundaries (the first two chunks as one) read the
  // same; cut inside a block (that chunk's last 7 bytes moved to the next) they do not.
  const std::uint32_t blocks = std::uint32_t(tile_blocks(t).size());
  const std::size_t two = chunks[0].size() + chunks[1].size();
  // Where each block of the raw payload ends (its 16-byte key and mask, 16 bytes per present voxel).
  std::vector<std::size_t> ends;
  for (std::size_t at = 0; at < joined.size();) {
    const std::uint64_t mask = get_le(joined.data() + at + 8, 8);
    at += 16 + 16 * std::size_t(std::popcount(mask));
    ends.push_back(at);
  }
  ASSERT_EQ(ends.size(), blocks);
  ASSERT_TRUE(std::binary_search(ends.begin(), ends.end(), two));
  const std::size_t tail = ends[ends.size() - 900];  // the last 900 blocks in a third chunk
  auto cut = [&](std::size_t at) {
    return std::vector<std::vector<unsigned char>>{std::vector<unsigned char>(joined.begin(), joined.begin() + at),
                                                   std::vector<unsigned char>(joined.begin() + at, joined.begin() + tail),
                                                   std::vector<unsigned char>(joined.begin() + tail, joined.end())};
  };
  write_bytes(dir / "recut.tile", chunked_tile(7, {2, 0, 2}, 3, blocks, cut(two)));
  VoxelTable recut_back(3);
  read_tile(dir / "recut.tile", recut_back);
  EXPECT_EQ(recut_back.live_count(), t.live_count());
  // Cut inside a block: in format 5 anywhere, in format 6 at a 16-byte unit (a chunk of format 6
  // is whole units, since its planes are).
  write_bytes(dir / "torn.tile", chunked_tile(5, {2, 0, 2}, 3, blocks, cut(two - 7)));
  VoxelTable torn_back(3);
  expect_input_error([&] { read_tile(dir / "torn.tile", torn_back); }, "torn.tile", "runs past the payload");
  EXPECT_EQ(torn_back.block_count(), 0u);
  write_bytes(dir / "torn6.tile", chunked_tile(6, {2, 0, 2}, 3, blocks, cut(two - 16)));
  VoxelTable torn6_back(3);
  expect_input_error([&] { read_tile(dir / "torn6.tile", torn6_back); }, "torn6.tile", "runs past the payload");
  EXPECT_EQ(torn6_back.block_count(), 0u);
  write_bytes(dir / "odd6.tile", chunked_tile(6, {2, 0, 2}, 3, blocks, cut(two - 7)));
  expect_input_error([&] {
    VoxelTable fresh(3);
    read_tile(dir / "odd6.tile", fresh);
  }, "odd6.tile", "chunk 0 of " + std::to_string(two - 7) + " raw bytes, not whole 16-byte units");
  // Block counts against the header: one more, one fewer.
  write_bytes(dir / "more.tile", chunked_tile(7, {2, 0, 2}, 3, blocks + 1, chunks));
  expect_input_error([&] {
    VoxelTable fresh(3);
    read_tile(dir / "more.tile", fresh);
  }, "more.tile", std::to_string(blocks) + " blocks, header says " + std::to_string(blocks + 1));
  // A count no payload could hold: the reader sizes its index by the bytes it has decompressed (a
  // block takes at least 16), not by the count, which would ask for 128 GiB.
  write_bytes(dir / "lying.tile", chunked_tile(7, {2, 0, 2}, 3, 0xffffffffu, chunks));
  expect_input_error([&] {
    VoxelTable fresh(3);
    read_tile(dir / "lying.tile", fresh);
  }, "lying.tile", std::to_string(blocks) + " blocks, header says 4294967295");
  write_bytes(dir / "fewer.tile", chunked_tile(7, {2, 0, 2}, 3, blocks - 1, chunks));
  VoxelTable fewer_back(3);
  expect_input_error([&] { read_tile(dir / "fewer.tile", fewer_back); }, "fewer.tile",
                     "more blocks than the header's " + std::to_string(blocks - 1));
  EXPECT_EQ(fewer_back.block_count(), 0u);
  // A flipped byte in any chunk's LZ4 block fails that chunk's checksum before it is decompressed.
  for (std::size_t at : {std::size_t{64 + 16 + 100}, bytes.size() - 1}) {
    std::vector<char> flipped = bytes;
    flipped[at] ^= 0x04;
    write_bytes(dir / "flipped.tile", flipped);
    VoxelTable fresh(3);
    expect_input_error([&] { read_tile(dir / "flipped.tile", fresh); }, "flipped.tile", "damaged tile: payload checksum mismatch");
    EXPECT_EQ(fresh.block_count(), 0u) << "the chunks before the damaged one are dropped again";
  }
  // Format 7's first half claiming none, or all, of the chunk's stored bytes (the chunk and header
  // checksums made to match) is damage; so is one that decompresses to other than half the planes.
  const std::uint32_t first_blocks = std::uint32_t(std::upper_bound(ends.begin(), ends.end(), chunks[0].size()) - ends.begin());
  const std::vector<char> halves = chunked_tile(7, {2, 0, 2}, 3, first_blocks, {chunks[0]});
  auto with_first_half = [&](std::uint32_t field) {
    std::vector<unsigned char> packed(halves.begin() + 64 + 16, halves.end());
    set_le(packed.data(), field, 4);
    return framed_tile(7, {2, 0, 2}, 3, first_blocks, {{chunks[0].size(), packed}});
  };
  const std::uint32_t stored_n = std::uint32_t(halves.size() - 64 - 16);
  const std::uint32_t field = std::uint32_t(get_le(halves.data() + 80, 4));
  ASSERT_GT(field, 0u);
  ASSERT_LT(field, stored_n - 4);
  write_bytes(dir / "halves_ok.tile", with_first_half(field));
  VoxelTable halves_back(3);
  read_tile(dir / "halves_ok.tile", halves_back);  // the first chunk's blocks, as a tile of their own
  const std::size_t first_records = (chunks[0].size() - 16 * first_blocks) / 16;
  EXPECT_GT(halves_back.live_count(), first_records - 8) << "all but the sample's few erased voxels are live";
  EXPECT_LE(halves_back.live_count(), first_records);
  for (std::uint32_t lie : {0u, stored_n - 4, 0xffffffffu}) {
    write_bytes(dir / "halves.tile", with_first_half(lie));
    VoxelTable fresh(3);
    expect_input_error([&] { read_tile(dir / "halves.tile", fresh); }, "halves.tile",
                       "chunk 0's halves do not fit its " + std::to_string(stored_n) + " stored bytes");
    EXPECT_EQ(fresh.block_count(), 0u);
  }
  // A chunk's stored bytes short of the first half's size, or a half beyond LZ4's bound on half
  // the raw bytes (the total within the bound on both), are damage too.
  auto with_stored = [&](std::vector<unsigned char> packed, std::size_t raw_n) {
    return framed_tile(7, {2, 0, 2}, 3, first_blocks, {{raw_n, std::move(packed)}});
  };
  write_bytes(dir / "halves.tile", with_stored({1, 0, 0}, 256));  // raw bytes the header finds plausible
  expect_input_error([&] {
    VoxelTable fresh(3);
    read_tile(dir / "halves.tile", fresh);
  }, "halves.tile", "chunk 0's halves do not fit its 3 stored bytes");
  const std::uint32_t half_bound = std::uint32_t(LZ4_compressBound(int(chunks[0].size() / 2)));
  std::vector<unsigned char> lopsided;
  put_le(lopsided, half_bound + 1, 4);
  lopsided.resize(4 + half_bound + 8, 0);
  write_bytes(dir / "halves.tile", with_stored(lopsided, chunks[0].size()));
  expect_input_error([&] {
    VoxelTable fresh(3);
    read_tile(dir / "halves.tile", fresh);
  }, "halves.tile", "chunk 0's halves do not fit its " + std::to_string(lopsided.size()) + " stored bytes");
  for (std::uint32_t lie : {field - 1, field + 1}) {
    write_bytes(dir / "halves.tile", with_first_half(lie));
    VoxelTable fresh(3);
    expect_input_error([&] { read_tile(dir / "halves.tile", fresh); }, "halves.tile",
                       "chunk 0 does not decompress to its stated size");
  }
  // A chunk of more than 1 MiB is refused before anything is allocated for it.
  write_bytes(dir / "huge.tile", chunked_tile(7, {2, 0, 2}, 3, blocks, {joined}));
  expect_input_error([&] {
    VoxelTable fresh(3);
    read_tile(dir / "huge.tile", fresh);
  }, "huge.tile", "chunk 0 of " + std::to_string(joined.size()) + " raw bytes (1 to 1048576)");
}

}  // namespace sf
