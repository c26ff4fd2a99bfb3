#pragma once
// FNV-1a, 64 bit: checksums of tiles and identities of depth maps. Not cryptographic; it detects
// damage and changed inputs, which is all a job directory needs.
#include <cstddef>
#include <cstdint>

namespace sf {

inline std::uint64_t fnv1a64(const void* data, std::size_t size, std::uint64_t h = 0xcbf29ce484222325ull) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < size; ++i) {
    h ^= p[i];
    h *= 0x100000001b3ull;
  }
  return h;
}

}  // namespace sf
