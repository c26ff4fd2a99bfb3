#pragma once
// An open-addressing map from 64-bit keys to 32-bit values, filled once and then only read: the
// lattice lookups of a window (cube corners, grid cells) run millions of times per second, where
// std::unordered_map's nodes and a sorted vector's binary search both cost a cache miss per step.
#include <cstdint>
#include <vector>

namespace sf::extract_detail {

class FlatMap {
 public:
  static constexpr std::uint64_t kEmpty = ~std::uint64_t{0};  // not a valid key
  explicit FlatMap(std::size_t expected) {
    std::size_t size = 16;
    shift_ = 60;
    while (size < 2 * expected) {
      size *= 2;
      --shift_;
    }
    keys_.assign(size, kEmpty);
    values_.resize(size);
    mask_ = size - 1;
  }
  // Keeps the first value of a key inserted twice.
  void insert(std::uint64_t key, std::uint32_t value) {
    for (std::size_t i = slot(key);; i = (i + 1) & mask_) {
      if (keys_[i] == key) return;
      if (keys_[i] == kEmpty) {
        keys_[i] = key;
        values_[i] = value;
        return;
      }
    }
  }
  // The value, or -1.
  std::int64_t find(std::uint64_t key) const {
    for (std::size_t i = slot(key);; i = (i + 1) & mask_) {
      if (keys_[i] == key) return values_[i];
      if (keys_[i] == kEmpty) return -1;
    }
  }

 private:
  // Fibonacci hashing: the product's top bits.
  std::size_t slot(std::uint64_t key) const { return std::size_t((key * 0x9E3779B97F4A7C15ull) >> shift_); }
  std::vector<std::uint64_t> keys_;
  std::vector<std::uint32_t> values_;
  std::size_t mask_;
  int shift_;
};

}  // namespace sf::extract_detail
