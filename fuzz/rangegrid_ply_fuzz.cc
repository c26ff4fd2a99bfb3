// A Stanford range-grid PLY, then the depth frame made from it.
#include "engine/input/rangegrid_io.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = sf::fuzz::put("s.ply", data, size);
  sf::fuzz::expect_accept_or_input_error([&] {
    const sf::RangeScan scan = sf::read_range_grid_ply(path);
    const sf::DepthFrame f = sf::range_scan_frame(scan, sf::RangeScanPose{}, path.string());
    if (f.size() != std::size_t(scan.num_cols) * std::size_t(scan.num_rows)) __builtin_trap();
    for (std::size_t i = 0; i < f.size(); ++i)
      if (f.valid[i] && (!f.position[i].allFinite() || !(f.footprint[i] > 0))) __builtin_trap();
  });
  return 0;
}
