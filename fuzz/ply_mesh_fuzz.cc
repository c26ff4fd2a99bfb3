// A PLY mesh (scalefuse synth and eval read them): ASCII or binary, any element layout.
#include "engine/meshio/ply_io.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = sf::fuzz::put("m.ply", data, size);
  sf::fuzz::expect_accept_or_input_error([&] {
    const sf::Mesh m = sf::read_ply_mesh(path);
    for (const auto& f : m.faces)
      for (auto v : f)
        if (std::size_t(v) >= m.vertices.size()) __builtin_trap();  // accepted faces index real vertices
  });
  return 0;
}
