// An MVE image (.mvei), then channel 0 as float (what depth and confidence go through).
#include "engine/input/mve_io.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = sf::fuzz::put("depth-L0.mvei", data, size);
  sf::fuzz::expect_accept_or_input_error([&] {
    const sf::MveImage image = sf::read_mvei(path);
    const std::vector<float> c0 = sf::mvei_channel0_as_float(image, path);
    if (c0.size() != std::size_t(image.width) * std::size_t(image.height)) __builtin_trap();
  });
  return 0;
}
