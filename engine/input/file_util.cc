#include "engine/input/file_util.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <system_error>

#include "engine/error.h"

namespace sf::input_detail {

namespace fs = std::filesystem;

std::vector<std::uint8_t> read_file_bytes(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw input_error(path.string(), "missing file");
  const std::uintmax_t size = fs::file_size(path, ec);
  if (ec) throw input_error(path.string(), "cannot read file size: " + ec.message());
  errno = 0;
  std::ifstream in(path, std::ios::binary);
  if (!in) throw input_error(path.string(), std::string("cannot open file: ") + (errno ? std::strerror(errno) : "unknown reason"));
  std::vector<std::uint8_t> bytes(size);
  if (size > 0 && !in.read(reinterpret_cast<char*>(bytes.data()), std::streamsize(size)))
    throw input_error(path.string(), "cannot read file");
  return bytes;
}

std::string read_file_text(const fs::path& path) {
  const auto bytes = read_file_bytes(path);
  return std::string(bytes.begin(), bytes.end());
}

fs::path temp_sibling(const fs::path& path) {
  // pid + counter: unique across the processes and threads that may write the same folder.
  static std::atomic<unsigned> counter{0};
  fs::path tmp = path;
  tmp += ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter++);
  return tmp;
}

void commit_temp(const fs::path& tmp, const fs::path& path) {
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    fs::remove(tmp, ec);
    throw std::runtime_error(path.string() + ": cannot move the written file into place");
  }
}

std::vector<std::string_view> split_ws(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t i = 0;
  const auto is_space = [](char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f'; };
  while (i < line.size()) {
    while (i < line.size() && is_space(line[i])) ++i;
    const std::size_t start = i;
    while (i < line.size() && !is_space(line[i])) ++i;
    if (i > start) out.push_back(line.substr(start, i - start));
  }
  return out;
}

std::string_view trim(std::string_view line) {
  const char* ws = " \t\r\n\v\f";
  const std::size_t a = line.find_first_not_of(ws);
  if (a == std::string_view::npos) return {};
  const std::size_t b = line.find_last_not_of(ws);
  return line.substr(a, b - a + 1);
}

std::vector<Rgb8> sample_colour(const Image8& image, int width, int height) {
  std::vector<Rgb8> out(std::size_t(width) * height);
  const double sx = double(image.width) / width, sy = double(image.height) / height;
  // Each column's byte offset in a source row, once per image rather than once per pixel (every
  // depth map is read once per plan tile that it reaches).
  std::vector<std::size_t> src_offset(static_cast<std::size_t>(width));
  for (int col = 0; col < width; ++col)
    src_offset[std::size_t(col)] = std::size_t(std::min(image.width - 1, int((col + 0.5) * sx))) * image.channels;
  const bool grey = image.channels < 3;
  for (int row = 0; row < height; ++row) {
    const int src_row = std::min(image.height - 1, int((row + 0.5) * sy));
    const std::uint8_t* const line = &image.data[std::size_t(src_row) * image.width * image.channels];
    Rgb8* const dst = &out[std::size_t(row) * width];
    if (grey) {
      for (int col = 0; col < width; ++col) {
        const std::uint8_t v = line[src_offset[std::size_t(col)]];
        dst[col] = Rgb8{v, v, v};
      }
    } else {
      for (int col = 0; col < width; ++col) {
        const std::uint8_t* p = line + src_offset[std::size_t(col)];
        dst[col] = Rgb8{p[0], p[1], p[2]};
      }
    }
  }
  return out;
}

void check_depth_size(const fs::path& path, long long width, long long height) {
  if (width >= 2 && height >= 2) return;
  throw input_error(path.string(), "a depth map of " + std::to_string(width) + "x" + std::to_string(height) +
                                       " samples holds no triangle (at least 2x2 needed)");
}

void check_depths(const fs::path& path, const std::vector<float>& depth, int width) {
  check_depth_size(path, width, width > 0 ? (long long)(depth.size() / std::size_t(width)) : 0);
  for (std::size_t i = 0; i < depth.size(); ++i) {
    const float d = depth[i];
    if (std::isfinite(d) && d >= 0) continue;
    throw input_error(path.string(), "depth " + std::to_string(d) + " at pixel (col " + std::to_string(i % width) +
                                         ", row " + std::to_string(i / width) +
                                         "); depths must be finite and >= 0 (0 = no depth)");
  }
}

}  // namespace sf::input_detail
