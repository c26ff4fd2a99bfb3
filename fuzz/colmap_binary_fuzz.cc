// COLMAP's binary model: cameras.bin (first byte even) or images.bin (odd).
#include "engine/input/colmap_io.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const bool cameras = (data[0] & 1) == 0;
  const auto path = sf::fuzz::put(cameras ? "cameras.bin" : "images.bin", data + 1, size - 1);
  sf::fuzz::expect_accept_or_input_error([&] {
    if (cameras) sf::read_colmap_cameras(path);
    else sf::read_colmap_images(path);
  });
  return 0;
}
