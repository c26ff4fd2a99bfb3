#pragma once
// Reading and writing the raster images our formats use (PNG 8/16-bit, JPEG), via libpng/libjpeg.
#include <cstdint>
#include <filesystem>
#include <vector>

namespace sf {

struct Image8 {  // interleaved, row-major
  int width = 0, height = 0, channels = 0;
  std::vector<std::uint8_t> data;
};
struct Image16 {  // single channel, row-major
  int width = 0, height = 0;
  std::vector<std::uint16_t> data;
};

// PNG (8-bit grey/grey+alpha/RGB/RGBA, palette) or JPEG, decided by content; returned as RGB
// (channels == 3). Throws InputError naming the file on failure.
Image8 read_image_rgb(const std::filesystem::path& path);
// 16-bit single-channel PNG (e.g. depth). Throws InputError naming the file on failure.
Image16 read_png16(const std::filesystem::path& path);
// Writers; write to a temporary name then rename, so readers never see a partial file. They throw
// std::invalid_argument if the image's size and data disagree, std::runtime_error naming the
// file if it cannot be written.
void write_png8(const std::filesystem::path& path, const Image8& image);   // channels 1 or 3
void write_png16(const std::filesystem::path& path, const Image16& image);

}  // namespace sf
