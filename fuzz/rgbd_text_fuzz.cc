// The RGB-D sequence's text files through the reader: camera-intrinsics.txt (first byte even) or
// a frame's pose.txt (odd), next to a valid 4x3 depth PNG and the other file valid.
#include <cmath>

#include "engine/input/image_io.h"
#include "engine/input/readers.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  static const bool once = [] {
    std::filesystem::create_directories(sf::fuzz::work_dir() / "rgbd");
    sf::write_png16(sf::fuzz::work_dir() / "rgbd/frame-000000.depth.png", sf::Image16{4, 3, std::vector<std::uint16_t>(12, 1500)});
    return true;
  }();
  (void)once;
  const bool intrinsics = (data[0] & 1) == 0;
  const std::string valid_k = "5 0 2\n0 5 1.5\n0 0 1\n", valid_pose = "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n";
  if (intrinsics) {
    sf::fuzz::put("rgbd/camera-intrinsics.txt", data + 1, size - 1);
    sf::fuzz::put("rgbd/frame-000000.pose.txt", valid_pose);
  } else {
    sf::fuzz::put("rgbd/camera-intrinsics.txt", valid_k);
    sf::fuzz::put("rgbd/frame-000000.pose.txt", data + 1, size - 1);
  }
  sf::fuzz::expect_accept_or_input_error([&] {
    sf::InputOptions o;
    o.format = "rgbd";
    const auto source = sf::open_rgbd(sf::fuzz::work_dir() / "rgbd", o);
    const sf::DepthFrame f = source->load(0);
    for (std::size_t i = 0; i < f.size(); ++i)
      if (f.valid[i] && !f.position[i].allFinite()) __builtin_trap();  // accepted input, finite samples
  });
  return 0;
}
