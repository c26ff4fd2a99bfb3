#include "storage/tile_file.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <lz4.h>
#include <unistd.h>
#include <xxhash.h>
#if defined(__SSE2__) && defined(__x86_64__)
#include <xmmintrin.h>
#endif

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "engine/error.h"
#include "storage/byte_planes.h"

namespace sf {
namespace {

// Anonymous pages for `size` bytes. From 2 MiB on they are aligned to 2 MiB and the kernel is asked
// for transparent huge pages: these images are touched from end to end, and a first touch of a 4
// KiB page cost ~10 µs on the virtual machines of sessions 19-37 (scheduler/huge_pages.h). Where
// the heap is kept on 4 KiB pages the advice stays: the pool reuses these mappings (igea's
// integration without it: 1.032, noise; bench/README.md, session 46), and under THP `always` the
// program has turned huge pages off for the whole process anyway.
unsigned char* map_pages(std::size_t size) {
  constexpr std::size_t kHuge = std::size_t{2} << 20;
  const bool huge = size >= kHuge;
  // For huge pages, a huge page more, whose unaligned ends are unmapped below.
  const std::size_t mapped = huge ? size + kHuge : size;
  void* p = ::mmap(nullptr, mapped, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) throw std::bad_alloc();
  if (!huge) return static_cast<unsigned char*>(p);
  const auto start = reinterpret_cast<std::uintptr_t>(p);
  const std::uintptr_t aligned = (start + kHuge - 1) & ~std::uintptr_t(kHuge - 1), end = start + mapped;
  if (aligned > start) ::munmap(p, aligned - start);
  if (end > aligned + size) ::munmap(reinterpret_cast<void*>(aligned + size), end - (aligned + size));
  auto* data = reinterpret_cast<unsigned char*>(aligned);
  ::madvise(data, size, MADV_HUGEPAGE);  // a hint; 4 KiB pages where it is refused
  return data;
}

// A tile's raw or compressed image (they can be hundreds of MB), in pages lent by a TileBuffers:
// mapped pages rather than malloc's, so that what the pool does not keep goes back to the system
// at once (through malloc it would raise the mmap threshold and then sit in the heap, where the
// brick cache's budget does not see it).
class PageBuffer {
 public:
  PageBuffer(std::size_t size, TileBuffers& pool) : size_(size), pool_(pool) {
    if (size_ > 0) mapping_ = pool_.take(size_);
  }
  ~PageBuffer() {
    if (mapping_.data) pool_.give_back(mapping_);
  }
  PageBuffer(const PageBuffer&) = delete;
  PageBuffer& operator=(const PageBuffer&) = delete;
  unsigned char* data() { return mapping_.data; }
  const unsigned char* data() const { return mapping_.data; }
  std::size_t size() const { return size_; }

 private:
  std::size_t size_ = 0;
  TileBuffers& pool_;
  TileBuffers::Mapping mapping_;
};

bool smaller(const TileBuffers::Mapping& m, std::size_t capacity) { return m.capacity < capacity; }

constexpr char kMagic[8] = {'S', 'F', 'T', 'I', 'L', 'E', '1', '\n'};
constexpr std::size_t kHeaderBytes = 64;  // 56 bytes of fields + their checksum
// Bytes of one voxel in a tile: formats 3 and 4 store VoxelData's 16 bytes (two float32, four
// u16); formats 1 and 2 stored six float32 (colour and colour weight as floats).
constexpr std::size_t record_bytes(std::uint32_t version) { return version >= 3 ? 16 : 24; }
// From format 4 a block stores a mask of its present voxels (weight != 0) and only their records:
// about half of a block's voxels are absent, and compressing their zeros took a third of LZ4's
// time at a checkpoint (bench/README.md, session 31).
constexpr bool stores_presence(std::uint32_t version) { return version >= 4; }
// From format 5 the raw payload is cut into chunks of whole blocks, each compressed on its own and
// stored behind a chunk header (below). A tile is then written and read through buffers
// of one chunk: as one LZ4 block, its raw and compressed images were two fresh mappings of the
// whole brick's size (hundreds of MB for a large brick, outside the memory budget, their page
// zeroing 3.6 % of igea's integration; bench/README.md, session 33), and the packed bytes went to
// memory and back before LZ4 read them. 256 KiB stay in the core's L2 cache; LZ4's window
// is 64 KiB, so independent chunks compress about as well as one block (igea's tiles +0.04 %).
constexpr bool stores_chunks(std::uint32_t version) { return version >= 5; }
// From format 6 LZ4 compresses a chunk's byte planes (storage/byte_planes.h), not its raw bytes:
// igea's checkpoint 0.89 -> 0.67 of the raw size, with less to write and sync for about as much
// compression time (bench/README.md, session 35).
constexpr bool stores_planes(std::uint32_t version) { return version >= 6; }
// From format 7 the planes are two LZ4 blocks, behind the u32 stored size of the first: the
// field's (planes 0-7, the bytes of distance and weight) at acceleration 4, and the colour's
// (planes 8-15: colour and colour share) at 16. The colour's planes compressed worst (0.6-0.75 of
// their size on igea) for most of LZ4's time; at 16 igea's checkpoint compresses in 0.72 of the
// time for 4.4 % more bytes (bench/README.md, session 45). Acceleration 4 was chosen for formats 5
// and 6: on the present voxels of igea's field it compressed 1.8x faster than 1 for 2.5 % more
// bytes (a checkpoint compresses the whole field; bench/README.md, session 31).
constexpr bool stores_plane_halves(std::uint32_t version) { return version >= 7; }
constexpr int kFieldAcceleration = 4, kColourAcceleration = 16;
constexpr int kHalfAcceleration[2] = {kFieldAcceleration, kColourAcceleration};
// LZ4's bound on one of a format-7 chunk's two blocks.
std::uint32_t half_bound(std::uint32_t raw_n) { return std::uint32_t(LZ4_compressBound(int(raw_n / 2))); }
// The most a chunk of `raw_n` raw bytes may store (LZ4's bound on its block or blocks).
std::uint64_t stored_bound(std::uint32_t version, std::uint32_t raw_n) {
  if (!stores_plane_halves(version)) return std::uint64_t(LZ4_compressBound(int(raw_n)));
  return 4 + 2 * std::uint64_t(half_bound(raw_n));
}
constexpr std::size_t kChunkRaw = std::size_t{256} << 10;  // raw bytes of the writer's chunks, at most
constexpr std::size_t kMaxChunkRaw = std::size_t{1} << 20;  // what a reader accepts
// u32 raw bytes, u32 stored bytes, u64 XXH3-64 of the stored bytes: a chunk is checked before it
// is decompressed, so damage reads as a checksum mismatch, not as whatever LZ4 or the block decoder
// makes of it. The header's payload checksum covers the chunk headers, and through them every byte.
constexpr std::size_t kChunkHeader = 16;
constexpr std::size_t kMaxBlockRaw = 16 + 64 * 16;  // key, mask, 4^3 present voxels
static_assert(kMaxBlockRaw <= kChunkRaw && kChunkRaw <= kMaxChunkRaw);

// Little-endian field packing (the format is little-endian whatever the host).
void put32(unsigned char* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<unsigned char>(v >> (8 * i));
}
void put64(unsigned char* p, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<unsigned char>(v >> (8 * i));
}
std::uint32_t get32(const unsigned char* p) {
  std::uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= std::uint32_t(p[i]) << (8 * i);
  return v;
}
std::uint64_t get64(const unsigned char* p) {
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v |= std::uint64_t(p[i]) << (8 * i);
  return v;
}
void put16(unsigned char* p, std::uint16_t v) {
  p[0] = static_cast<unsigned char>(v);
  p[1] = static_cast<unsigned char>(v >> 8);
}
std::uint16_t get16(const unsigned char* p) { return std::uint16_t(p[0] | (p[1] << 8)); }
void put_float(unsigned char* p, float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, 4);
  put32(p, u);
}
// A voxel's 16-byte record (formats 3 on). On a little-endian host it is the voxel's own bytes.
void put_record(unsigned char* p, const VoxelData& v) {
  if constexpr (std::endian::native == std::endian::little && offsetof(VoxelData, distance) == 0 &&
                offsetof(VoxelData, weight) == 4 && offsetof(VoxelData, colour_fixed) == 8 &&
                offsetof(VoxelData, colour_share) == 14) {
    std::memcpy(p, &v, 16);
  } else {
    put_float(p, v.distance);
    put_float(p + 4, v.weight);
    for (int c = 0; c < 3; ++c) put16(p + 8 + 2 * c, v.colour_fixed[c]);
    put16(p + 14, v.colour_share);
  }
}
float get_float(const unsigned char* p) {
  const std::uint32_t u = get32(p);
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}


void write_all(int fd, const unsigned char* data, std::size_t size, const std::filesystem::path& path) {
  while (size > 0) {
    const ssize_t n = ::write(fd, data, size);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw_write_error(path.string(), "cannot write tile", errno);
    }
    data += n;
    size -= std::size_t(n);
  }
}

void pwrite_all(int fd, const unsigned char* data, std::size_t size, off_t offset, const std::filesystem::path& path) {
  while (size > 0) {
    const ssize_t n = ::pwrite(fd, data, size, offset);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw_write_error(path.string(), "cannot write tile", errno);
    }
    data += n;
    offset += n;
    size -= std::size_t(n);
  }
}

struct XXH3StateDeleter {
  void operator()(XXH3_state_t* s) const { XXH3_freeState(s); }
};
using XXH3State = std::unique_ptr<XXH3_state_t, XXH3StateDeleter>;
XXH3State new_xxh3_state() {
  XXH3State s(XXH3_createState());
  if (!s || XXH3_64bits_reset(s.get()) != XXH_OK) throw std::bad_alloc();
  return s;
}

// The stored payload of a format-7 tile, streamed to `fd` chunk by chunk: blocks are packed into
// the raw chunk until the next might not fit, then the chunk is compressed, hashed and written.
class ChunkWriter {
 public:
  ChunkWriter(int fd, const std::filesystem::path& path, TileBuffers& pool)
      : fd_(fd), path_(path), raw_(kChunkRaw, pool), planes_(kChunkRaw, pool),
        stored_(kChunkHeader + std::size_t(stored_bound(kTileVersion, std::uint32_t(kChunkRaw))), pool),
        hash_(new_xxh3_state()) {}

  // Room for `n` <= kMaxBlockRaw raw bytes; commit(n) after filling them.
  unsigned char* reserve(std::size_t n) {
    if (used_ + n > kChunkRaw) flush();
    return raw_.data() + used_;
  }
  void commit(std::size_t n) {
    used_ += n;
    raw_bytes_ += n;
  }
  // Writes the last chunk; returns the payload checksum (XXH3-64 of the chunk headers).
  std::uint64_t finish() {
    flush();
    return XXH3_64bits_digest(hash_.get());
  }
  std::uint64_t raw_bytes() const { return raw_bytes_; }
  std::uint64_t stored_bytes() const { return stored_bytes_; }

 private:
  void flush() {
    if (used_ == 0) return;
    unsigned char* out = stored_.data();
    to_byte_planes(raw_.data(), used_ / kPlaneUnit, planes_.data());  // every block is whole units
    const int half = int(used_ / 2);  // whole units: planes 0-7, then 8-15
    const int capacity = int(stored_.size() - kChunkHeader);
    int packed = 4;  // the field's stored size, then the two blocks
    for (int i = 0; i < 2; ++i) {
      const int n = LZ4_compress_fast(reinterpret_cast<const char*>(planes_.data()) + i * half,
                                      reinterpret_cast<char*>(out + kChunkHeader + packed), half, capacity - packed,
                                      kHalfAcceleration[i]);
      if (n <= 0) throw std::runtime_error(path_.string() + ": LZ4 compression failed");
      if (i == 0) put32(out + kChunkHeader, std::uint32_t(n));
      packed += n;
    }
    put32(out, std::uint32_t(used_));
    put32(out + 4, std::uint32_t(packed));
    put64(out + 8, XXH3_64bits(out + kChunkHeader, std::size_t(packed)));
    XXH3_64bits_update(hash_.get(), out, kChunkHeader);
    const std::size_t n = kChunkHeader + std::size_t(packed);
    write_all(fd_, out, n, path_);
    stored_bytes_ += n;
    used_ = 0;
  }

  int fd_;
  const std::filesystem::path& path_;
  PageBuffer raw_, planes_, stored_;
  XXH3State hash_;
  std::size_t used_ = 0;  // raw bytes in the chunk under way
  std::uint64_t raw_bytes_ = 0, stored_bytes_ = 0;
};

}  // namespace

TileBuffers::~TileBuffers() {
  for (const Mapping& m : free_) ::munmap(m.data, m.capacity);
}

TileBuffers::Mapping TileBuffers::take(std::size_t size) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = std::lower_bound(free_.begin(), free_.end(), size, smaller);
    if (it != free_.end()) {
      const Mapping m = *it;
      free_.erase(it);
      retained_ -= m.capacity;
      return m;
    }
  }
  // Rounded up to 1 MiB, so that tiles of similar sizes can share a mapping.
  constexpr std::size_t kGrain = std::size_t{1} << 20;
  const std::size_t capacity = (size + kGrain - 1) / kGrain * kGrain;
  return {map_pages(capacity), capacity};
}

void TileBuffers::give_back(Mapping m) {
  if (m.capacity > max_retained_) {
    ::munmap(m.data, m.capacity);
    return;
  }
  std::vector<Mapping> drop;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = std::lower_bound(free_.begin(), free_.end(), m.capacity, smaller);
    free_.insert(it, m);
    retained_ += m.capacity;
    // The largest stay: they are the dearest to fault in again.
    std::size_t n = 0;
    while (retained_ > max_retained_) {
      retained_ -= free_[n].capacity;
      drop.push_back(free_[n++]);
    }
    free_.erase(free_.begin(), free_.begin() + std::ptrdiff_t(n));
  }
  for (const Mapping& d : drop) ::munmap(d.data, d.capacity);
}

std::size_t TileBuffers::retained_bytes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return retained_;
}

namespace {

// A block's presence mask (bit i: voxel i's weight is not 0, so live or erased) and its count.
std::uint64_t presence_mask(const VoxelData* v, std::size_t n, std::size_t* present) {
  std::uint64_t mask = 0;
  std::size_t count = 0, i = 0;
#if defined(__SSE2__) && defined(__x86_64__)
  // Four voxels' weights gathered into one register and compared at once; the count of a 4-bit
  // group read from a table of nibbles (baseline x86-64 has no popcount instruction).
  static_assert(sizeof(VoxelData) == 16 && offsetof(VoxelData, weight) == 4, "weight is lane 1 of a record");
  constexpr std::uint64_t kBitsIn = 0x4332322132212110;  // nibble k: the bits set in k
  for (; i + 4 <= n; i += 4) {
    const float* f = reinterpret_cast<const float*>(v + i);
    const __m128 ab = _mm_shuffle_ps(_mm_loadu_ps(f), _mm_loadu_ps(f + 4), _MM_SHUFFLE(1, 1, 1, 1));
    const __m128 cd = _mm_shuffle_ps(_mm_loadu_ps(f + 8), _mm_loadu_ps(f + 12), _MM_SHUFFLE(1, 1, 1, 1));
    const __m128 weights = _mm_shuffle_ps(ab, cd, _MM_SHUFFLE(2, 0, 2, 0));
    const unsigned bits = unsigned(_mm_movemask_ps(_mm_cmpneq_ps(weights, _mm_setzero_ps())));
    mask |= std::uint64_t(bits) << i;
    count += (kBitsIn >> (4 * bits)) & 15;
  }
#endif
  for (; i < n; ++i) {
    const bool in = v[i].weight != 0;
    mask |= std::uint64_t(in) << i;
    count += in;
  }
  *present = count;
  return mask;
}

// The 8-bit presence mask of part o of a group as bits of its tile block's mask (kGroupToTile
// without a loop): part voxel i = x + 2 y + 4 z sits at tile bit (2 px + x) + 4 (2 py + y) +
// 16 (2 pz + z) for the part's offset (px, py, pz).
constexpr std::uint64_t group_part_bits(std::uint64_t m, int o) {
  const std::uint64_t spread = (m & 3) | (m >> 2 & 3) << 4 | (m >> 4 & 3) << 16 | (m >> 6 & 3) << 20;
  return spread << ((o & 1) * 2 + (o >> 1 & 1) * 8 + (o >> 2) * 32);
}
static_assert([] {
  for (int q = 0; q < 64; ++q)
    if (group_part_bits(std::uint64_t{1} << (q & 7), q >> 3) != std::uint64_t{1} << kGroupToTile[q]) return false;
  return true;
}(), "group_part_bits agrees with kGroupToTile");

}  // namespace

std::uint64_t write_tile(const std::filesystem::path& path, BrickCoord coord, const VoxelTable& voxels, bool durable,
                         TileBuffers* buffers) {
  TileBuffers unpooled(0);  // keeps nothing: pages mapped for this tile alone
  TileBuffers& pool = buffers ? *buffers : unpooled;
  // The table's groups of blocks are the tile's blocks (voxel_table.h: a 4^3 block of the tile is
  // up to eight 2^3 blocks of the table), in origin order, so the bytes do not depend on insertion
  // order.
  struct GroupView {
    VoxelKey origin;
    const BlockGroup* group;
  };
  const int brick_level = voxels.brick_level();
  std::vector<GroupView> blocks;
  blocks.reserve(voxels.group_count());
  voxels.for_each_group([&](VoxelKey o, const BlockGroup& g) { blocks.push_back({o, &g}); });
  std::sort(blocks.begin(), blocks.end(), [](const GroupView& a, const GroupView& b) { return a.origin < b.origin; });
  static_assert(3 * kTileBlockLog <= 6, "a tile block's presence mask is one u64");
  if (blocks.size() > std::numeric_limits<std::uint32_t>::max())
    throw std::length_error(path.string() + ": brick of " + std::to_string(blocks.size()) +
                            " blocks, more than a tile's u32 count; use a finer octree.brick_level");
  constexpr std::size_t kRecord = record_bytes(kTileVersion);
  static_assert(kRecord == kPlaneUnit && kMaxBlockRaw % kPlaneUnit == 0, "a chunk is whole byte-plane units");

  // Temporary name in the same directory: header last (it holds the sizes and checksums), fsync,
  // rename, fsync the directory.
  std::filesystem::path tmp = path;
  tmp += ".tmp." + std::to_string(::getpid());
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw_write_error(tmp.string(), "cannot create tile", errno);
  std::uint64_t total = 0;
  try {
    ChunkWriter chunks(fd, tmp, pool);
    if (::lseek(fd, off_t(kHeaderBytes), SEEK_SET) < 0) throw_write_error(tmp.string(), "cannot write tile", errno);
    // The groups lie scattered over the table's arena, so each one's voxels were a cache miss that
    // stalled the presence scan: ask for a group some places ahead, and for its blocks' lines
    // (a block is at most 2^3 voxels, two lines, 64-byte aligned) once the group has arrived.
    constexpr std::size_t kGroupAhead = 16, kPartsAhead = 8;
    for (std::size_t i = 0; i < blocks.size(); ++i) {
      if (i + kGroupAhead < blocks.size()) __builtin_prefetch(blocks[i + kGroupAhead].group);
      if (i + kPartsAhead < blocks.size()) {
        const BlockGroup& ahead = *blocks[i + kPartsAhead].group;
        for (int o = 0; o < 8; ++o) {
          if (const VoxelData* v = ahead.part[o].load(std::memory_order_relaxed)) {
            __builtin_prefetch(v);
            __builtin_prefetch(reinterpret_cast<const char*>(v) + 64);  // a 1-voxel block's arena line ends there
          }
        }
      }
      const GroupView& b = blocks[i];
      const VoxelKey origin = b.origin;
      const int log = tile_block_log(origin.level(), brick_level);
      std::uint64_t mask;
      std::size_t present = 0;
      const VoxelData* parts[8];
      const bool split = block_log(origin.level(), brick_level) != log;  // eight 2^3 blocks
      if (!split) {
        parts[0] = b.group->part[0].load(std::memory_order_relaxed);
        mask = parts[0] ? presence_mask(parts[0], std::size_t{1} << (3 * log), &present) : 0;
      } else {  // the tile block's mask from its parts' masks, in tile order (kGroupToTile)
        mask = 0;
        for (int o = 0; o < 8; ++o) {
          parts[o] = b.group->part[o].load(std::memory_order_relaxed);
          if (!parts[o]) continue;
          std::size_t count = 0;
          mask |= group_part_bits(presence_mask(parts[o], 8, &count), o);
          present += count;
        }
      }
      const std::size_t bytes = 16 + present * kRecord;
      unsigned char* p = chunks.reserve(bytes);
      put64(p, origin.bits);
      put64(p + 8, mask);
      p += 16;
      for (std::uint64_t m = mask; m != 0; m &= m - 1, p += kRecord) {
        const int t = std::countr_zero(m), q = kTileToGroup[t];
        put_record(p, split ? parts[q >> 3][q & 7] : parts[0][t]);
      }
      chunks.commit(bytes);
    }
    const std::uint64_t payload_checksum = chunks.finish();
    unsigned char h[kHeaderBytes];
    std::memcpy(h, kMagic, 8);
    put32(h + 8, kTileVersion);
    put32(h + 12, std::uint32_t(voxels.brick_level()));
    put32(h + 16, coord.x);
    put32(h + 20, coord.y);
    put32(h + 24, coord.z);
    put32(h + 28, std::uint32_t(blocks.size()));
    put64(h + 32, chunks.raw_bytes());
    put64(h + 40, chunks.stored_bytes());
    put64(h + 48, payload_checksum);
    put64(h + 56, tile_checksum(kTileVersion, h, 56));
    pwrite_all(fd, h, kHeaderBytes, 0, tmp);
    total = kHeaderBytes + chunks.stored_bytes();
    if (durable && ::fsync(fd) != 0) throw_write_error(tmp.string(), "cannot sync tile", errno);
#if defined(__linux__)
    // Not durable yet, but on its way: a checkpoint's sync (one syncfs for many tiles) then waits
    // for the disk only on the last tiles' bytes, as the device writes while the next tiles are
    // packed and compressed. A spilled tile's writeback starts now too, rather than at the next
    // checkpoint; one replaced before then costs a disk write it might have been spared. The
    // submission runs on this thread (where syncfs left it to a flusher). A hint: its failure
    // leaves the sync to do all the work, and write errors still surface there.
    if (!durable) ::sync_file_range(fd, 0, 0, SYNC_FILE_RANGE_WRITE);
#endif
  } catch (...) {
    ::close(fd);
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    throw;
  }
  if (::close(fd) != 0) {
    const int err = errno;
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    throw_write_error(tmp.string(), "cannot close tile", err);
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    throw_write_error(path.string(), "cannot rename tile into place", ec.value());
  }
  const std::filesystem::path dir = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
  const int dfd = durable ? ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC) : -1;
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
  return total;
}

std::uint64_t tile_checksum(std::uint32_t version, const void* data, std::size_t size) {
  return version == 1 ? fnv1a64(data, size) : XXH3_64bits(data, size);
}

namespace {

// Decodes a raw payload's blocks into a table, checking everything a damaged file could get wrong.
class BlockDecoder {
 public:
  BlockDecoder(const std::string& name, std::uint32_t version, int brick_level, BrickCoord coord,
               std::uint32_t block_count, VoxelTable& out)
      : name_(name), version_(version), brick_level_(brick_level), coord_(coord), block_count_(block_count), out_(out) {}

  // Decodes one block from p (end: the end of the raw bytes at hand); returns the byte after it.
  const unsigned char* block(const unsigned char* p, const unsigned char* end) {
    const std::uint32_t b = decoded_;
    if (b == block_count_) throw bad("more blocks than the header's " + std::to_string(block_count_));
    if (end - p < 8) throw bad("block " + std::to_string(b) + " runs past the payload");
    const VoxelKey origin{get64(p)};
    p += 8;
    const int level = origin.level();
    if ((origin.bits >> 62) != 0 || level > kMaxLevel || !valid_voxel(level, origin.x(), origin.y(), origin.z()))
      throw bad("block " + std::to_string(b) + " has an invalid key");
    if (b > 0 && origin.bits <= previous_) throw bad("blocks out of order or duplicated");
    previous_ = origin.bits;
    const int log = tile_block_log(level, brick_level_);
    if (aligned_origin(origin, log) != origin) throw bad("block " + std::to_string(b) + " is not aligned");
    const BrickCoord bc = brick_of(origin, brick_level_);
    if (bc.x != coord_.x || bc.y != coord_.y || bc.z != coord_.z)
      throw bad("block " + std::to_string(b) + " lies outside the brick");
    const std::size_t n = std::size_t{1} << (3 * log);
    const std::uint64_t all = n == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << n) - 1;
    std::uint64_t present = all;
    if (stores_presence(version_)) {
      if (end - p < 8) throw bad("block " + std::to_string(b) + " runs past the payload");
      present = get64(p);
      p += 8;
      if ((present & ~all) != 0) throw bad("block " + std::to_string(b) + " marks voxels beyond its size");
    }
    const std::size_t record = record_bytes(version_);
    if (std::size_t(end - p) < std::size_t(std::popcount(present)) * record)
      throw bad("block " + std::to_string(b) + " runs past the payload");
    // The table's blocks are smaller than the tile's at the finer levels (voxel_table.h): there a
    // record goes to its place in the group's blocks (kTileToGroup), and only the blocks holding a
    // voxel are made. Tiles without presence masks (versions 1-3) store absent voxels too: those
    // tile blocks are decoded into `gathered_` and split.
    // The group is made even for a block with no voxel, as the 4^3 table made the block, so that
    // a tile read and written again keeps its bytes.
    const int table_log = block_log(level, brick_level_);
    const bool by_part = table_log != log && stores_presence(version_);
    VoxelData* data = nullptr;
    BlockGroup* group = nullptr;
    if (table_log == log) {
      data = out_.block(origin, true).data;
    } else {
      group = out_.group(origin, true);
      if (!by_part) {
        data = gathered_;
        std::fill_n(gathered_, n, VoxelData{});
      }
    }
    for (std::uint64_t m = present; m != 0; m &= m - 1, p += record) {
      const int t = std::countr_zero(m);
      VoxelData& v = by_part ? out_.make_part(*group, kTileToGroup[t] >> 3, table_log)[kTileToGroup[t] & 7] : data[t];
      v.distance = get_float(p);
      v.weight = get_float(p + 4);
      if (!std::isfinite(v.distance) || !std::isfinite(v.weight))
        throw bad("block " + std::to_string(b) + " holds a non-finite value");
      if (stores_presence(version_) && v.weight == 0) throw bad("block " + std::to_string(b) + " stores an absent voxel");
      if (version_ >= 3) {
        for (int c = 0; c < 3; ++c) v.colour_fixed[c] = get16(p + 8 + 2 * c);
        v.colour_share = get16(p + 14);
      } else {
        float colour[3];
        for (int c = 0; c < 3; ++c) colour[c] = get_float(p + 8 + 4 * c);
        const float colour_weight = get_float(p + 20);
        if (!std::isfinite(colour[0]) || !std::isfinite(colour[1]) || !std::isfinite(colour[2]) ||
            !std::isfinite(colour_weight))
          throw bad("block " + std::to_string(b) + " holds a non-finite value");
        v.set_colour(colour, colour_weight);
      }
    }
    if (table_log != log && !by_part) split(origin, log, table_log);
    ++decoded_;
    return p;
  }
  std::uint32_t decoded() const { return decoded_; }

 private:
  InputError bad(const std::string& what) const { return input_error(name_, "damaged tile: " + what); }

  const std::string& name_;  // the tile's path, for errors
  const std::uint32_t version_;
  const int brick_level_;
  const BrickCoord coord_;
  const std::uint32_t block_count_;
  VoxelTable& out_;
  // Copies the tile block in gathered_ (edge 2^log, origin `origin`) into the table's blocks of
  // edge 2^table_log that hold a voxel (weight != 0).
  void split(VoxelKey origin, int log, int table_log) {
    const std::uint32_t parts = 1u << (log - table_log), edge = 1u << table_log;
    for (std::uint32_t pz = 0; pz < parts; ++pz)
      for (std::uint32_t py = 0; py < parts; ++py)
        for (std::uint32_t px = 0; px < parts; ++px) {
          const std::uint32_t x0 = px * edge, y0 = py * edge, z0 = pz * edge;
          auto at = [&](std::uint32_t x, std::uint32_t y, std::uint32_t z) -> const VoxelData& {
            return gathered_[(((z0 + z) << log | (y0 + y)) << log) | (x0 + x)];
          };
          bool any = false;
          for (std::uint32_t z = 0; z < edge; ++z)
            for (std::uint32_t y = 0; y < edge; ++y)
              for (std::uint32_t x = 0; x < edge; ++x) any = any || at(x, y, z).weight != 0;
          if (!any) continue;
          VoxelData* const to =
              out_.block(VoxelKey::make(origin.level(), origin.x() + x0, origin.y() + y0, origin.z() + z0), true).data;
          for (std::uint32_t z = 0, v = 0; z < edge; ++z)
            for (std::uint32_t y = 0; y < edge; ++y)
              for (std::uint32_t x = 0; x < edge; ++x, ++v) to[v] = at(x, y, z);
        }
  }

  std::uint32_t decoded_ = 0;
  std::uint64_t previous_ = 0;  // the last block's origin key
  VoxelData gathered_[std::size_t{1} << (3 * kTileBlockLog)];
};

}  // namespace

BrickCoord read_tile(const std::filesystem::path& path, VoxelTable& out, TileBuffers* buffers) {
  TileBuffers unpooled(0);
  TileBuffers& pool = buffers ? *buffers : unpooled;
  const std::string name = path.string();
  auto bad = [&](const std::string& what) { return input_error(name, "damaged tile: " + what); };
  std::ifstream in(path, std::ios::binary);
  if (!in) throw input_error(name, "cannot open tile");
  in.seekg(0, std::ios::end);
  const std::uint64_t file_size = std::uint64_t(in.tellg());
  in.seekg(0);
  if (file_size < kHeaderBytes) throw bad("shorter than its 64-byte header (" + std::to_string(file_size) + " bytes)");
  unsigned char h[kHeaderBytes];
  in.read(reinterpret_cast<char*>(h), kHeaderBytes);
  if (!in) throw bad("cannot read the header");
  if (std::memcmp(h, kMagic, 8) != 0) throw bad("wrong magic (not a scalefuse tile)");
  // The version picks the checksum, so it is read before the header is known to be intact; a
  // damaged version gives the wrong checksum and fails below all the same.
  std::uint32_t version = get32(h + 8);
  if (version < 1 || version > kTileVersion) version = kTileVersion;
  if (get64(h + 56) != tile_checksum(version, h, 56)) throw bad("header checksum mismatch");
  if (get32(h + 8) != version)
    throw bad("format version " + std::to_string(get32(h + 8)) + ", this build reads 1 to " + std::to_string(kTileVersion));
  const int brick_level = int(get32(h + 12));
  if (brick_level != out.brick_level())
    throw bad("brick level " + std::to_string(brick_level) + ", the job uses " + std::to_string(out.brick_level()));
  const BrickCoord coord{get32(h + 16), get32(h + 20), get32(h + 24)};
  const std::uint32_t block_count = get32(h + 28);
  const std::uint64_t raw_size = get64(h + 32), stored_size = get64(h + 40);
  if (stored_size != file_size - kHeaderBytes)
    throw bad("payload of " + std::to_string(file_size - kHeaderBytes) + " bytes, header says " +
              std::to_string(stored_size) + " (truncated?)");
  // LZ4 expands at most 255:1; a larger raw size is a lie, not an allocation to make.
  if ((!stores_chunks(version) && raw_size > std::uint64_t(LZ4_MAX_INPUT_SIZE)) || raw_size > 255 * stored_size + 16)
    throw bad("implausible raw size " + std::to_string(raw_size));
  if (out.group_count() != 0) throw std::logic_error(name + ": read_tile into a non-empty table");
  // The index is sized once for the blocks to come, but only by bytes decompressed and checked: a
  // block takes at least its key and mask (16 raw bytes; 8 without masks), so neither a damaged
  // count nor a damaged raw size reserves more than the payload holds.
  const std::uint64_t least_block_bytes = stores_presence(version) ? 16 : 8;
  const auto reserve_for = [&](std::uint64_t raw_bytes) {
    out.reserve(std::min<std::uint64_t>(block_count, out.group_count() + raw_bytes / least_block_bytes));
  };
  BlockDecoder decoder(name, version, brick_level, coord, block_count, out);
  try {
    if (stores_chunks(version)) {
      // Chunk by chunk: each is hashed, decompressed and decoded before the next is read.
      const bool any = stored_size > 0;  // an empty brick's tile has no chunk
      PageBuffer stored(any ? kChunkHeader + std::size_t(stored_bound(version, std::uint32_t(kMaxChunkRaw))) : 0, pool);
      PageBuffer raw(any ? kMaxChunkRaw : 0, pool);
      PageBuffer planes(any && stores_planes(version) ? kMaxChunkRaw : 0, pool);
      const XXH3State hash = new_xxh3_state();
      std::uint64_t left = stored_size, raw_seen = 0;
      for (std::uint64_t chunk = 0; left > 0; ++chunk) {
        const std::string which = "chunk " + std::to_string(chunk);
        if (left < kChunkHeader) throw bad(which + " runs past the payload");
        unsigned char* s = stored.data();
        in.read(reinterpret_cast<char*>(s), kChunkHeader);
        if (!in) throw bad("cannot read " + which);
        const std::uint32_t raw_n = get32(s), stored_n = get32(s + 4);
        if (raw_n == 0 || raw_n > kMaxChunkRaw)
          throw bad(which + " of " + std::to_string(raw_n) + " raw bytes (1 to " + std::to_string(kMaxChunkRaw) + ")");
        if (stores_planes(version) && raw_n % kPlaneUnit != 0)
          throw bad(which + " of " + std::to_string(raw_n) + " raw bytes, not whole 16-byte units");
        if (stored_n == 0 || stored_n > stored_bound(version, raw_n) || stored_n > left - kChunkHeader)
          throw bad(which + " of " + std::to_string(stored_n) + " stored bytes does not fit");
        in.read(reinterpret_cast<char*>(s + kChunkHeader), std::streamsize(stored_n));
        if (!in) throw bad("cannot read " + which);
        if (XXH3_64bits(s + kChunkHeader, stored_n) != get64(s + 8)) throw bad("payload checksum mismatch");
        XXH3_64bits_update(hash.get(), s, kChunkHeader);
        left -= kChunkHeader + stored_n;
        raw_seen += raw_n;
        if (raw_seen > raw_size) throw bad("chunks hold more than the header's " + std::to_string(raw_size) + " raw bytes");
        // One LZ4 block, or from format 7 two, each half of the planes, behind the first's stored
        // size. The stored buffer holds a whole chunk of the largest size, so the size is read
        // before stored_n is known to cover it.
        const unsigned char* packed = s + kChunkHeader;
        std::uint32_t block_stored[2] = {stored_n, 0};
        int blocks = 1;
        if (stores_plane_halves(version)) {
          const std::uint32_t field = get32(packed);
          if (stored_n < 4 || field == 0 || field >= stored_n - 4 || field > half_bound(raw_n) ||
              stored_n - 4 - field > half_bound(raw_n))
            throw bad(which + "'s halves do not fit its " + std::to_string(stored_n) + " stored bytes");
          packed += 4;
          block_stored[0] = field;
          block_stored[1] = stored_n - 4 - field;
          blocks = 2;
        }
        unsigned char* unpacked = stores_planes(version) ? planes.data() : raw.data();
        const int block_raw = int(raw_n) / blocks;
        for (int i = 0; i < blocks; ++i) {
          const int n = LZ4_decompress_safe(reinterpret_cast<const char*>(packed), reinterpret_cast<char*>(unpacked),
                                            int(block_stored[i]), block_raw);
          if (n != block_raw) throw bad(which + " does not decompress to its stated size");
          packed += block_stored[i];
          unpacked += block_raw;
        }
        if (stores_planes(version)) from_byte_planes(planes.data(), raw_n / kPlaneUnit, raw.data());
        reserve_for(raw_n);
        // A chunk holds whole blocks.
        const unsigned char* p = raw.data();
        const unsigned char* end = p + raw_n;
        while (p != end) p = decoder.block(p, end);
      }
      if (XXH3_64bits_digest(hash.get()) != get64(h + 48)) throw bad("payload checksum mismatch");
      if (raw_seen != raw_size)
        throw bad("chunks hold " + std::to_string(raw_seen) + " raw bytes, header says " + std::to_string(raw_size));
      if (decoder.decoded() != block_count)
        throw bad(std::to_string(decoder.decoded()) + " blocks, header says " + std::to_string(block_count));
      return coord;
    }
    // Formats 1 to 4: one LZ4 block, read and decompressed whole.
    PageBuffer stored(stored_size, pool);
    in.read(reinterpret_cast<char*>(stored.data()), std::streamsize(stored_size));
    if (!in) throw bad("cannot read the payload");
    if (get64(h + 48) != tile_checksum(version, stored.data(), stored.size())) throw bad("payload checksum mismatch");
    PageBuffer raw(raw_size, pool);
    if (raw_size > 0) {
      const int n = LZ4_decompress_safe(reinterpret_cast<const char*>(stored.data()),
                                        reinterpret_cast<char*>(raw.data()), int(stored_size), int(raw_size));
      if (n < 0 || std::uint64_t(n) != raw_size) throw bad("LZ4 payload does not decompress to its stated size");
      reserve_for(raw_size);
    }
    const unsigned char* p = raw.data();
    const unsigned char* end = raw.data() + raw.size();
    while (decoder.decoded() < block_count) p = decoder.block(p, end);
    if (p != end) throw bad("trailing bytes after the last block");
  } catch (...) {
    out.clear();  // a damaged tile leaves no half of a brick behind
    throw;
  }
  return coord;
}

}  // namespace sf
