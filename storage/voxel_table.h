#pragma once
// The voxels of one brick, stored as dense blocks of up to 2x2x2 voxels of one level.
//
// Integration touches voxels in bands a few cells thick, so neighbouring voxels are written
// together: a dense block turns most of those writes into stores next to the previous one, where
// a hash table of single voxels costs a random probe each (the reason session 1's integration was
// memory-bound). A group index (open addressing) maps the origin key of a 4x4x4 region to the
// group of its blocks.
//
// Block shape: a block of level l holds 2^k voxels per axis with k = clamp(l - brick_level, 0, 1),
// aligned to multiples of 2^k. A brick holds 2^(l - brick_level) voxels of level l per axis, so a
// block never straddles two bricks; levels at or above the brick level get one-voxel blocks (there
// are few such voxels). Blocks were 4x4x4 until session 41: a band a few voxels thick fills 33-60 %
// of such a block's slots at the finer levels and 60-81 % of a 2x2x2 one's (igea, bench/README.md
// session 40), and every slot is fresh memory once, which a virtual machine's host hands out
// slowly (session 41). The index
// holds groups of the eight blocks of a 4x4x4 region (BlockGroup), and tiles keep 4x4x4 blocks
// (tile_block_log): tile_file.cc writes a group as its tile block and reads one into its blocks.
//
// A voxel is absent while its weight is 0 (every contribution carries a positive weight), live
// while it is > 0 and erased when < 0. Pointers to voxels stay valid until compact() or clear():
// blocks' voxels live in an arena of chunks that never move.
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>
#include <vector>
#if defined(__SSE2__) && defined(__x86_64__)
#include <emmintrin.h>
#endif

#include "storage/voxel_key.h"

namespace sf {

// The hSDF sample of one voxel: cumulative weighted averages (equations 2-3 of the paper), in 16
// bytes. Integration's cost is mostly memory (every voxel is fresh memory once, and the whole
// field is compressed into tiles at each checkpoint), so colour, whose float precision no output
// needs, is kept in fixed point: 24-byte voxels cost 10-20 % more integration time and 50 % more
// field and tile bytes (bench/README.md, session 29).
struct VoxelData {
  static constexpr float kColourUnit = 256.0f;  // colour_fixed units per colour step
  static constexpr std::uint16_t kFullShare = 65535;

  float distance = 0;  // D: weighted mean signed distance, metres, positive in front
  float weight = 0;    // W: accumulated weight (confidence); 0 = absent, < 0 = erased
  std::uint16_t colour_fixed[3] = {0, 0, 0};  // weighted mean colour, 0..255 in 1/256 steps
  // Weight of the contributions that carried colour, as a share of W in 1/65535 steps. It never
  // exceeds W: a contribution with colour adds the same weight to both, one without only to W.
  std::uint16_t colour_share = 0;

  bool live() const { return weight > 0; }
  bool erased() const { return weight < 0; }

  float colour(int k) const { return float(colour_fixed[k]) * (1.0f / kColourUnit); }  // exact
  // Exactly W while every contribution carried colour.
  float colour_weight() const {
    if (!(weight > 0) || colour_share == 0) return 0;
    return colour_share == kFullShare ? weight : weight * (float(colour_share) / float(kFullShare));
  }
  // Sets the mean colour (0..255) and the weight behind it (the voxel's weight must be set first;
  // a colour weight above it counts as equal).
  void set_colour(const float c[3], double colour_weight) {
    for (int k = 0; k < 3; ++k) colour_fixed[k] = colour_to_fixed(c[k]);
    colour_share = share_of(colour_weight, weight);
  }

  static std::uint16_t colour_to_fixed(float c) {
    if (!(c > 0)) return 0;
    const float f = c * kColourUnit + 0.5f;
    return f >= 65535.0f ? std::uint16_t(65535) : std::uint16_t(f);
  }
  static std::uint16_t share_of(double part, double whole) {
    if (!(part > 0) || !(whole > 0)) return 0;
    if (part >= whole) return kFullShare;
    return std::uint16_t(part / whole * double(kFullShare) + 0.5);
  }
};
static_assert(sizeof(VoxelData) == 16, "voxel records are 16 bytes (tiles and the memory budget count on it)");

// The colour part of accumulate: each channel colour_to_fixed((before colour(k) + weight c[k]) inv).
inline void blend_colour_scalar(VoxelData& v, float before, float weight, const std::uint8_t* colour, float inv) {
  for (int k = 0; k < 3; ++k)
    v.colour_fixed[k] = VoxelData::colour_to_fixed((before * v.colour(k) + weight * float(colour[k])) * inv);
}
#if defined(__SSE2__) && defined(__x86_64__)
// VoxelData::colour_to_fixed per lane, as 32-bit integers: max clamps a NaN or -0 to 0 (then 0.5
// truncates to 0, as !(c > 0) gives), min saturates at 65535.
inline __m128i colour_to_fixed_lanes(__m128 c) {
  const __m128 f = _mm_min_ps(
      _mm_add_ps(_mm_mul_ps(_mm_max_ps(c, _mm_setzero_ps()), _mm_set1_ps(VoxelData::kColourUnit)), _mm_set1_ps(0.5f)),
      _mm_set1_ps(65535.0f));
  return _mm_cvttps_epi32(f);
}

// The three channels in the lanes of one register: the same float products and sums as
// blend_colour_scalar lane by lane (so the same bits), without its branches; this runs for every
// contribution.
inline void blend_colour(VoxelData& v, float before, float weight, const std::uint8_t* colour, float inv) {
  const __m128i zero = _mm_setzero_si128();
  std::uint64_t fixed;  // colour_fixed[0..2] and colour_share, which lane 3 carries along unused
  static_assert(offsetof(VoxelData, colour_share) == offsetof(VoxelData, colour_fixed) + 6);
  std::memcpy(&fixed, reinterpret_cast<const char*>(&v) + offsetof(VoxelData, colour_fixed), 8);
  const __m128 mean = _mm_mul_ps(_mm_cvtepi32_ps(_mm_unpacklo_epi16(_mm_cvtsi64_si128(std::int64_t(fixed)), zero)),
                                 _mm_set1_ps(1.0f / VoxelData::kColourUnit));
  const int bytes = int(colour[0]) | (int(colour[1]) << 8) | (int(colour[2]) << 16);
  const __m128 c = _mm_cvtepi32_ps(_mm_unpacklo_epi16(_mm_unpacklo_epi8(_mm_cvtsi32_si128(bytes), zero), zero));
  const __m128 blended =
      _mm_mul_ps(_mm_add_ps(_mm_mul_ps(_mm_set1_ps(before), mean), _mm_mul_ps(_mm_set1_ps(weight), c)), _mm_set1_ps(inv));
  // u16 from i32 without SSE4.1: bias to i16, pack, unbias.
  const __m128i biased = _mm_sub_epi32(colour_to_fixed_lanes(blended), _mm_set1_epi32(32768));
  const __m128i u16 = _mm_xor_si128(_mm_packs_epi32(biased, biased), _mm_set1_epi16(std::int16_t(-32768)));
  const std::uint64_t out = std::uint64_t(_mm_cvtsi128_si64(u16));
  std::memcpy(v.colour_fixed, &out, sizeof v.colour_fixed);
}
#else
inline void blend_colour(VoxelData& v, float before, float weight, const std::uint8_t* colour, float inv) {
  blend_colour_scalar(v, before, weight, colour, inv);
}
#endif

// Equations 2-3 (Curless & Levoy): adds one contribution (d, w > 0) to a voxel's running weighted
// means; `colour` may be null (no colour).
inline void accumulate(VoxelData& v, float distance, float weight, const std::uint8_t* colour) {
  const float W = v.weight + weight;
  v.distance = (v.weight * v.distance + weight * distance) / W;
  if (colour) {
    // The colour weight before: exactly v.weight while every contribution had colour (then Wc = W).
    const float before = v.colour_weight();
    const float Wc = before + weight, inv = 1.0f / Wc;
    blend_colour(v, before, weight, colour, inv);
    v.colour_share = Wc >= W ? VoxelData::kFullShare : VoxelData::share_of(Wc, W);
  } else if (v.colour_share != 0) {
    v.colour_share = VoxelData::share_of(v.colour_weight(), W);
  }
  v.weight = W;
}

// accumulate() for four distinct voxels at once, each with colour: the voxels' fields side by side
// in the lanes of four registers (one 4 x 4 transpose of their 16 bytes each way), and in each lane
// the same float operations in the same order as accumulate(), so the same bits; its two
// divisions and its branches on the colour weight then serve four contributions. A lane whose
// colour weight falls short of its weight (some earlier contribution had no colour) takes
// share_of's double division, lane by lane.
#if defined(__SSE2__) && defined(__x86_64__)
inline void accumulate4(VoxelData* const v[4], const float distance[4], const float weight[4],
                        const std::uint8_t* const colour[4]) {
  static_assert(offsetof(VoxelData, weight) == 4 && offsetof(VoxelData, colour_fixed) == 8);
  __m128 r0 = _mm_loadu_ps(reinterpret_cast<const float*>(v[0])), r1 = _mm_loadu_ps(reinterpret_cast<const float*>(v[1])),
         r2 = _mm_loadu_ps(reinterpret_cast<const float*>(v[2])), r3 = _mm_loadu_ps(reinterpret_cast<const float*>(v[3]));
  _MM_TRANSPOSE4_PS(r0, r1, r2, r3);  // r0 distances, r1 weights, r2 colour 0 | 1, r3 colour 2 | share
  const __m128 d = _mm_loadu_ps(distance), w = _mm_loadu_ps(weight), zero = _mm_setzero_ps();
  const __m128i low16 = _mm_set1_epi32(0xffff);
  const __m128 W = _mm_add_ps(r1, w);
  const __m128 D = _mm_div_ps(_mm_add_ps(_mm_mul_ps(r1, r0), _mm_mul_ps(w, d)), W);
  // colour_weight(): 0 unless live with a share; the weight itself at the full share.
  const __m128i share = _mm_srli_epi32(_mm_castps_si128(r3), 16);
  const __m128 scaled = _mm_mul_ps(r1, _mm_div_ps(_mm_cvtepi32_ps(share), _mm_set1_ps(float(VoxelData::kFullShare))));
  const __m128 full = _mm_castsi128_ps(_mm_cmpeq_epi32(share, _mm_set1_epi32(VoxelData::kFullShare)));
  const __m128 has = _mm_andnot_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(share, _mm_setzero_si128())), _mm_cmpgt_ps(r1, zero));
  const __m128 before = _mm_and_ps(has, _mm_or_ps(_mm_and_ps(full, r1), _mm_andnot_ps(full, scaled)));
  const __m128 Wc = _mm_add_ps(before, w);
  const __m128 inv = _mm_div_ps(_mm_set1_ps(1.0f), Wc);
  // blend_colour per channel: (before mean + weight c) inv, then colour_to_fixed_lanes. The lanes'
  // colours go into a register as one word each and are split there, rather than stored to an
  // int32 array lane by lane and read back as vectors (a read cannot take its bytes from several
  // pending writes, so it waited for them to reach the cache; igea 0.98-1.00).
  const auto word = [](const std::uint8_t* c) { return int(c[0]) | (int(c[1]) << 8) | (int(c[2]) << 16); };
  const __m128i words = _mm_set_epi32(word(colour[3]), word(colour[2]), word(colour[1]), word(colour[0]));
  const __m128i byte = _mm_set1_epi32(255);
  const __m128i c[3] = {_mm_and_si128(words, byte), _mm_and_si128(_mm_srli_epi32(words, 8), byte),
                        _mm_srli_epi32(words, 16)};
  const __m128i fixed_in[3] = {_mm_and_si128(_mm_castps_si128(r2), low16), _mm_srli_epi32(_mm_castps_si128(r2), 16),
                               _mm_and_si128(_mm_castps_si128(r3), low16)};
  __m128i fixed[3];
  for (int k = 0; k < 3; ++k) {
    const __m128 mean = _mm_mul_ps(_mm_cvtepi32_ps(fixed_in[k]), _mm_set1_ps(1.0f / VoxelData::kColourUnit));
    const __m128 blended = _mm_mul_ps(
        _mm_add_ps(_mm_mul_ps(before, mean), _mm_mul_ps(w, _mm_cvtepi32_ps(c[k]))),
        inv);
    fixed[k] = colour_to_fixed_lanes(blended);
  }
  // colour_share: full where Wc >= W, else share_of(Wc, W) in double (lane by lane, rare).
  __m128i share_out = _mm_set1_epi32(VoxelData::kFullShare);
  const int short_lanes = ~_mm_movemask_ps(_mm_cmpge_ps(Wc, W)) & 15;  // a NaN too, as there
  if (short_lanes) {
    alignas(16) float wc[4], wt[4];
    alignas(16) std::int32_t s[4];
    _mm_store_ps(wc, Wc);
    _mm_store_ps(wt, W);
    _mm_store_si128(reinterpret_cast<__m128i*>(s), share_out);
    for (int lane = 0; lane < 4; ++lane)
      if (short_lanes >> lane & 1) s[lane] = VoxelData::share_of(wc[lane], wt[lane]);
    share_out = _mm_load_si128(reinterpret_cast<const __m128i*>(s));
  }
  __m128 o0 = D, o1 = W;
  __m128 o2 = _mm_castsi128_ps(_mm_or_si128(fixed[0], _mm_slli_epi32(fixed[1], 16)));
  __m128 o3 = _mm_castsi128_ps(_mm_or_si128(fixed[2], _mm_slli_epi32(share_out, 16)));
  _MM_TRANSPOSE4_PS(o0, o1, o2, o3);
  _mm_storeu_ps(reinterpret_cast<float*>(v[0]), o0);
  _mm_storeu_ps(reinterpret_cast<float*>(v[1]), o1);
  _mm_storeu_ps(reinterpret_cast<float*>(v[2]), o2);
  _mm_storeu_ps(reinterpret_cast<float*>(v[3]), o3);
}
#else
inline void accumulate4(VoxelData* const v[4], const float distance[4], const float weight[4],
                        const std::uint8_t* const colour[4]) {
  for (int lane = 0; lane < 4; ++lane) accumulate(*v[lane], distance[lane], weight[lane], colour[lane]);
}
#endif

inline constexpr int kMaxBlockLog = 1;   // in memory
inline constexpr int kTileBlockLog = 2;  // in tiles (storage/tile_file.h)

// log2 of a block's edge in voxels for `level`, in memory (see above) and in tiles.
constexpr int block_log(int level, int brick_level) {
  const int k = level - brick_level;
  return k < 0 ? 0 : (k > kMaxBlockLog ? kMaxBlockLog : k);
}
constexpr int tile_block_log(int level, int brick_level) {
  const int k = level - brick_level;
  return k < 0 ? 0 : (k > kTileBlockLog ? kTileBlockLog : k);
}

// The origin of the block of edge 2^log holding `key`.
inline VoxelKey aligned_origin(VoxelKey key, int log) {
  const std::uint32_t m = ~((1u << log) - 1);
  return VoxelKey::make(key.level(), key.x() & m, key.y() & m, key.z() & m);
}
// The origin of the block holding `key` (the one rule; VoxelTable and integration both use it).
inline VoxelKey block_origin(VoxelKey key, int brick_level) {
  return aligned_origin(key, block_log(key.level(), brick_level));
}

// A block's voxels, addressed relative to its origin.
struct BlockRef {
  VoxelKey origin;
  int log = 0;               // edge = 1 << log voxels
  VoxelData* data = nullptr;  // (1 << 3 log) voxels, x fastest
  VoxelData& at(VoxelKey k) const {
    const std::uint32_t dx = k.x() - origin.x(), dy = k.y() - origin.y(), dz = k.z() - origin.z();
    return data[(((dz << log) | dy) << log) | dx];
  }
};

// The blocks of one tile block (a 4^3 region at the finer levels: eight 2^3 blocks; a single block
// at the coarser ones), each made when a voxel in it is first written. The table's index holds
// groups, so that integration looks up a 4^3 region once and finds its blocks here, as it did
// when blocks were 4^3. Integration reads and makes a group's blocks without the brick's lock
// (VoxelTable::make_part_shared), hence the atomics.
struct BlockGroup {
  std::atomic<VoxelData*> part[8] = {};
};
static_assert(sizeof(BlockGroup) == 64, "a group is one cache line");
static_assert(kTileBlockLog - kMaxBlockLog == 1, "a group holds at most 2 blocks per axis");

// A full group's voxels seen as its tile block: voxel i of part o of a group (q = 8 o + i) is voxel
// kGroupToTile[q] of the 4^3 tile block (x fastest), and kTileToGroup is the way back, so that
// tiles are written from and read into a group's blocks without copying through a 4^3 array.
inline constexpr std::array<std::uint8_t, 64> kGroupToTile = [] {
  std::array<std::uint8_t, 64> t{};
  for (int q = 0; q < 64; ++q) {
    const int o = q >> 3, i = q & 7;
    const int x = (o & 1) << 1 | (i & 1), y = (o >> 1 & 1) << 1 | (i >> 1 & 1), z = (o >> 2) << 1 | (i >> 2);
    t[q] = std::uint8_t(z << 4 | y << 2 | x);
  }
  return t;
}();
inline constexpr std::array<std::uint8_t, 64> kTileToGroup = [] {
  std::array<std::uint8_t, 64> t{};
  for (int q = 0; q < 64; ++q) t[kGroupToTile[q]] = std::uint8_t(q);
  return t;
}();

// Which block of its group holds `key`: x, y and z's bit at the block's edge (0 where the group is
// one block).
inline int group_part(VoxelKey key, int brick_level) {
  const int log = block_log(key.level(), brick_level);
  if (tile_block_log(key.level(), brick_level) == log) return 0;
  return int((key.x() >> log) & 1) | int(((key.y() >> log) & 1) << 1) | int(((key.z() >> log) & 1) << 2);
}

class VoxelTable {
 public:
  explicit VoxelTable(int brick_level) : brick_level_(brick_level) {}
  VoxelTable(VoxelTable&& other) noexcept;
  VoxelTable& operator=(VoxelTable&& other) noexcept;

  int brick_level() const { return brick_level_; }
  std::size_t block_count() const;        // blocks (a scan of the groups)
  std::size_t live_count() const;        // live voxels (a scan)
  // The arena's chunks and the index.
  std::size_t memory_bytes() const { return chunk_bytes_ + index_.capacity() * sizeof(Slot); }
  std::size_t group_count() const { return groups_; }

  // The origin of the block holding `key`.
  VoxelKey block_origin(VoxelKey key) const { return sf::block_origin(key, brick_level_); }

  // The block holding `key`; null data if absent and !create.
  BlockRef block(VoxelKey key, bool create);
  // Room in the index for `groups` groups without regrowing (a tile's reader, by the bytes it has
  // decompressed).
  void reserve(std::size_t groups);
  // The group of the tile block holding `key` (tile_block_log); null if absent and !create.
  BlockGroup* group(VoxelKey key, bool create);
  // Block `part` of `group`, of edge 2^log, made if absent, by a caller that has the table to
  // itself (reading a tile).
  VoxelData* make_part(BlockGroup& group, int part, int log);
  // The same while other threads may make blocks of the table's groups: `lock` guards the index
  // (null if the caller holds it), each thread carves from the chunk of its `cursor` (any number:
  // threads sharing one stay correct, they only contend), and *grown (if given) receives the bytes
  // of any chunk added (memory_bytes' growth).
  VoxelData* make_part_shared(BlockGroup& group, int part, int log, std::mutex* lock, unsigned cursor,
                              std::int64_t* grown);

  // The voxel if present (live or erased), else null.
  VoxelData* find(VoxelKey key);
  const VoxelData* find(VoxelKey key) const;
  // The voxel, creating its block if needed (an absent voxel reads weight 0).
  VoxelData& find_or_insert(VoxelKey key);
  // Erased voxels become absent; blocks without live voxels are dropped.
  void compact();
  // Drops every block and frees the memory.
  void clear();

  // Visits every block: f(VoxelKey origin, int log, const VoxelData* voxels), in index order
  // (which depends on the order the blocks were made in: callers that write files sort).
  template <class F>
  void for_each_block(F&& f) const {
    for (const Slot& s : index_)
      if (s.key != kEmpty) visit_parts(VoxelKey{s.key}, *s.group, f);
  }

  // Visits every group: f(VoxelKey origin of its tile block, const BlockGroup&), in index order.
  template <class F>
  void for_each_group(F&& f) const {
    for (const Slot& s : index_)
      if (s.key != kEmpty) f(VoxelKey{s.key}, static_cast<const BlockGroup&>(*s.group));
  }

  // Visits every live voxel: f(VoxelKey, VoxelData&), block by block.
  template <class F>
  void for_each(F&& f) {
    for_each_block([&](VoxelKey origin, int log, const VoxelData* v) { visit(origin, log, const_cast<VoxelData*>(v), f); });
  }
  template <class F>
  void for_each(F&& f) const {
    for_each_block([&](VoxelKey origin, int log, const VoxelData* v) { visit(origin, log, v, f); });
  }

 private:
  static constexpr std::uint64_t kEmpty = ~std::uint64_t{0};  // no valid key has all bits set

  template <class F>
  void visit_parts(VoxelKey origin, const BlockGroup& g, F& f) const {
    const int log = block_log(origin.level(), brick_level_);
    const int parts = tile_block_log(origin.level(), brick_level_) == log ? 1 : 8;
    for (int o = 0; o < parts; ++o) {
      const VoxelData* v = g.part[o].load(std::memory_order_relaxed);
      if (!v) continue;
      const std::uint32_t dx = std::uint32_t(o & 1) << log, dy = std::uint32_t(o >> 1 & 1) << log,
                          dz = std::uint32_t(o >> 2) << log;
      f(VoxelKey::make(origin.level(), origin.x() + dx, origin.y() + dy, origin.z() + dz), log, v);
    }
  }
  template <class V, class F>
  static void visit(VoxelKey origin, int log, V* voxels, F& f) {
    const std::uint32_t n = 1u << log;
    std::size_t i = 0;
    for (std::uint32_t z = 0; z < n; ++z)
      for (std::uint32_t y = 0; y < n; ++y)
        for (std::uint32_t x = 0; x < n; ++x, ++i)
          if (voxels[i].live())
            f(VoxelKey::make(origin.level(), origin.x() + x, origin.y() + y, origin.z() + z), voxels[i]);
  }
  // The index: a tile block's origin key and its group, side by side, so that a lookup reads one
  // cache line.
  struct Slot {
    std::uint64_t key;
    BlockGroup* group;
  };
  BlockGroup* find_group(std::uint64_t origin) const;  // null if absent
  void reindex(std::size_t capacity);
  void insert_slot(std::uint64_t origin, BlockGroup* group);
  // `bytes` zeroed bytes from the arena, aligned to a cache line, from the chunk of `cursor`. Safe
  // while other threads allocate with `lock` (taken to add a chunk; null if the caller holds it),
  // unless `alone` (the caller has the table to itself: no atomic read-modify-write, which the
  // profile showed as most of a block's making). A new chunk's bytes are added to *grown.
  void* allocate(std::size_t bytes, bool alone, std::mutex* lock = nullptr, std::int64_t* grown = nullptr,
                 unsigned cursor = 0);
  VoxelData* part_voxels(int log, bool alone, std::mutex* lock, unsigned cursor, std::int64_t* grown);

  // The arena: groups and blocks' voxels in chunks that never move (pointers stay valid until
  // compact() or clear()), zeroed by calloc (all zero bytes are VoxelData{}, an implicit-lifetime
  // type that calloc's memory holds without a constructor; groups and chunk heads, which hold
  // atomics, are constructed in place). One heap allocation
  // per block cost a 16-byte header each, a call to malloc and a memset, and a block record beside
  // the index; the chunks grow from 2 KiB to 32 KiB, so that a brick with few voxels does not hold
  // a large chunk half empty (a city job has some 35,000 bricks).
  //
  // Integration makes a group's blocks without the brick's lock (make_part_shared): blocks are
  // carved by a fetch_add on the used count of a chunk, and only a new chunk is made under the
  // lock. Each thread carves from a chunk of its own (kCursors of them, by thread index), as two
  // cores adding to one count passed its cache line back and forth (city eighth, 2 threads: making
  // blocks fell from 2.5 to 1.8 % of the samples); threads beyond kCursors, and group(), which
  // carves from cursor 0 under the lock, share a chunk safely. Groups are made and the index
  // changes under the lock alone.
  struct FreeChunk {
    void operator()(void* p) const { std::free(p); }
  };
  struct alignas(64) ChunkHead {  // at the start of each chunk, its bytes after it
    std::atomic<std::size_t> used{0};
    std::size_t size = 0;
    unsigned char* bytes() { return reinterpret_cast<unsigned char*>(this + 1); }
  };
  static constexpr std::size_t kFirstChunkBytes = 2048, kMaxChunkBytes = 32768;
  static constexpr unsigned kCursors = 4;
  // A new chunk of at least `bytes` for `cursor` (callers hold the lock, if any); returns the
  // bytes it adds.
  std::size_t grow(std::size_t bytes, unsigned cursor);

  int brick_level_;
  std::vector<std::unique_ptr<void, FreeChunk>> chunks_;
  std::atomic<ChunkHead*> current_[kCursors] = {};  // the chunks blocks are carved from
  std::size_t chunk_bytes_ = 0;
  std::size_t groups_ = 0;
  std::vector<Slot> index_;  // open addressing: tile block origin key -> its group
};

}  // namespace sf
