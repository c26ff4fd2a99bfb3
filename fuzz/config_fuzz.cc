// A TOML parameter file (configs/*.toml, a job's config.toml), loaded and checked.
#include "engine/fusion.h"
#include "engine/parameters.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = sf::fuzz::put("c.toml", data, size);
  sf::fuzz::expect_accept_or_input_error([&] {
    sf::FusionOptions options;
    sf::ParameterSet params;
    sf::register_parameters(params, options);
    params.load_toml(path);
    options.check();
    (void)params.assignments();
  });
  return 0;
}
