// A synthetic scene's synth.json (scalefuse eval reads it).
#include "engine/synth/scene_writer.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = sf::fuzz::put("synth.json", data, size);
  sf::fuzz::expect_accept_or_input_error([&] { (void)sf::read_scene_info(path); });
  return 0;
}
