// What a checkpoint's files cost this machine's file system, apart from packing and compressing:
// N tile-sized files created (O_CREAT | O_TRUNC, as write_tile does), written, closed and renamed
// into place, then one syncfs of the folder, as TileStore::sync does. Each round runs twice:
// without and with sync_file_range(SYNC_FILE_RANGE_WRITE) before each close, which starts a file's
// writeback while the next ones are written, so that the syncfs waits for the last files only
// (storage/tile_file.cc). Also prints the creates apart: on ext4 their cost grows with the inodes
// deleted in the last seconds (the allocator's `recently_deleted` check), which is what a job
// directory removed and run again sees.
// Build and run: g++ -O2 -std=c++20 -o /tmp/tile_files bench/tile_files.cc && /tmp/tile_files DIR [N=221] [BYTES=313000] [ROUNDS=3]
// (igea's checkpoint, default parameters: 221 tiles of 313 kB on average). DIR is deleted and made.
#include <fcntl.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;
double ms(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double>(b - a).count() * 1e3; }

bool round(const std::string& dir, int n, std::size_t bytes, bool start_writeback) {
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    std::fprintf(stderr, "%s: cannot make the folder: %s\n", dir.c_str(), ec.message().c_str());
    return false;
  }
  std::vector<char> data(bytes);
  for (std::size_t i = 0; i < bytes; ++i) data[i] = char(i * 2654435761u >> 13);  // not all zeros
  double creating = 0;
  const auto t0 = Clock::now();
  for (int i = 0; i < n; ++i) {
    const std::string name = dir + "/b_" + std::to_string(i) + ".1.tile", tmp = name + ".tmp";
    const auto c0 = Clock::now();
    const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    creating += ms(c0, Clock::now());
    if (fd < 0) {
      std::perror(tmp.c_str());
      return false;
    }
    for (std::size_t done = 0; done < bytes;) {
      const ssize_t w = ::write(fd, data.data() + done, bytes - done);
      if (w <= 0) {
        std::perror(tmp.c_str());
        ::close(fd);
        return false;
      }
      done += std::size_t(w);
    }
    if (start_writeback) ::sync_file_range(fd, 0, 0, SYNC_FILE_RANGE_WRITE);
    ::close(fd);
    if (std::rename(tmp.c_str(), name.c_str()) != 0) {
      std::perror(name.c_str());
      return false;
    }
  }
  const auto t1 = Clock::now();
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd < 0 || ::syncfs(dfd) != 0) {
    std::perror(dir.c_str());
    return false;
  }
  ::close(dfd);
  const auto t2 = Clock::now();
  std::printf("%-22s files %6.1f ms (creates %5.1f ms), syncfs %5.1f ms, in all %6.1f ms\n",
              start_writeback ? "writeback started:" : "syncfs alone:", ms(t0, t1), creating, ms(t1, t2),
              ms(t0, t2));
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s DIR [N=221] [BYTES=313000] [ROUNDS=3]\n", argv[0]);
    return 2;
  }
  const std::string dir = argv[1];
  const int n = argc > 2 ? std::atoi(argv[2]) : 221;
  const std::size_t bytes = argc > 3 ? std::size_t(std::atol(argv[3])) : 313000;
  const int rounds = argc > 4 ? std::atoi(argv[4]) : 3;
  if (n <= 0 || bytes == 0 || rounds <= 0) {
    std::fprintf(stderr, "N, BYTES and ROUNDS must be positive\n");
    return 2;
  }
  for (int r = 0; r < rounds; ++r)
    for (const bool start : {false, true})
      if (!round(dir, n, bytes, start)) return 1;
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  return 0;
}
