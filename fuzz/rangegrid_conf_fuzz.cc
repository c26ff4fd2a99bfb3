// A range-grid registration (.conf): bmesh lines with translation and quaternion.
#include "engine/input/rangegrid_io.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = sf::fuzz::put("s.conf", data, size);
  sf::fuzz::expect_accept_or_input_error([&] {
    for (const sf::RangeScanPose& p : sf::read_range_grid_conf(path))
      if (!p.t.allFinite() || std::abs(p.q.norm() - 1) > 1e-6) __builtin_trap();
  });
  return 0;
}
