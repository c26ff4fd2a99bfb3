// An MVE view's meta.ini, its [camera], and the pinhole sensor made from it.
#include <cmath>

#include "engine/input/mve_io.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = sf::fuzz::put("meta.ini", data, size);
  sf::fuzz::expect_accept_or_input_error([&] {
    const sf::MveCamera camera = sf::mve_camera(sf::read_mve_ini(path), path);
    const sf::Sensor s = sf::mve_sensor(camera, 40, 30);
    // An accepted camera gives a finite sensor with a proper rotation.
    if (!std::isfinite(s.fx) || !std::isfinite(s.fy) || !(s.fx > 0) || !s.R.allFinite() || !s.t.allFinite()) __builtin_trap();
    if (std::abs(s.R.determinant() - 1) > 1e-3) __builtin_trap();
  });
  return 0;
}
