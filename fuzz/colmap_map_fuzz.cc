// A COLMAP dense map (stereo/depth_maps/*.bin): "W&H&C&" then float32 little-endian.
#include "engine/input/colmap_io.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = sf::fuzz::put("a.png.geometric.bin", data, size);
  sf::fuzz::expect_accept_or_input_error([&] {
    const sf::ColmapArray a = sf::read_colmap_array(path);
    // What the reader promises: the header's size is the data's.
    if (a.data.size() != std::size_t(a.width) * std::size_t(a.height) * std::size_t(a.channels)) __builtin_trap();
  });
  return 0;
}
