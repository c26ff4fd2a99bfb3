#pragma once
// Shared by the fuzz targets (fuzz/*_fuzz.cc). Our parsers read files, so each input is written
// to a file in a private folder of this process (in /dev/shm when it exists, for speed), then
// parsed. A parser may reject an input only with sf::InputError (exit code 2 in the program);
// anything else escapes and libFuzzer reports it as a crash, as it does sanitizer findings.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "engine/error.h"

namespace sf::fuzz {

inline const std::filesystem::path& work_dir() {
  // Never destroyed, so that the exit handler below can still read it.
  static const std::filesystem::path* dir = [] {
    std::error_code ec;
    const std::filesystem::path base =
        std::filesystem::is_directory("/dev/shm", ec) ? std::filesystem::path("/dev/shm") : std::filesystem::temp_directory_path();
    auto* d = new std::filesystem::path(base / ("scalefuse-fuzz-" + std::to_string(::getpid())));
    std::filesystem::create_directories(*d);
    std::atexit([] {
      std::error_code ignored;
      std::filesystem::remove_all(work_dir(), ignored);
    });
    return d;
  }();
  return *dir;
}

// Writes `size` bytes to work_dir()/name (replacing it) and returns the path.
inline std::filesystem::path put(const std::string& name, const std::uint8_t* data, std::size_t size) {
  const std::filesystem::path p = work_dir() / name;
  std::filesystem::create_directories(p.parent_path());
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), std::streamsize(size));
  return p;
}
inline std::filesystem::path put(const std::string& name, const std::string& text) {
  return put(name, reinterpret_cast<const std::uint8_t*>(text.data()), text.size());
}

// Runs `parse`; a rejection by InputError is the expected outcome for bad bytes.
template <typename F>
void expect_accept_or_input_error(F&& parse) {
  try {
    parse();
  } catch (const sf::InputError&) {
  }
}

}  // namespace sf::fuzz
