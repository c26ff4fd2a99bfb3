// Faults (issue 6, docs/hardening.md): a disk that fills up while a job writes its tiles, journal,
// scratch files or mesh. The job must stop with exit code 3 and a message that names the file and
// says how to continue, leave no mesh, and, once space is back, resume to the byte-identical mesh.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "engine/synth/scene_writer.h"
#include "engine/synth/shapes.h"
#include "engine/synth/synth.h"
#include "tests/test_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

std::string read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

struct CliRun {
  int code = 0;
  std::string log;
};
CliRun run(const std::string& command) {
  CliRun r;
  r.code = test::run_command(command, &r.log);
  return r;
}
std::string bin() { return test::scalefuse_binary().string(); }

fs::path small_scene(const std::string& name) {
  SynthOptions o;
  o.far_views = 4;
  o.far_width = 40;
  o.far_height = 30;
  o.close_views = 1;
  o.close_width = 64;
  o.close_height = 48;
  o.footprint_ratio = 3;
  const fs::path dir = test::scratch_dir(name) / "scene";
  write_scene(render_scene(make_sphere(Eigen::Vector3d::Zero(), 0.5, 3), o), dir, SceneWriteOptions{});
  return dir;
}

// Flags that make the job write a checkpoint after every depth map and extract brick by brick,
// so that every kind of file is written while the disk can fill up.
const char* kFlags = " -q --threads 2 --checkpoint-every 1 --extract bricks --brick-size 0.25";

// A tmpfs of `kib` KiB at `dir` (root only); false where mounting is not allowed.
bool mount_tmpfs(const fs::path& dir, std::size_t kib) {
  fs::create_directories(dir);
  return test::run_command("mount -t tmpfs -o size=" + std::to_string(kib) + "k tmpfs " + dir.string() +
                           " 2>/dev/null") == 0;
}

TEST(Faults, DiskFullStopsWithExitThreeAndResumesToTheSameMesh) {
  if (::geteuid() != 0) GTEST_SKIP() << "mounting a small tmpfs needs root";
  const fs::path scene = small_scene("faults-disk");
  const fs::path root = scene.parent_path();
  // The reference, and how much disk the job needs at its end.
  const CliRun ref = run(bin() + " fuse " + scene.string() + " -o " + (root / "ref.ply").string() + " --job " +
                         (root / "ref.job").string() + kFlags);
  ASSERT_EQ(ref.code, 0) << ref.log;
  std::uintmax_t need = fs::file_size(root / "ref.ply");
  for (const auto& e : fs::recursive_directory_iterator(root / "ref.job"))
    if (e.is_regular_file()) need += e.file_size();
  const std::size_t need_kib = need / 1024 + 1;

  int failed = 0, recovered = 0, tile_write_resumed = 0;
  std::set<std::string> where;  // which kind of file the disk filled up in
  // Disks from 1.5 % to 1.7 times what the job holds at its end: it fills up at different points
  // (creating the journal, tiles of integration checkpoints, the extraction's scratch files and
  // journal records; a checkpoint keeps the previous generation until it commits).
  for (double fraction : {0.015, 0.1, 0.4, 0.8, 1.0, 1.3, 1.7}) {
    SCOPED_TRACE("disk of " + std::to_string(fraction) + " of the job's size");
    const fs::path disk = root / ("disk" + std::to_string(int(fraction * 1000)));
    if (!mount_tmpfs(disk, std::max<std::size_t>(16, std::size_t(double(need_kib) * fraction)))) {
      if (failed + recovered == 0) GTEST_SKIP() << "mount -t tmpfs is not allowed here";
      FAIL() << "mount failed after it worked";
    }
    const fs::path out = disk / "m.ply", job = disk / "job";
    const std::string fuse = bin() + " fuse " + scene.string() + " -o " + out.string() + " --job " + job.string() + kFlags;
    const CliRun r = run(fuse);
    if (r.code == 0) {  // it fit after all
      EXPECT_EQ(read_all(out), read_all(root / "ref.ply"));
    } else {
      ++failed;
      EXPECT_EQ(r.code, 3) << r.log;
      EXPECT_TRUE(r.log.find("No space left on device") != std::string::npos ||
                  r.log.find("disk is full") != std::string::npos)
          << r.log;
      EXPECT_EQ(std::count(r.log.begin(), r.log.end(), '\n'), 1) << r.log;
      EXPECT_FALSE(fs::exists(out));
      for (const char* kind : {"job.sqlite", "tile", "scratch", "job journal", "m.ply"})
        if (r.log.find(kind) != std::string::npos) where.insert(kind);
      std::printf("disk of %.3f x the job: %s", fraction, r.log.c_str());
      // Space is back: the job continues from its last checkpoint to the same mesh, or, if it had
      // not integrated anything, it left no job and the command runs again.
      ASSERT_EQ(test::run_command("mount -o remount,size=" + std::to_string(need_kib * 4) + "k " + disk.string()), 0);
      const bool again_from_scratch = r.log.find("run the command again") != std::string::npos;
      if (again_from_scratch) {
        EXPECT_FALSE(fs::exists(job)) << "an empty job was left behind";
      } else {
        EXPECT_NE(r.log.find("scalefuse resume " + job.string()), std::string::npos) << r.log;
      }
      const CliRun again = run(again_from_scratch ? fuse : bin() + " resume " + job.string() + " -q --threads 2");
      EXPECT_EQ(again.code, 0) << again.log;
      if (again.code == 0) {
        ++recovered;
        EXPECT_EQ(read_all(out), read_all(root / "ref.ply"));
        if (!again_from_scratch && r.log.find("cannot write tile") != std::string::npos) ++tile_write_resumed;
      }
    }
    test::run_command("umount " + disk.string());
  }
  EXPECT_GE(failed, 5) << "too few sizes ran out of space to show anything";
  EXPECT_EQ(recovered, failed);
  EXPECT_GE(where.size(), 3u) << "the disk should fill up in several kinds of file";
  EXPECT_GE(tile_write_resumed, 1) << "no size stopped a job (past its first checkpoint) in a tile write";
}

// A file-size limit (ulimit -f) is the same condition for one file: EFBIG instead of SIGXFSZ.
TEST(Faults, FileSizeLimitStopsWithExitThreeAndResumes) {
  const fs::path scene = small_scene("faults-ulimit");
  const fs::path root = scene.parent_path();
  const CliRun ref = run(bin() + " fuse " + scene.string() + " -o " + (root / "ref.ply").string() + kFlags);
  ASSERT_EQ(ref.code, 0) << ref.log;
  const std::uintmax_t mesh = fs::file_size(root / "ref.ply");
  ASSERT_GT(mesh, 8u * 1024);
  // Every tile and the journal fit in the limit; the mesh does not.
  const std::size_t limit_kib = mesh / 1024 / 2;
  const fs::path out = root / "m.ply", job = root / "m.job";
  const CliRun r = run("bash -c 'ulimit -f " + std::to_string(limit_kib) + "; exec " + bin() + " fuse " +
                       scene.string() + " -o " + out.string() + " --job " + job.string() + kFlags + "'");
  EXPECT_EQ(r.code, 3) << r.log;
  // The file that hit the limit: a tile, a scratch file or the mesh (EFBIG), or the journal
  // (SQLite's "database or disk is full").
  EXPECT_TRUE(r.log.find("File too large") != std::string::npos || r.log.find("disk is full") != std::string::npos)
      << r.log;
  EXPECT_EQ(std::count(r.log.begin(), r.log.end(), '\n'), 1) << "one line: " << r.log;
  EXPECT_NE(r.log.find("continue with: scalefuse resume " + job.string()), std::string::npos) << r.log;
  EXPECT_FALSE(fs::exists(out));
  for (const auto& e : fs::directory_iterator(root))
    EXPECT_EQ(e.path().filename().string().find("m.ply.tmp"), std::string::npos) << "a temporary mesh was left: " << e.path();
  const CliRun again = run(bin() + " resume " + job.string() + " -q --threads 2");
  ASSERT_EQ(again.code, 0) << again.log;
  EXPECT_EQ(read_all(out), read_all(root / "ref.ply"));
}

}  // namespace
}  // namespace sf
