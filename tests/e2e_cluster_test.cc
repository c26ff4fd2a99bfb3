// Cluster runs (issue 5): a job planned into tiles, each integrated by its own process in any
// order (as Slurm array tasks or MPI ranks would), then merged, gives the single-machine mesh byte
// for byte; a finished tile is a no-op, a killed one resumes, and a merge refuses missing tiles.
#include <gtest/gtest.h>

#include <filesystem>
#include <algorithm>
#include <fstream>
#include <set>
#include <vector>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>

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

nlohmann::json plan_of(const fs::path& job) {
  std::ifstream in(job / "plan.json");
  return nlohmann::json::parse(in);
}

std::string tile_arg(std::size_t k) { return " --tile " + std::to_string(k); }

}  // namespace

TEST(Cluster, TilesInAnyOrderThenMergeGiveTheSingleMachineMesh) {
  const fs::path dir = test::scratch_dir("cluster-identity");
  const fs::path ref = dir / "ref.ply";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + ref.string() + " -q --threads 2 " + kScene).code, 0);
  const std::string expected = bytes_of(ref);
  ASSERT_GT(expected.size(), 10000u);
  for (std::size_t n : {1u, 3u, 5u}) {
    const fs::path job = dir / ("j" + std::to_string(n));
    const fs::path out = dir / ("m" + std::to_string(n) + ".ply");
    const CliRun planned = scalefuse("plan " + bunny().string() + " --tiles " + std::to_string(n) + " --job " +
                                     job.string() + " -o " + out.string() + " -q " + kScene);
    ASSERT_EQ(planned.code, 0) << planned.output;
    const nlohmann::json plan = plan_of(job);
    ASSERT_EQ(plan["tiles"].size(), n);
    // Every depth map reaches some tile (each scan sees the whole bunny, so here all of them), in
    // input order.
    std::set<std::size_t> reached;
    for (const auto& t : plan["tiles"]) {
      const auto frames = t["frames"].get<std::vector<std::size_t>>();
      EXPECT_TRUE(std::is_sorted(frames.begin(), frames.end()));
      reached.insert(frames.begin(), frames.end());
    }
    EXPECT_EQ(reached.size(), 10u);
    // Tiles run last to first, with other thread counts and memory limits than the reference.
    for (std::size_t k = n; k-- > 0;) {
      const CliRun r = scalefuse("run-tile " + job.string() + tile_arg(k) + " -q --threads " + (k % 2 ? "1" : "2") +
                                 " --memory-limit " + (k % 2 ? "8M" : "64M"));
      ASSERT_EQ(r.code, 0) << r.output;
    }
    const CliRun merged = scalefuse("merge " + job.string() + " -q --threads 2");
    ASSERT_EQ(merged.code, 0) << merged.output;
    EXPECT_NE(merged.output.find(out.string()), std::string::npos) << merged.output;
    EXPECT_TRUE(bytes_of(out) == expected) << n << " tiles: the merged mesh differs from the single-machine one";
  }
}

TEST(Cluster, FinishedTilesAreNoOpsKilledTilesResumeAndMergeWaitsForAll) {
  const fs::path dir = test::scratch_dir("cluster-faults");
  const fs::path ref = dir / "ref.ply", out = dir / "out.ply", job = dir / "job";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + ref.string() + " -q " + kScene).code, 0);
  ASSERT_EQ(scalefuse("plan " + bunny().string() + " --tiles 3 --job " + job.string() + " -o " + out.string() + " -q " +
                      kScene).code, 0);
  // Planning again the same way is a no-op; another tile count is refused.
  CliRun r = scalefuse("plan " + bunny().string() + " --tiles 3 --job " + job.string() + " -q " + kScene);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("already planned"), std::string::npos) << r.output;
  r = scalefuse("plan " + bunny().string() + " --tiles 4 --job " + job.string() + " -q " + kScene);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("already holds a plan"), std::string::npos) << r.output;

  // A merge before the tiles ran names the missing ones.
  r = scalefuse("merge " + job.string() + " -q");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("3 of 3 tiles are not integrated"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(out));

  // Tile 0 from the environment as a Slurm array task; killed after 3 depth maps, it resumes.
  r = scalefuse("run-tile " + job.string() + " -q --checkpoint-every 1", "SLURM_ARRAY_TASK_ID=0 SCALEFUSE_TEST_KILL_AFTER=3");
  EXPECT_NE(r.code, 0) << r.output;
  r = scalefuse("merge " + job.string() + " -q");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("0 (integrating"), std::string::npos) << r.output;
  r = scalefuse("run-tile " + job.string() + " -q", "SLURM_ARRAY_TASK_ID=0");
  ASSERT_EQ(r.code, 0) << r.output;
  r = scalefuse("run-tile " + job.string() + " -q", "SLURM_ARRAY_TASK_ID=0");
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.output.find("already integrated"), std::string::npos) << r.output;
  // A Kubernetes indexed job's index works the same; a tile the plan lacks is a bad input.
  ASSERT_EQ(scalefuse("run-tile " + job.string() + " -q", "JOB_COMPLETION_INDEX=1").code, 0);
  r = scalefuse("run-tile " + job.string() + " --tile 3 -q");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("no tile 3"), std::string::npos) << r.output;
  r = scalefuse("run-tile " + job.string() + " -q", "SLURM_ARRAY_TASK_ID=x");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("not a tile number"), std::string::npos) << r.output;

  r = scalefuse("merge " + job.string() + " -q");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("1 of 3 tiles are not integrated: 2 (not started)"), std::string::npos) << r.output;
  r = scalefuse("status " + job.string());
  EXPECT_NE(r.output.find("3 tiles: 2 integrated, 0 under way, 1 not started"), std::string::npos) << r.output;
  const nlohmann::json status = nlohmann::json::parse(scalefuse("status " + job.string() + " --json").output);
  ASSERT_EQ(status["cluster"]["tiles"].size(), 3u);
  EXPECT_EQ(status["cluster"]["tiles"][0]["stage"], "integrated");
  EXPECT_EQ(status["cluster"]["tiles"][2]["stage"], "not started");
  ASSERT_EQ(scalefuse("run-tile " + job.string() + tile_arg(2) + " -q").code, 0);
  r = scalefuse("merge " + job.string() + " -q");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(bytes_of(out) == bytes_of(ref));
  // Merging again re-extracts the adopted field: the same mesh.
  fs::remove(out);
  ASSERT_EQ(scalefuse("merge " + job.string() + " -q").code, 0);
  EXPECT_TRUE(bytes_of(out) == bytes_of(ref));
}

// Regularization and extraction on the tiles too: every stage run by every tile (in another order
// each stage, other threads and memory), then a merge that only writes the mesh.
TEST(Cluster, TilesRunEveryStageAndTheMergeOnlyWritesTheSingleMachineMesh) {
  const fs::path dir = test::scratch_dir("cluster-stages");
  const fs::path ref = dir / "ref.ply";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + ref.string() + " -q --threads 2 " + kScene).code, 0);
  const std::string expected = bytes_of(ref);
  const std::vector<std::string> stages = {"integrate", "regularize", "prepare", "tetrahedralize", "snap",
                                           "march",     "number",     "faces",   "sort"};
  for (std::size_t n : {1u, 4u}) {
    const fs::path job = dir / ("j" + std::to_string(n));
    const fs::path out = dir / ("m" + std::to_string(n) + ".ply");
    ASSERT_EQ(scalefuse("plan " + bunny().string() + " --tiles " + std::to_string(n) + " --job " + job.string() + " -o " +
                        out.string() + " -q " + kScene).code, 0);
    for (std::size_t s = 0; s < stages.size(); ++s) {
      for (std::size_t i = 0; i < n; ++i) {
        const std::size_t k = s % 2 ? i : n - 1 - i;
        if (i == n - 1 && n > 1 && s + 1 < stages.size()) {
          // The next stage before every tile finished this one is refused, naming the tile.
          const CliRun early = scalefuse("run-tile " + job.string() + " --stage " + stages[s + 1] +
                                         tile_arg(s % 2 ? 0 : n - 1) + " -q");
          EXPECT_EQ(early.code, 2) << early.output;
          EXPECT_NE(early.output.find("tile " + std::to_string(k) + " has not finished stage " + stages[s]),
                    std::string::npos)
              << early.output;
        }
        const CliRun r = scalefuse("run-tile " + job.string() + " --stage " + stages[s] + tile_arg(k) + " -q --threads " +
                                   (k % 2 ? "1" : "2") + " --memory-limit " + (k % 2 ? "8M" : "64M"));
        ASSERT_EQ(r.code, 0) << stages[s] << " tile " << k << ": " << r.output;
      }
      if (s == 3 && n > 1) {
        const CliRun m = scalefuse("merge " + job.string() + " -q");
        EXPECT_EQ(m.code, 2) << m.output;
        EXPECT_NE(m.output.find("have not finished stage snap"), std::string::npos) << m.output;
        EXPECT_FALSE(fs::exists(out));
      }
    }
    // A finished stage is a no-op.
    const CliRun again = scalefuse("run-tile " + job.string() + " --stage march" + tile_arg(0));
    EXPECT_EQ(again.code, 0) << again.output;
    EXPECT_NE(again.output.find("was done before"), std::string::npos) << again.output;
    const nlohmann::json status = nlohmann::json::parse(scalefuse("status " + job.string() + " --json").output);
    EXPECT_EQ(status["cluster"]["tiles"][0]["stage_done"], "sort");
    const CliRun merged = scalefuse("merge " + job.string() + " --threads 2");
    ASSERT_EQ(merged.code, 0) << merged.output;
    EXPECT_NE(merged.output.find("extraction written"), std::string::npos) << merged.output;
    EXPECT_TRUE(bytes_of(out) == expected) << n << " tiles: the mesh of the tiles' stages differs from one machine's";
  }
}

// A tile killed in the middle of a stage resumes it brick by brick; the mesh is the same.
TEST(Cluster, AKilledStageResumes) {
  const fs::path dir = test::scratch_dir("cluster-stage-kill");
  const fs::path ref = dir / "ref.ply", out = dir / "out.ply", job = dir / "job";
  ASSERT_EQ(scalefuse("fuse " + bunny().string() + " -o " + ref.string() + " -q " + kScene).code, 0);
  ASSERT_EQ(scalefuse("plan " + bunny().string() + " --tiles 2 --job " + job.string() + " -o " + out.string() + " -q " +
                      kScene).code, 0);
  for (const std::string stage : {"integrate", "regularize", "prepare", "tetrahedralize", "snap", "march", "number",
                                  "faces", "sort"})
    for (std::size_t k = 0; k < 2; ++k) {
      if (stage == "tetrahedralize" || stage == "regularize") {
        // Killed after its second commit of finished bricks (one brick each: the journal commits at once).
        const CliRun killed = scalefuse("run-tile " + job.string() + " --stage " + stage + tile_arg(k) +
                                            " -q --threads 1 --checkpoint-seconds 0.000001",
                                        "SCALEFUSE_TEST_KILL_IN_EXTRACTION=2");
        EXPECT_NE(killed.code, 0) << stage << ": " << killed.output;
      }
      const CliRun r = scalefuse("run-tile " + job.string() + " --stage " + stage + tile_arg(k) + " -q");
      ASSERT_EQ(r.code, 0) << stage << " tile " << k << ": " << r.output;
    }
  ASSERT_EQ(scalefuse("merge " + job.string() + " -q").code, 0);
  EXPECT_TRUE(bytes_of(out) == bytes_of(ref));
}

TEST(Cluster, SlurmScriptsChainTheMergeAfterEveryTile) {
  const fs::path dir = test::scratch_dir("cluster-slurm");
  const fs::path job = dir / "job";
  ASSERT_EQ(scalefuse("plan " + bunny().string() + " --tiles 4 --job " + job.string() + " -q " + kScene).code, 0);
  const CliRun r = scalefuse("slurm " + job.string() + " --cpus 2 --mem 2G --partition ci --time 1:00:00 --sbatch=--constraint=x");
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string tiles = bytes_of(job / "slurm" / "tiles.sbatch"), merge = bytes_of(job / "slurm" / "merge.sbatch"),
                    submit = bytes_of(job / "slurm" / "submit.sh");
  EXPECT_NE(tiles.find("#SBATCH --array=0-3\n"), std::string::npos) << tiles;
  EXPECT_NE(tiles.find("#SBATCH --partition=ci\n"), std::string::npos) << tiles;
  EXPECT_NE(tiles.find("#SBATCH --constraint=x\n"), std::string::npos) << tiles;
  EXPECT_NE(tiles.find(" run-tile '" + fs::absolute(job).string() + "'"), std::string::npos) << tiles;
  EXPECT_NE(tiles.find("--memory-limit 1610612736"), std::string::npos) << tiles;  // 3/4 of 2G
  EXPECT_NE(merge.find(" merge '" + fs::absolute(job).string() + "' -o '" + fs::absolute(job / "mesh.ply").string() + "'"),
            std::string::npos)
      << merge;
  EXPECT_NE(tiles.find("--stage \"${1:-integrate}\""), std::string::npos) << tiles;
  // One array per stage, each after the one before, then the merge after the last.
  EXPECT_NE(submit.find("for stage in integrate regularize prepare tetrahedralize snap march number faces sort; do"),
            std::string::npos)
      << submit;
  EXPECT_NE(submit.find("${prev:+--dependency=afterok:$prev --kill-on-invalid-dep=yes}"), std::string::npos) << submit;
  EXPECT_NE(submit.find("--dependency=afterok:$prev --kill-on-invalid-dep=yes merge.sbatch"), std::string::npos) << submit;
  for (const char* f : {"tiles.sbatch", "merge.sbatch", "submit.sh"})
    EXPECT_EQ(test::run_command("bash -n " + (job / "slurm" / f).string()), 0) << f << " is not valid shell";
  // Without a plan there is nothing to submit; a damaged plan is named.
  const CliRun none = scalefuse("slurm " + dir.string());
  EXPECT_EQ(none.code, 2);
  EXPECT_NE(none.output.find("plan.json"), std::string::npos) << none.output;
  test::write_text(dir / "broken" / "plan.json", "{\"version\": 1, \"root\": ");
  const CliRun broken = scalefuse("run-tile " + (dir / "broken").string() + " --tile 0");
  EXPECT_EQ(broken.code, 2);
  EXPECT_NE(broken.output.find("plan.json: malformed plan"), std::string::npos) << broken.output;
}

}  // namespace sf
