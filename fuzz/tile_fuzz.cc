// A brick tile (JOB/tiles/*.tile, docs/formats.md). With the first byte even the rest is the whole
// file; odd, the rest after 16 bytes (block count and brick coordinates) is the raw payload and the
// harness wraps it in a valid header, one LZ4 chunk and checksums, so the fuzzer reaches the block
// decoder behind them.
#include <lz4.h>

#include <algorithm>
#include <cstring>
#include <vector>

#include "engine/hash.h"
#include "fuzz/fuzz_util.h"
#include "storage/tile_file.h"

namespace {
void put32(unsigned char* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<unsigned char>(v >> (8 * i));
}
void put64(unsigned char* p, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<unsigned char>(v >> (8 * i));
}
std::uint32_t get32(const std::uint8_t* p) { return std::uint32_t(p[0]) | p[1] << 8 | p[2] << 16 | std::uint32_t(p[3]) << 24; }
constexpr int kBrickLevel = 3;
constexpr std::uint32_t kWrappedVersion = 5;  // odd inputs' chunk format (below)
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  std::vector<unsigned char> file;
  if ((data[0] & 1) == 0) {
    file.assign(data + 1, data + size);
  } else {
    if (size < 17) return 0;
    const std::uint8_t* raw = data + 17;
    const std::size_t raw_size = size - 17;
    // The raw payload as one chunk of format 5 (u32 raw bytes, u32 stored bytes, u64 XXH3-64 of the
    // stored bytes, LZ4 block of the raw bytes; none for an empty payload), which the reader still
    // reads and decodes with the same block decoder as the current format: labelled with the
    // current version, the chunk would be read as two halves of byte planes, and fail before the
    // blocks.
    std::vector<char> stored;
    if (raw_size > 0) {
      stored.resize(16 + std::size_t(LZ4_compressBound(int(raw_size))));
      const int n = LZ4_compress_default(reinterpret_cast<const char*>(raw), stored.data() + 16, int(raw_size),
                                         int(stored.size() - 16));
      auto* c = reinterpret_cast<unsigned char*>(stored.data());
      put32(c, std::uint32_t(raw_size));
      put32(c + 4, std::uint32_t(n));
      put64(c + 8, sf::tile_checksum(kWrappedVersion, c + 16, std::size_t(n)));
      stored.resize(16 + std::size_t(n));
    }
    unsigned char h[64] = {'S', 'F', 'T', 'I', 'L', 'E', '1', '\n'};
    put32(h + 8, kWrappedVersion);
    put32(h + 12, kBrickLevel);
    for (int i = 0; i < 3; ++i) put32(h + 16 + 4 * i, get32(data + 5 + 4 * i) % (1u << kBrickLevel));
    put32(h + 28, get32(data + 1) % 4096);
    put64(h + 32, raw_size);
    put64(h + 40, stored.size());
    put64(h + 48, sf::tile_checksum(kWrappedVersion, stored.data(), std::min<std::size_t>(stored.size(), 16)));
    put64(h + 56, sf::tile_checksum(kWrappedVersion, h, 56));
    file.assign(h, h + 64);
    file.insert(file.end(), stored.begin(), stored.end());
  }
  const auto path = sf::fuzz::put("b.tile", file.data(), file.size());
  sf::fuzz::expect_accept_or_input_error([&] {
    sf::VoxelTable table(kBrickLevel);
    (void)sf::read_tile(path, table);
  });
  return 0;
}
