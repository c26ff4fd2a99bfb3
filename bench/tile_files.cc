// What a checkpoint's files cost this machine's file system, apart from packing and compressing:
// N tile-sized files created (O_CREAT | O_TRUNC, as write_tile does), written, closed and renamed
// into place, then one syncfs of the folder, as TileStore::sync does. Each round runs two ways,
// their order swapped round by round: without and with sync_file_range(SYNC_FILE_RANGE_WRITE)
// before each close, which starts a file's writeback while the next ones are written, so that the
// syncfs waits for the last files only (storage/tile_file.cc). The creates are also timed apart:
// on an ext4 without a journal their cost grows with the inodes freed in the last seconds (the
// allocator's `recently_deleted` check), which a job directory removed and run again meets.
// Build and run: g++ -O2 -std=c++20 -o /tmp/tile_files bench/tile_files.cc && /tmp/tile_files DIR [N=221] [BYTES=313000] [ROUNDS=3]
// (igea's checkpoint, default parameters: 221 tiles of 313 kB on average). The files go to a
// fresh folder DIR/tile_files.PID, removed at the end; DIR must exist.
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;
double ms(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double>(b - a).count() * 1e3; }

// A positive whole number, or false.
bool parse(const char* text, unsigned long max, unsigned long* out) {
  char* end = nullptr;
  errno = 0;
  const unsigned long v = std::strtoul(text, &end, 10);
  if (errno != 0 || end == text || *end != '\0' || text[0] == '-' || v == 0 || v > max) return false;
  *out = v;
  return true;
}

bool fail(const std::string& what) {
  std::fprintf(stderr, "%s: %s\n", what.c_str(), std::strerror(errno));
  return false;
}

// One way of writing the files into `dir` (made empty first); prints its times.
bool run_round(const std::filesystem::path& dir, unsigned long n, const std::vector<char>& data, bool start_writeback) {
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  if (!std::filesystem::create_directory(dir, ec)) {
    std::fprintf(stderr, "%s: cannot make the folder: %s\n", dir.c_str(), ec.message().c_str());
    return false;
  }
  double creating = 0;
  const auto t0 = Clock::now();
  for (unsigned long i = 0; i < n; ++i) {
    const std::string name = (dir / ("b_" + std::to_string(i) + ".1.tile")).string(), tmp = name + ".tmp";
    const auto c0 = Clock::now();
    const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    creating += ms(c0, Clock::now());
    if (fd < 0) return fail(tmp);
    for (std::size_t done = 0; done < data.size();) {
      const ssize_t w = ::write(fd, data.data() + done, data.size() - done);
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) {
        if (w == 0) errno = EIO;  // no progress: not an error the call reported
        fail(tmp);
        ::close(fd);
        return false;
      }
      done += std::size_t(w);
    }
    if (start_writeback && ::sync_file_range(fd, 0, 0, SYNC_FILE_RANGE_WRITE) != 0) {
      fail(tmp + " (sync_file_range)");
      ::close(fd);
      return false;
    }
    if (::close(fd) != 0) return fail(tmp);
    if (std::rename(tmp.c_str(), name.c_str()) != 0) return fail(name);
  }
  const auto t1 = Clock::now();
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd < 0) return fail(dir.string());
  const bool synced = ::syncfs(dfd) == 0;
  const int err = errno;
  ::close(dfd);
  if (!synced) {
    errno = err;
    return fail(dir.string() + " (syncfs)");
  }
  const auto t2 = Clock::now();
  std::printf("%-20s files %6.1f ms (creates %5.1f ms), syncfs %5.1f ms, in all %6.1f ms\n",
              start_writeback ? "writeback started:" : "syncfs alone:", ms(t0, t1), creating, ms(t1, t2),
              ms(t0, t2));
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  unsigned long n = 221, bytes = 313000, rounds = 3;
  if (argc < 2 || argc > 5 || (argc > 2 && !parse(argv[2], 1000000, &n)) ||
      (argc > 3 && !parse(argv[3], 1ul << 30, &bytes)) || (argc > 4 && !parse(argv[4], 1000, &rounds))) {
    std::fprintf(stderr, "usage: %s DIR [N=221] [BYTES=313000] [ROUNDS=3]  (N, BYTES, ROUNDS positive)\n", argv[0]);
    return 2;
  }
  std::error_code ec;
  if (!std::filesystem::is_directory(argv[1], ec)) {
    std::fprintf(stderr, "%s: not a folder\n", argv[1]);
    return 2;
  }
  const std::filesystem::path dir = std::filesystem::path(argv[1]) / ("tile_files." + std::to_string(::getpid()));
  std::vector<char> data(bytes);
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = char(i * 2654435761u >> 13);  // not all zeros
  bool ok = true;
  for (unsigned long r = 0; r < rounds && ok; ++r)
    for (const bool second : {false, true})  // odd rounds start with the writeback started
      if (ok) ok = run_round(dir, n, data, second != (r % 2 == 1));
  std::filesystem::remove_all(dir, ec);
  return ok ? 0 : 1;
}
