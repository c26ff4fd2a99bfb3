#include "tests/test_util.h"

#include <unistd.h>

#include <gtest/gtest.h>

#include <array>
#include <fstream>

#include "engine/error.h"
#include <cstdio>
#include <sys/wait.h>

namespace sf::test {

namespace {

std::filesystem::path scratch_root() {
  return std::filesystem::temp_directory_path() / ("scalefuse-test-" + std::to_string(::getpid()));
}

// The process's scratch folders go when its tests pass (a failure keeps them for a look): a suite
// run leaves gigabytes of jobs and meshes otherwise.
class RemoveScratchWhenPassed : public ::testing::Environment {
 public:
  void TearDown() override {
    if (::testing::UnitTest::GetInstance()->failed_test_count() > 0) return;
    std::error_code ec;
    std::filesystem::remove_all(scratch_root(), ec);
  }
};
[[maybe_unused]] ::testing::Environment* const kRemoveScratch =
    ::testing::AddGlobalTestEnvironment(new RemoveScratchWhenPassed);

}  // namespace

std::filesystem::path scratch_dir(const std::string& name) {
  auto dir = scratch_root() / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

std::filesystem::path shared_data() { return SCALEFUSE_SHARED_DATA; }
std::filesystem::path scalefuse_binary() { return SCALEFUSE_BINARY; }

int run_command(const std::string& command, std::string* log) {
  const std::string full = command + " 2>&1";
  FILE* pipe = ::popen(full.c_str(), "r");
  if (!pipe) return -1;
  std::array<char, 4096> buf;
  std::size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0)
    if (log) log->append(buf.data(), n);
  const int status = ::pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

void write_text(const std::filesystem::path& path, const std::string& text) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream(path, std::ios::binary) << text;
}

void expect_input_error(const std::function<void()>& fn, const std::string& file_part, const std::string& what) {
  try {
    fn();
    ADD_FAILURE() << "no error; expected one naming " << file_part;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(file_part), std::string::npos) << msg;
    EXPECT_NE(msg.find(what), std::string::npos) << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  }
}

}  // namespace sf::test
