// Jobs (issue 3): the mesh does not depend on threads, memory limit or interruptions (SIGKILL at
// several points, then resume); a job refuses to resume on changed inputs or parameters, and
// re-extracts a finished job without integrating again.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <thread>
#include <chrono>
#include <cstdlib>
#include <vector>

#include "tests/test_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

// The bundled ten bunny scans, kept small (deepest level 8) so that each run takes seconds.
const std::string kScene = "--config " + (fs::path(SCALEFUSE_SOURCE_DIR) / "configs" / "laser.toml").string() +
                           " --set integrate.max_level=8";
fs::path bunny() { return fs::path(SCALEFUSE_SOURCE_DIR) / "examples" / "stanford_bunny"; }

struct CliRun {
  int code;
  std::string output;
};
CliRun scalefuse(const std::string& args, const std::string& env = "") {
  CliRun r;
  r.code = test::run_command(env + " " + test::scalefuse_binary().string() + " " + args, &r.output);
  return r;
}

std::string bytes_of(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// "k7.ply" (spelled out: GCC 12 warns falsely on "k" + std::to_string(n)).
std::string numbered(const char* prefix, int n, const char* suffix) {
  std::string s = prefix;
  s += std::to_string(n);
  s += suffix;
  return s;
}

// Commits of the extraction's progress in a brick extraction of kScene committing after every
// brick: one per brick of each pass and one per pass (the last one ends the last pass, before
// the mesh is written). It changes with the bricks or passes of the extraction.
constexpr int kExtractionCommits = 1131;

nlohmann::json json_of(const std::string& text) {
  const std::size_t at = text.find('{');
  return nlohmann::json::parse(at == std::string::npos ? text : text.substr(at));
}

}  // namespace

TEST(Job, MeshIsByteIdenticalAcrossThreadsAndMemoryLimits) {
  const fs::path dir = test::scratch_dir("job-determinism");
  const fs::path ref = dir / "ref.ply";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + ref.string() + " -q --threads 2 " + kScene).code, 0);
  const std::string expected = bytes_of(ref);
  ASSERT_GT(expected.size(), 100000u);
  int run = 0;
  for (const char* threads : {"1", "2"})
    for (const char* memory : {"1G", "16M", "1M"}) {
      const fs::path out = dir / numbered("m", run++, ".ply");
      const CliRun r = scalefuse("fuse " + bunny().string() + " -o " + out.string() + " -q --threads " + threads +
                              " --memory-limit " + memory + " --checkpoint-every 3 --stats " + out.string() + ".json " +
                              kScene);
      ASSERT_EQ(r.code, 0) << r.output;
      EXPECT_TRUE(bytes_of(out) == expected) << "threads " << threads << ", memory " << memory;
    }
  // Nor on the brick size (the auto level here is 3: 8 bricks per axis).
  for (const char* level : {"2", "5"}) {
    const fs::path out = dir / numbered("b", std::stoi(level), ".ply");
    const CliRun r = scalefuse("fuse " + bunny().string() + " -o " + out.string() + " -q --memory-limit 8M " + kScene +
                               " --set octree.brick_level=" + level);
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_TRUE(bytes_of(out) == expected) << "brick level " << level;
  }
  // The tightest limit really spilled: the job holds tiles of every brick.
  const CliRun st = scalefuse("status " + (dir / "m5.ply.job").string() + " --json");
  ASSERT_EQ(st.code, 0) << st.output;
  const auto j = json_of(st.output);
  EXPECT_EQ(j["stage"], "done");
  EXPECT_EQ(j["integrated"], 10);
  EXPECT_EQ(j["depth_maps"], 10);
  EXPECT_GT(j["bricks"].get<int>(), 50);
  EXPECT_GT(j["tile_bytes"].get<double>(), 1e5);
}

TEST(Job, KilledAtSeveralPointsAndResumedGivesTheSameMesh) {
  const fs::path dir = test::scratch_dir("job-kill");
  const fs::path ref = dir / "ref.ply";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + ref.string() + " -q " + kScene).code, 0);
  const std::string expected = bytes_of(ref);
  // With a 4 MB limit the integration sweeps many tiles, a depth map reaching several: the steps
  // (tile, depth map) of that plan, to kill at its start, within, and just before its end.
  const fs::path planned = dir / "planned.ply";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + planned.string() + " -q --memory-limit 4M --stats " +
                      planned.string() + ".json " + kScene)
                .code,
            0);
  const auto plan = nlohmann::json::parse(bytes_of(planned.string() + ".json"));
  const int steps = plan["sweep_steps"], tiles = plan["tiles"];
  ASSERT_GT(tiles, 4);
  ASSERT_GT(steps, 30);
  EXPECT_TRUE(bytes_of(planned) == expected) << "a sweep of " << tiles << " tiles";
  for (int kill_after : {1, 4, steps / 2 + 1, steps - 1}) {
    const fs::path out = dir / numbered("k", kill_after, ".ply");
    const fs::path job = dir / numbered("k", kill_after, ".job");
    const CliRun killed = scalefuse("fuse " + bunny().string() + " -o " + out.string() + " --job " + job.string() +
                                     " -q --memory-limit 4M --checkpoint-every 3 " + kScene,
                                 "SCALEFUSE_TEST_KILL_AFTER=" + std::to_string(kill_after));
    EXPECT_NE(killed.code, 0) << "the process was to kill itself after " << kill_after << " steps";
    EXPECT_FALSE(fs::exists(out));
    const auto st = json_of(scalefuse("status " + job.string() + " --json").output);
    EXPECT_EQ(st["integrated"], 0) << "no depth map is in every tile yet";
    if (kill_after >= 3) {
      EXPECT_EQ(st["sweep"]["tiles"], tiles) << "the plan is recorded with the first checkpoint";
    }
    // The last checkpoint before the kill: every 3 steps, and at each tile's end.
    const int checkpointed = st["sweep"]["steps"];
    EXPECT_LE(checkpointed, kill_after);
    EXPECT_GE(checkpointed, kill_after / 3 * 3);
    // Resumed with another limit, the job keeps its recorded plan.
    const std::string limit = kill_after == steps / 2 + 1 ? "1G" : "4M";
    const CliRun resumed = scalefuse("resume " + job.string() + " -q --memory-limit " + limit +
                                  " --checkpoint-every 3 --stats " + out.string() + ".json");
    ASSERT_EQ(resumed.code, 0) << resumed.output;
    EXPECT_TRUE(bytes_of(out) == expected) << "killed after " << kill_after;
    const auto stats = nlohmann::json::parse(bytes_of(out.string() + ".json"));
    EXPECT_EQ(stats["resumed_at"], checkpointed);
    EXPECT_EQ(stats["sweep_steps"], steps - checkpointed) << "the resumed run does only what is left";
    EXPECT_EQ(stats["tiles"], tiles);
  }
}

// Issue 4: a killed brick-by-brick extraction resumes brick by brick. The process kills itself
// right after the n-th commit of the extraction's progress (one per finished brick here), in
// regularization, in the windows' pass and in the passes after it; each resumed run skips what
// the killed one finished and writes the same bytes. A changed extraction parameter drops the
// record instead of reusing it.
TEST(Job, KilledDuringBrickExtractionResumesBrickByBrick) {
  const fs::path dir = test::scratch_dir("job-kill-extract");
  const fs::path ref = dir / "ref.ply";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + ref.string() + " -q " + kScene).code, 0);
  const std::string expected = bytes_of(ref);
  // One brick per window group: one commit per brick in every pass.
  const std::string commit_each = " --extract bricks --checkpoint-seconds 0.000001 --set extract.window_group_voxels=0 ";
  for (int kill_after : {60, 380, 1000}) {
    SCOPED_TRACE("killed after commit " + std::to_string(kill_after));
    const fs::path out = dir / numbered("x", kill_after, ".ply");
    const fs::path job = dir / numbered("x", kill_after, ".job");
    const CliRun killed = scalefuse("fuse " + bunny().string() + " -o " + out.string() + " --job " + job.string() +
                                        " -q" + commit_each + kScene,
                                    "SCALEFUSE_TEST_KILL_IN_EXTRACTION=" + std::to_string(kill_after));
    ASSERT_NE(killed.code, 0) << "the process was to kill itself";
    EXPECT_FALSE(fs::exists(out));
    EXPECT_TRUE(fs::exists(job / "scratch"));
    const auto st = json_of(scalefuse("status " + job.string() + " --json").output);
    EXPECT_EQ(st["stage"], "extracting");
    ASSERT_FALSE(st["extraction"].empty());
    EXPECT_EQ(st["extraction"][0]["pass"], "regularize");
    EXPECT_EQ(st["extraction"].back()["complete"], false) << "killed in that pass";
    const CliRun resumed = scalefuse("resume " + job.string() + " -q --stats " + out.string() + ".json");
    ASSERT_EQ(resumed.code, 0) << resumed.output;
    EXPECT_TRUE(bytes_of(out) == expected);
    EXPECT_FALSE(fs::exists(job / "scratch")) << "a finished job keeps no scratch files";
    const auto stats = nlohmann::json::parse(bytes_of(out.string() + ".json"));
    EXPECT_GT(stats["extract"]["resumed_items"].get<int>(), 40) << "bricks finished before the kill were skipped";
    // Counts are summed from every brick's record, whichever run did it.
    EXPECT_EQ(stats["extract"]["windows"].get<int>(), 149);
    if (kill_after > 200) {
      EXPECT_EQ(stats["regularize"]["blended"], 0) << "regularization was complete: not run again";
    }
  }
  // Window groups of several bricks (149 bricks in 103 windows): killed after the 30th group of
  // the windows' pass, whose commits hold the posts of every brick of their groups.
  {
    const fs::path out = dir / "groups.ply", job = dir / "groups.job";
    const std::string groups = " --extract bricks --checkpoint-seconds 0.000001 --set extract.window_group_voxels=20000 ";
    ASSERT_NE(scalefuse("fuse " + bunny().string() + " -o " + out.string() + " --job " + job.string() + " -q" + groups +
                            kScene,
                        "SCALEFUSE_TEST_KILL_IN_EXTRACTION=330")
                  .code,
              0);
    const auto st = json_of(scalefuse("status " + job.string() + " --json").output);
    ASSERT_FALSE(st["extraction"].empty());
    EXPECT_EQ(st["extraction"].back()["pass"], "tetrahedralize");
    EXPECT_EQ(st["extraction"].back()["complete"], false);
    const CliRun resumed = scalefuse("resume " + job.string() + " -q --stats " + out.string() + ".json");
    ASSERT_EQ(resumed.code, 0) << resumed.output;
    EXPECT_TRUE(bytes_of(out) == expected);
    const auto stats = nlohmann::json::parse(bytes_of(out.string() + ".json"));
    EXPECT_GE(stats["extract"]["resumed_items"].get<int>(), 20);
    EXPECT_EQ(stats["extract"]["windows"].get<int>(), 103);
  }
  // Killed in the windows' pass, then fused again with another snapping distance: the record
  // belongs to other parameters and is dropped, the result is the new parameters' mesh.
  const fs::path fresh = dir / "nosnap.ply", again = dir / "again.ply", job = dir / "again.job";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + fresh.string() + " -q --set extract.snap_fraction=0 " + kScene)
                .code,
            0);
  ASSERT_NE(scalefuse("fuse " + bunny().string() + " -o " + again.string() + " --job " + job.string() + " -q" +
                          commit_each + kScene,
                      "SCALEFUSE_TEST_KILL_IN_EXTRACTION=380")
                .code,
            0);
  const CliRun changed = scalefuse("fuse " + bunny().string() + " -o " + again.string() + " --job " + job.string() +
                                   " -q --set extract.snap_fraction=0 --stats " + again.string() + ".json" + commit_each + kScene);
  ASSERT_EQ(changed.code, 0) << changed.output;
  EXPECT_TRUE(bytes_of(again) == bytes_of(fresh));
  EXPECT_FALSE(bytes_of(again) == expected);
  EXPECT_EQ(nlohmann::json::parse(bytes_of(again.string() + ".json"))["extract"]["resumed_items"], 0);
}

TEST(Job, SigtermCheckpointsExitsAndResumesToTheSameMesh) {
  const fs::path dir = test::scratch_dir("job-term");
  const fs::path ref = dir / "ref.ply", out = dir / "t.ply", job = dir / "t.job";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + ref.string() + " -q " + kScene).code, 0);
  const CliRun stopped = scalefuse("fuse " + bunny().string() + " -o " + out.string() + " --job " + job.string() +
                                       " -q --threads 2 --checkpoint-every 100 " + kScene,
                                   "SCALEFUSE_TEST_TERM_AFTER=4");
  EXPECT_EQ(stopped.code, 128 + 15) << stopped.output;
  EXPECT_NE(stopped.output.find("checkpoint written; continue with: scalefuse resume"), std::string::npos) << stopped.output;
  EXPECT_FALSE(fs::exists(out));
  // The depth maps in flight when the signal came were integrated before the checkpoint.
  const auto st = json_of(scalefuse("status " + job.string() + " --json").output);
  EXPECT_GE(st["integrated"].get<int>(), 4);
  EXPECT_LT(st["integrated"].get<int>(), 10);
  ASSERT_EQ(scalefuse("resume " + job.string() + " -q").code, 0);
  EXPECT_TRUE(bytes_of(out) == bytes_of(ref));
}

// Issue 6: SIGTERM past integration (the process sends it to itself right after the n-th commit
// of the extraction's progress: in regularization, in the windows' pass, in a later pass, and
// after the last pass, before the mesh is written). The bricks in flight finish, their progress
// is committed, and the process exits with 128 + 15, leaving no mesh and no temporary file; the
// resumed run skips what was finished and writes the same bytes.
TEST(Job, SigtermDuringExtractionCommitsExitsAndResumes) {
  const fs::path dir = test::scratch_dir("job-term-extract");
  const fs::path ref = dir / "ref.ply";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + ref.string() + " -q " + kScene).code, 0);
  const std::string expected = bytes_of(ref);
  const std::string commit_each = " --extract bricks --checkpoint-seconds 0.000001 --set extract.window_group_voxels=0 ";
  for (int term_after : {60, 380, 1000, kExtractionCommits}) {
    SCOPED_TRACE("SIGTERM after commit " + std::to_string(term_after));
    const fs::path out_dir = dir / numbered("t", term_after, "");
    fs::create_directories(out_dir);
    const fs::path out = out_dir / "mesh.ply", job = dir / numbered("t", term_after, ".job");
    const CliRun stopped = scalefuse("fuse " + bunny().string() + " -o " + out.string() + " --job " + job.string() +
                                         " -q" + commit_each + kScene,
                                     "SCALEFUSE_TEST_TERM_IN_EXTRACTION=" + std::to_string(term_after));
    EXPECT_EQ(stopped.code, 128 + 15) << stopped.output;
    EXPECT_NE(stopped.output.find("interrupted "), std::string::npos) << stopped.output;
    EXPECT_NE(stopped.output.find("continue with: scalefuse resume"), std::string::npos) << stopped.output;
    EXPECT_TRUE(fs::is_empty(out_dir)) << "no mesh and no temporary file";
    if (term_after == kExtractionCommits) {
      EXPECT_NE(stopped.output.find("while writing the mesh"), std::string::npos) << stopped.output;
    }
    const auto st = json_of(scalefuse("status " + job.string() + " --json").output);
    EXPECT_EQ(st["stage"], "extracting");
    const CliRun resumed = scalefuse("resume " + job.string() + " -q --stats " + out.string() + ".json");
    ASSERT_EQ(resumed.code, 0) << resumed.output;
    EXPECT_TRUE(bytes_of(out) == expected);
    const auto stats = nlohmann::json::parse(bytes_of(out.string() + ".json"));
    EXPECT_GT(stats["extract"]["resumed_items"].get<int>(), 40) << "bricks finished before the signal were skipped";
  }
}

TEST(Job, RefusesChangedParametersOrInputsAndReextractsAFinishedJob) {
  const fs::path dir = test::scratch_dir("job-refuse");
  const fs::path input = dir / "scans";
  fs::copy(bunny(), input, fs::copy_options::recursive);
  const fs::path job = dir / "job";
  const std::string base = "fuse " + input.string() + " -o " + (dir / "m.ply").string() + " --job " + job.string() + " -q ";
  ASSERT_EQ(scalefuse(base + kScene).code, 0);

  // Another ramp changes the integrated field: refused, naming the job and the parameter.
  CliRun r = scalefuse(base + kScene + " --set integrate.gamma=2");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("configuration differs"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("integrate.gamma"), std::string::npos) << r.output;

  // Another extraction parameter reruns regularization and extraction from the tiles only.
  r = scalefuse(base + kScene + " --set extract.min_component_triangles=0 --stats " + (dir / "s.json").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(nlohmann::json::parse(bytes_of(dir / "s.json"))["resumed_at"], 10);

  // An implicit job (OUTPUT.job) on the same input, to be started over below.
  const std::string implicit = "fuse " + input.string() + " -o " + (dir / "implicit.ply").string() + " -q " + kScene;
  ASSERT_EQ(scalefuse(implicit).code, 0);
  const std::string before = bytes_of(dir / "implicit.ply");

  // A moved scan changes a depth map: refused.
  {
    std::ifstream in(input / "bun.conf");
    std::string conf((std::istreambuf_iterator<char>(in)), {});
    const std::string from = "bmesh bun045.ply -0.0520211", to = "bmesh bun045.ply -0.0530211";  // 1 mm
    const auto at = conf.find(from);
    ASSERT_NE(at, std::string::npos);
    conf.replace(at, from.size(), to);
    std::ofstream(input / "bun.conf") << conf;
  }
  r = scalefuse(base + kScene);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("inputs changed"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("bun045"), std::string::npos) << r.output;
  // The implicit job is not the user's: it starts over with the moved scan.
  r = scalefuse(implicit);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_FALSE(bytes_of(dir / "implicit.ply") == before);
  const auto st = json_of(scalefuse("status " + (dir / "implicit.ply.job").string() + " --json").output);
  EXPECT_EQ(st["integrated"], 10);
}

// `scalefuse add`: six scans, then the other four into the same job, give the mesh of all ten
// fused at once (same root cube, fixed by --bbox).
TEST(Job, AddingDepthMapsToAFinishedJobEqualsFusingThemAllAtOnce) {
  const fs::path dir = test::scratch_dir("job-add");
  std::ifstream conf_in(bunny() / "bun.conf");
  std::string camera, line;
  std::getline(conf_in, camera);
  std::vector<std::string> scans;
  while (std::getline(conf_in, line))
    if (line.rfind("bmesh ", 0) == 0) scans.push_back(line);
  ASSERT_EQ(scans.size(), 10u);
  auto make_folder = [&](const fs::path& folder, std::size_t from, std::size_t to) {
    fs::create_directories(folder);
    std::ofstream conf(folder / "bun.conf");
    conf << camera << "\n";
    for (std::size_t i = from; i < to; ++i) {
      conf << scans[i] << "\n";
      const std::string file = scans[i].substr(6, scans[i].find(' ', 6) - 6);
      fs::copy_file(bunny() / file, folder / file);
    }
  };
  make_folder(dir / "all", 0, 10);
  make_folder(dir / "first", 0, 6);
  make_folder(dir / "more", 6, 10);
  const std::string scene = kScene + " --bbox=-0.11,0.02,-0.08,0.08,0.2,0.08 -q";
  ASSERT_EQ(scalefuse("fuse " + (dir / "all").string() + " -o " + (dir / "all.ply").string() + " " + scene).code, 0);
  const fs::path job = dir / "job", out = dir / "grown.ply";
  ASSERT_EQ(scalefuse("fuse " + (dir / "first").string() + " -o " + out.string() + " --job " + job.string() + " " + scene).code, 0);
  EXPECT_FALSE(bytes_of(out) == bytes_of(dir / "all.ply"));
  // The new depth maps are swept over tiles of a small limit, planned around the bricks the job holds.
  const CliRun added = scalefuse("add " + job.string() + " " + (dir / "more").string() + " -q --memory-limit 4M --stats " +
                                 (dir / "add.json").string());
  ASSERT_EQ(added.code, 0) << added.output;
  EXPECT_TRUE(bytes_of(out) == bytes_of(dir / "all.ply"));
  const auto add_stats = nlohmann::json::parse(bytes_of(dir / "add.json"));
  EXPECT_EQ(add_stats["resumed_at"], 6);
  EXPECT_GT(add_stats["tiles"].get<int>(), 1);
  const auto st = json_of(scalefuse("status " + job.string() + " --json").output);
  EXPECT_EQ(st["depth_maps"], 10);
  EXPECT_EQ(st["integrated"], 10);
  // The grown job resumes like any other: a plain resume changes nothing.
  ASSERT_EQ(scalefuse("resume " + job.string() + " -q").code, 0);
  EXPECT_TRUE(bytes_of(out) == bytes_of(dir / "all.ply"));
}

TEST(Job, StatusOfAFolderWithoutAJobIsABadInput) {
  const fs::path dir = test::scratch_dir("job-status");
  const CliRun r = scalefuse("status " + dir.string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("not a scalefuse job directory"), std::string::npos) << r.output;
}


namespace {

// The bunny's scan lines of bun.conf: the camera line, then one "bmesh FILE ..." line per scan.
struct BunnyConf {
  std::string camera;
  std::vector<std::string> scans;
  static std::string file_of(const std::string& line) { return line.substr(6, line.find(' ', 6) - 6); }
};
BunnyConf bunny_conf() {
  BunnyConf c;
  std::ifstream in(bunny() / "bun.conf");
  std::string line;
  std::getline(in, c.camera);
  while (std::getline(in, line))
    if (line.rfind("bmesh ", 0) == 0) c.scans.push_back(line);
  return c;
}

// Writes `lines` as `folder`/bun.conf the way a careful writer does: a temp file, then rename.
void write_conf(const fs::path& folder, const std::string& camera, const std::vector<std::string>& lines) {
  {
    std::ofstream out(folder / "bun.conf.tmp");
    out << camera << "\n";
    for (const auto& l : lines) out << l << "\n";
  }
  fs::rename(folder / "bun.conf.tmp", folder / "bun.conf");
}

// A command run in the background: its exit status lands in DIR/rc. A run still going when the
// test ends (a failed assertion) is killed, so that it cannot hold the job or the test's output.
struct Background {
  fs::path rc, pid;
  Background(const std::string& args, const fs::path& dir, const std::string& env = "")
      : rc(dir / "rc"), pid(dir / "pid") {
    const std::string cmd = "(" + env + " " + test::scalefuse_binary().string() + " " + args + " > " +
                            (dir / "log").string() + " 2>&1 & echo $! > " + pid.string() + "; wait $!; echo $? > " +
                            (dir / "rc.tmp").string() + "; mv " + (dir / "rc.tmp").string() + " " + rc.string() +
                            ") > /dev/null 2>&1 &";
    EXPECT_EQ(std::system(cmd.c_str()), 0);
  }
  ~Background() {
    if (fs::exists(rc)) return;
    for (int i = 0; i < 50 && !fs::exists(pid); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(100));
    if (!fs::exists(pid)) return;
    const std::string id = std::to_string(std::stol(bytes_of(pid)));
    if (std::system(("kill -9 " + id + " 2> /dev/null").c_str()) != 0) return;  // it ended meanwhile
  }
  // The exit status, or -1 after `seconds`.
  int wait(double seconds) const {
    for (int i = 0; i < int(seconds * 10); ++i) {
      if (fs::exists(rc)) return std::stoi(bytes_of(rc));
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return -1;
  }
};

}  // namespace

TEST(Job, FollowIntegratesDepthMapsAsTheyCompleteInArrivalOrder) {
  const fs::path dir = test::scratch_dir("job-follow");
  const BunnyConf conf = bunny_conf();
  ASSERT_EQ(conf.scans.size(), 10u);
  const std::string scene = kScene + " --bbox=-0.11,0.02,-0.08,0.08,0.2,0.08 -q";
  // The reference: all ten scans at once, in conf order 0..9.
  fs::create_directories(dir / "all");
  for (const auto& l : conf.scans) fs::copy_file(bunny() / BunnyConf::file_of(l), dir / "all" / BunnyConf::file_of(l));
  write_conf(dir / "all", conf.camera, conf.scans);
  ASSERT_EQ(scalefuse("fuse " + (dir / "all").string() + " -o " + (dir / "all.ply").string() + " " + scene).code, 0);

  // A live folder: scans 0..2 are there at the start, 3..9 arrive while the job follows; each new
  // line goes to the top of the conf, so the folder ends up listing 9..3,0,1,2: only the job's
  // arrival order gives the reference.
  const fs::path live = dir / "live", job = dir / "job", out = dir / "follow.ply";
  fs::create_directories(live);
  std::vector<std::string> listed;
  auto arrive = [&](std::size_t i, bool slowly) {
    const std::string file = BunnyConf::file_of(conf.scans[i]);
    const std::string bytes = bytes_of(bunny() / file);
    std::ofstream ply(live / file, std::ios::binary);
    if (slowly) {  // listed while half written, and left so for longer than the settle time
      ply.write(bytes.data(), std::streamsize(bytes.size() / 2));
      ply.flush();
      listed.insert(listed.begin(), conf.scans[i]);
      write_conf(live, conf.camera, listed);
      // Long against the settle time: the feed looks only between rounds of integration, which
      // take longer on a loaded machine.
      std::this_thread::sleep_for(std::chrono::milliseconds(3000));
      ply.write(bytes.data() + bytes.size() / 2, std::streamsize(bytes.size() - bytes.size() / 2));
      ply.close();
      return;
    }
    ply.write(bytes.data(), std::streamsize(bytes.size()));
    ply.close();
    listed.insert(i < 3 ? listed.end() : listed.begin(), conf.scans[i]);
    write_conf(live, conf.camera, listed);
  };
  for (std::size_t i = 0; i < 3; ++i) arrive(i, false);
  fs::create_directories(dir / "run");
  const Background run("fuse " + live.string() + " -o " + out.string() + " --job " + job.string() +
                           " --follow --settle-seconds 0.5 --poll-seconds 0.1 --threads 2 --checkpoint-every 2 --stats " +
                           (dir / "follow.json").string() + " " + kScene + " --bbox=-0.11,0.02,-0.08,0.08,0.2,0.08",
                       dir / "run");
  // Each scan arrives once the job has taken the one before: on a loaded machine a slow round of
  // integration could otherwise see two arrivals at once, and take them in listing order.
  const auto wait_taken = [&](std::size_t n) {
    for (int tries = 0; tries < 1200; ++tries) {
      const CliRun st = scalefuse("status " + job.string() + " --json");
      if (st.code == 0 && json_of(st.output)["depth_maps"].get<std::size_t>() >= n) return;
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    FAIL() << "the job did not take depth map " << n;
  };
  for (std::size_t i = 3; i < 10; ++i) {
    wait_taken(i);
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    arrive(i, i == 5);
  }
  // Let the last scan settle, then stop the feed.
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  test::write_text(job / "STOP", "");
  const int rc = run.wait(300);
  const std::string log = bytes_of(dir / "run" / "log");
  ASSERT_EQ(rc, 0) << log;
  // The half-written scan was listed, stable for longer than the settle time, and not taken.
  EXPECT_NE(log.find("follow: not taken yet (incomplete or damaged): " + (live / "top2.ply").string()), std::string::npos)
      << log;
  EXPECT_TRUE(bytes_of(out) == bytes_of(dir / "all.ply"));
  EXPECT_FALSE(fs::exists(job / "STOP")) << "a consumed stop file is removed";
  const auto stats = nlohmann::json::parse(bytes_of(dir / "follow.json"));
  EXPECT_EQ(stats["depth_maps"], 10);
  EXPECT_EQ(stats["samples_outside_root"], 0);
  const auto st = json_of(scalefuse("status " + job.string() + " --json").output);
  EXPECT_EQ(st["integrated"], 10);
  EXPECT_EQ(st["stage"], "done");
  // Resuming the followed job keeps its arrival order (a plain fuse of the folder would take the
  // listed order and be refused by the job): the same mesh again.
  fs::remove(out);
  const CliRun resumed = scalefuse("resume " + job.string() + " -q");
  ASSERT_EQ(resumed.code, 0) << resumed.output;
  EXPECT_TRUE(bytes_of(out) == bytes_of(dir / "all.ply"));
}

TEST(Job, FollowEndsOnSigtermWithACheckpointAndAMesh) {
  const fs::path dir = test::scratch_dir("job-follow-term");
  const fs::path ref = dir / "ref.ply", out = dir / "f.ply", job = dir / "f.job";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + ref.string() + " -q " + kScene).code, 0);
  // SIGTERM after 4 depth maps: the feed ends, the depth maps already found are integrated, and the
  // job extracts as usual (exit 0), instead of stopping as a plain run does.
  const CliRun r = scalefuse("fuse " + bunny().string() + " -o " + out.string() + " --job " + job.string() +
                                 " -q --follow --poll-seconds 0.1 --settle-seconds 0 " + kScene,
                             "SCALEFUSE_TEST_TERM_AFTER=4");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(bytes_of(out) == bytes_of(ref));
  const auto st = json_of(scalefuse("status " + job.string() + " --json").output);
  EXPECT_EQ(st["stage"], "done");
  EXPECT_EQ(st["integrated"], 10);
}
// Issue 6: two processes on one job (and SIGINT). A following job holds the job's lock while it waits for
// depth maps; a second fuse or resume on the job is refused as bad input naming the job (and must
// not remove the folder, as a failed first fuse would), and the first run is unharmed.
TEST(Job, ASecondProcessOnARunningJobIsRefusedAndLeavesItIntact) {
  const fs::path dir = test::scratch_dir("job-lock");
  const fs::path ref = dir / "ref.ply", out = dir / "f.ply", job = dir / "f.job";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + ref.string() + " -q " + kScene).code, 0);
  fs::create_directories(dir / "run");
  const Background first("fuse " + bunny().string() + " -o " + out.string() + " --job " + job.string() +
                             " -q --follow --poll-seconds 0.1 --settle-seconds 0 --checkpoint-every 2 " + kScene,
                         dir / "run");
  bool running = false;
  for (int tries = 0; tries < 1200 && !running; ++tries) {
    const CliRun st = scalefuse("status " + job.string() + " --json");
    running = st.code == 0 && json_of(st.output)["depth_maps"].get<int>() >= 1;
    if (!running) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  ASSERT_TRUE(running) << bytes_of(dir / "run" / "log");
  const std::string refused = job.string() + ": another scalefuse process is using this job";
  for (const std::string& second :
       {"fuse " + bunny().string() + " -o " + (dir / "second.ply").string() + " --job " + job.string() + " -q " + kScene,
        "resume " + job.string() + " -q"}) {
    SCOPED_TRACE(second);
    const CliRun r = scalefuse(second);
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_NE(r.output.find(refused), std::string::npos) << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << "one line: " << r.output;
    EXPECT_TRUE(fs::exists(job / "job.sqlite")) << "the refused process left the job alone";
  }
  EXPECT_FALSE(fs::exists(dir / "second.ply"));
  // Ctrl-C (SIGINT, from outside) ends the following job as SIGTERM does: the feed ends, the
  // depth maps found are integrated, and the job extracts its mesh.
  ASSERT_EQ(std::system(("kill -INT " + std::to_string(std::stol(bytes_of(dir / "run" / "pid")))).c_str()), 0);
  const int rc = first.wait(300);
  ASSERT_EQ(rc, 0) << bytes_of(dir / "run" / "log");
  EXPECT_TRUE(bytes_of(out) == bytes_of(ref));
}

TEST(Job, IntegrateOnlyStopsAtTheCheckpointAndResumeExtractsTheSameMesh) {
  const fs::path dir = test::scratch_dir("job-integrate-only");
  const fs::path ref = dir / "ref.ply", out = dir / "i.ply", job = dir / "i.job";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + ref.string() + " -q --stats " + (dir / "ref.json").string() +
                      " " + kScene).code, 0);
  const CliRun r = scalefuse("fuse " + bunny().string() + " -o " + out.string() + " --job " + job.string() +
                             " -q --integrate-only --memory-limit 2M --stats " + (dir / "i.json").string() + " " + kScene);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("extract with: scalefuse resume"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(out));
  EXPECT_EQ(json_of(scalefuse("status " + job.string() + " --json").output)["stage"], "integrated");
  // The voxels per level, counted brick by brick from the tiles, are those the full run fused.
  const auto a = nlohmann::json::parse(bytes_of(dir / "ref.json")), b = nlohmann::json::parse(bytes_of(dir / "i.json"));
  ASSERT_EQ(a["levels"].size(), b["levels"].size());
  for (std::size_t l = 0; l < a["levels"].size(); ++l)
    EXPECT_EQ(a["levels"][l]["voxels_fused"], b["levels"][l]["voxels_fused"]) << "level " << a["levels"][l]["level"];
  ASSERT_EQ(scalefuse("resume " + job.string() + " -q").code, 0);
  EXPECT_TRUE(bytes_of(out) == bytes_of(ref));
}

namespace {
// The `n` largest tiles of a job's checkpoint (bricks deep in the surface).
std::vector<fs::path> largest_tiles(const fs::path& job, std::size_t n) {
  std::vector<std::pair<std::uintmax_t, fs::path>> tiles;
  for (const auto& e : fs::directory_iterator(job / "tiles"))
    if (e.path().extension() == ".tile") tiles.emplace_back(e.file_size(), e.path());
  std::sort(tiles.begin(), tiles.end(), std::greater<>());
  std::vector<fs::path> out;
  for (std::size_t i = 0; i < std::min(n, tiles.size()); ++i) out.push_back(tiles[i].second);
  return out;
}
void flip_byte(const fs::path& file, std::streamoff at) {
  std::fstream f(file, std::ios::in | std::ios::out | std::ios::binary);
  f.seekg(at);
  char c = 0;
  f.read(&c, 1);
  c = char(c ^ 0x5a);
  f.seekp(at);
  f.write(&c, 1);
}
}  // namespace

// Issue 6: a tile of the checkpoint found damaged (checksum) or missing is rebuilt by
// re-integrating the job's depth maps into its brick alone, and the job goes on to the same
// mesh: after integration (one tile; four at once, rebuilt together in one pass; four of a job of
// every other depth map); in the
// middle of a brick extraction (whose finished bricks are kept);
// and stopped in the middle of a sweep of tiles (a memory limit far below the field) with every
// tile damaged, where a brick of the tile under way cannot be rebuilt and the job says so.
TEST(Job, DamagedOrMissingTileIsRebuiltFromTheDepthMapsAndGivesTheSameMesh) {
  const fs::path dir = test::scratch_dir("job-rebuild");
  const fs::path ref = dir / "ref.ply";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + ref.string() + " -q " + kScene).code, 0);
  const std::string expected = bytes_of(ref);
  // Every other depth map: the rebuild must read the job's depth maps, not the input's first ones.
  const std::string every_other = kScene + " --set input.frame_step=2";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + ref.string() + "2 -q " + every_other).code, 0);
  const std::string expected_every_other = bytes_of(ref.string() + "2");
  for (const std::string damage : {"payload", "missing", "several", "frame_step", "extracting", "sweep"}) {
    SCOPED_TRACE(damage);
    const fs::path out = dir / (damage + ".ply"), job = dir / (damage + ".job");
    const std::string fuse = "fuse " + bunny().string() + " -o " + out.string() + " --job " + job.string() + " -q ";
    CliRun first;
    std::vector<fs::path> tiles;
    if (damage == "extracting") {
      // Five bricks of the regularization pass are finished; three of the largest bricks' tiles
      // are damaged, so at least one of them is still to be read.
      first = scalefuse(fuse + "--extract bricks --checkpoint-seconds 0.000001 " + kScene,
                        "SCALEFUSE_TEST_TERM_IN_EXTRACTION=5");
      tiles = largest_tiles(job, 3);
    } else if (damage == "sweep") {
      first = scalefuse(fuse + "--memory-limit 2M --checkpoint-every 1 " + kScene, "SCALEFUSE_TEST_TERM_AFTER=12");
      const auto st = json_of(scalefuse("status " + job.string() + " --json").output);
      EXPECT_GT(st["sweep"]["tiles"].get<int>(), 1) << st.dump();
      tiles = largest_tiles(job, 1000);
    } else {
      first = scalefuse(fuse + "--integrate-only " + (damage == "frame_step" ? every_other : kScene));
      tiles = largest_tiles(job, damage == "several" || damage == "frame_step" ? 4 : 1);
    }
    ASSERT_EQ(first.code, damage == "extracting" || damage == "sweep" ? 128 + 15 : 0) << first.output;
    ASSERT_FALSE(tiles.empty());
    std::set<fs::path> removed;  // the others get a byte flipped
    for (const fs::path& tile : tiles) {
      if (damage == "missing" || (damage == "several" && tile == tiles.front())) {
        fs::remove(tile);
        removed.insert(tile);
      } else {
        flip_byte(tile, 64 + 100);  // in the payload, past the 64-byte header
      }
    }
    const CliRun resumed = scalefuse("resume " + job.string() + " -q --stats " + out.string() + ".json");
    if (damage == "sweep" && resumed.code == 2) {
      // Stopped inside a tile of the sweep: its bricks took depth maps the journal does not list,
      // and the resumed sweep reads them first. (Where the stop lands depends on the threads.)
      EXPECT_NE(resumed.output.find(": damaged tile: payload checksum mismatch; it cannot be rebuilt: its brick is in "
                                    "the tile of the sweep under way"),
                std::string::npos)
          << resumed.output;
      EXPECT_EQ(std::count(resumed.output.begin(), resumed.output.end(), '\n'), 1) << resumed.output;
      continue;
    }
    ASSERT_EQ(resumed.code, 0) << resumed.output;
    std::size_t rebuilt = 0;
    for (const fs::path& tile : tiles)
      if (resumed.output.find(tile.string() + (removed.count(tile) ? ": tile of the last checkpoint is missing; rebuilt it"
                                                                   : ": damaged tile: payload checksum mismatch; rebuilt it")) !=
          std::string::npos) {
        ++rebuilt;
        EXPECT_FALSE(fs::exists(tile)) << "the damaged tile was replaced by a new generation";
      }
    EXPECT_GE(rebuilt, 1u) << resumed.output;
    if (damage == "sweep") {
      EXPECT_GE(rebuilt, 5u) << resumed.output;
    }
    if (damage == "several") {
      // Found at once (the missing one at restore, the others by checking every tile) and rebuilt
      // in one pass over the depth maps: they all hold the same ones.
      EXPECT_EQ(rebuilt, 4u) << resumed.output;
      EXPECT_NE(resumed.output.find("for the 4 tiles, in 1 pass)"), std::string::npos) << resumed.output;
    }
    EXPECT_TRUE(bytes_of(out) == (damage == "frame_step" ? expected_every_other : expected));
    EXPECT_FALSE(fs::exists(job / "rebuild"));
    if (damage == "extracting") {
      const auto stats = nlohmann::json::parse(bytes_of(out.string() + ".json"));
      EXPECT_GT(stats["extract"]["resumed_items"].get<int>(), 0) << "the extraction's finished bricks were kept";
    }
  }
}

}  // namespace sf
