#pragma once
// Small file helpers shared by the readers (internal to sf_input).
#include <bit>
#include <charconv>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "engine/depth_frame.h"
#include "engine/input/image_io.h"

namespace sf::input_detail {

// Whole file as bytes. Throws InputError "missing file" / "cannot read" naming the path.
std::vector<std::uint8_t> read_file_bytes(const std::filesystem::path& path);
// Whole file as text (same errors).
std::string read_file_text(const std::filesystem::path& path);

// A unique sibling name for writing `path` atomically: write there, then rename over `path`.
std::filesystem::path temp_sibling(const std::filesystem::path& path);
// Renames `tmp` onto `path`; removes `tmp` and throws std::runtime_error naming `path` on failure.
void commit_temp(const std::filesystem::path& tmp, const std::filesystem::path& path);

// Whitespace-separated tokens of a line (views into `line`).
std::vector<std::string_view> split_ws(std::string_view line);
// Line without leading/trailing whitespace (including '\r').
std::string_view trim(std::string_view line);

// Parses a whole token as a number; false on junk, overflow or an empty token. Accepts a leading
// '+', which from_chars does not.
template <typename T>
bool parse_number(std::string_view token, T* out) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  if (token.empty()) return false;
  const char* end = token.data() + token.size();
  const auto r = std::from_chars(token.data(), end, *out);
  return r.ec == std::errc() && r.ptr == end;
}

// Colour for a `width` x `height` depth map from an image of the same aspect: nearest sampling of
// the image pixel whose area contains the depth pixel's centre (pixel centres at +0.5 in both).
std::vector<Rgb8> sample_colour(const Image8& image, int width, int height);

// Validates a depth map read from `path`: 0 marks an invalid sample; NaN, infinity and negative
// values mean the file is bad, so they throw InputError naming the file and the first bad pixel.
void check_depths(const std::filesystem::path& path, const std::vector<float>& depth, int width);
// A depth map smaller than 2x2 samples holds no triangle: a sign of a broken file, not data.
void check_depth_size(const std::filesystem::path& path, long long width, long long height);

// Little-endian scalar at data[offset]; the caller has checked the bounds.
template <typename T>
T load_le(const std::uint8_t* data) {
  // The formats we read are little-endian and so are the hosts we build for; a big-endian port
  // would byte-swap here.
  static_assert(std::endian::native == std::endian::little);
  static_assert(std::is_trivially_copyable_v<T>);
  T v;
  std::memcpy(&v, data, sizeof(T));
  return v;
}

}  // namespace sf::input_detail
