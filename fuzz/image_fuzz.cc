// Raster images: a 16-bit depth PNG (first byte even) or a colour PNG/JPEG (odd).
#include "engine/input/image_io.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const bool depth = (data[0] & 1) == 0;
  const auto path = sf::fuzz::put(depth ? "d.depth.png" : "c.color.png", data + 1, size - 1);
  sf::fuzz::expect_accept_or_input_error([&] {
    if (depth) {
      const sf::Image16 im = sf::read_png16(path);
      if (im.data.size() != std::size_t(im.width) * std::size_t(im.height)) __builtin_trap();
    } else {
      const sf::Image8 im = sf::read_image_rgb(path);
      if (im.channels != 3 || im.data.size() != std::size_t(im.width) * std::size_t(im.height) * 3) __builtin_trap();
    }
  });
  return 0;
}
