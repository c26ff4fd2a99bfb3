// scalefuse resume DIR and scalefuse status DIR: a job directory's life after `fuse` started it.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <sstream>
#include <vector>
#include <nlohmann/json.hpp>

#include "cli/commands.h"
#include "engine/error.h"
#include "scheduler/cluster.h"
#include "scheduler/cluster_stage.h"
#include "scheduler/job.h"

namespace sf::cli {

namespace {

}  // namespace

// The recorded job as `fuse` arguments, plus `more` input folders (scalefuse add).
void rerun_job(const std::string& dir, FuseArgs args, const std::string& more, const std::string& output) {
  const JobStatus st = Job::recorded(dir, nullptr);
  if (st.input.empty() || st.output.empty())
    throw InputError(dir + ": the job never got past its start; run fuse again");
  std::istringstream inputs(st.input);
  std::string line;
  std::getline(inputs, args.input);
  while (std::getline(inputs, line)) args.more_inputs.push_back(line);
  if (!more.empty()) {
    args.more_inputs.push_back(more);
    args.add = true;
  }
  args.output = output.empty() ? st.output : output;
  args.job = dir;
  args.config = (std::filesystem::path(dir) / "config.toml").string();
  run_fuse(args);
}

namespace {

// A cluster plan's tiles: each one's stage ("integrated", "integrating", "not started", "empty":
// no depth map reaches it) and depth maps integrated of its own.
struct TileState {
  std::string stage;
  std::string stage_done;  // the last of tile_stages() it has finished (integrate: with its boundary)
  std::size_t integrated = 0, depth_maps = 0, bricks = 0;
};
std::vector<TileState> tile_states(const std::filesystem::path& dir, const ClusterPlan& plan) {
  std::vector<TileState> out;
  for (std::size_t t = 0; t < plan.tiles.size(); ++t) {
    TileState s;
    s.depth_maps = plan.tiles[t].frames.size();
    const std::filesystem::path tile_dir = tile_job_dir(dir, t);
    if (s.depth_maps == 0) {
      s.stage = "empty";
    } else if (!std::filesystem::exists(tile_dir / "job.sqlite")) {
      s.stage = "not started";
    } else {
      const JobStatus ts = Job::status(tile_dir);
      s.stage = ts.stage == "new" ? "not started" : ts.stage == "extracting" ? "integrated" : ts.stage;
      s.integrated = ts.integrated;
      s.bricks = ts.bricks;
    }
    TileStageContext c;
    c.job_dir = dir;
    for (const std::string& stage : tile_stages())
      if (tile_stage_finished(c, t, stage)) s.stage_done = stage;
    out.push_back(s);
  }
  return out;
}

void run_status(const std::string& dir, bool json) {
  const JobStatus st = Job::status(dir);
  std::optional<ClusterPlan> plan;
  std::vector<TileState> tiles;
  if (std::filesystem::exists(std::filesystem::path(dir) / "plan.json")) {
    plan = read_cluster_plan(dir);
    tiles = tile_states(dir, *plan);
  }
  if (json) {
    nlohmann::json j = {{"stage", st.stage},           {"input", st.input},
                        {"output", st.output},         {"depth_maps", st.depth_maps},
                        {"integrated", st.integrated}, {"bricks", st.bricks},
                        {"tile_bytes", st.tile_bytes}, {"journal_bytes", st.journal_bytes},
                        {"last_checkpoint", st.last_checkpoint},
                        {"sweep", {{"tiles", st.sweep_tiles}, {"tile", st.sweep_tile}, {"steps", st.sweep_steps}}}};
    nlohmann::json passes = nlohmann::json::array();
    for (const JobStatus::ExtractPass& p : st.extraction)
      passes.push_back({{"pass", p.pass}, {"bricks", p.bricks}, {"complete", p.complete}});
    j["extraction"] = passes;
    if (plan) {
      nlohmann::json t = nlohmann::json::array();
      for (const TileState& s : tiles)
        t.push_back({{"stage", s.stage}, {"stage_done", s.stage_done}, {"depth_maps", s.depth_maps},
                     {"integrated", s.integrated}, {"bricks", s.bricks}});
      j["cluster"] = {{"tiles", t}};
    }
    std::printf("%s\n", j.dump(2).c_str());
    return;
  }
  std::printf("job          %s\n", std::filesystem::absolute(dir).c_str());
  std::printf("stage        %s\n", st.stage.c_str());
  std::string inputs = st.input;
  for (std::size_t at = inputs.find('\n'); at != std::string::npos; at = inputs.find('\n', at + 14))
    inputs.replace(at, 1, "\n             ");
  std::printf("input        %s\n", inputs.c_str());
  std::printf("output       %s\n", st.output.c_str());
  std::printf("depth maps   %zu of %zu integrated (at the last checkpoint%s%s)\n", st.integrated, st.depth_maps,
              st.last_checkpoint.empty() ? "" : ", ", st.last_checkpoint.c_str());
  if (st.sweep_tiles > 1)
    std::printf("sweep        in tile %zu of %zu, %zu steps (depth map x tile) done\n", st.sweep_tile + 1, st.sweep_tiles,
                st.sweep_steps);
  if (plan) {
    std::size_t done = 0, empty = 0, started = 0;
    for (const TileState& s : tiles) {
      done += s.stage == "integrated";
      empty += s.stage == "empty";
      started += s.stage == "integrating";
    }
    std::printf("cluster      %zu tiles: %zu integrated, %zu under way, %zu not started, %zu empty%s\n", tiles.size(),
                done, started, tiles.size() - done - started - empty, empty,
                done + empty == tiles.size() && st.integrated == 0 ? " (ready to merge)" : "");
    for (std::size_t t = 0; t < tiles.size() && t < 64; ++t)
      std::printf("  tile %-4zu  %-12s %zu of %zu depth maps, %zu bricks%s%s\n", t, tiles[t].stage.c_str(),
                  tiles[t].integrated, tiles[t].depth_maps, tiles[t].bricks,
                  tiles[t].stage_done.empty() ? "" : "; stages done up to ", tiles[t].stage_done.c_str());
  }
  std::printf("bricks       %zu\n", st.bricks);
  if (!st.extraction.empty()) {
    std::string passes;
    for (const JobStatus::ExtractPass& p : st.extraction)
      passes += (passes.empty() ? "" : ", ") + p.pass + (p.complete ? " done" : " " + std::to_string(p.bricks) + " bricks");
    std::printf("extraction   %s\n", passes.c_str());
  }
  std::printf("on disk      %.1f MiB of tiles, %.1f MiB of journal\n", double(st.tile_bytes) / (1 << 20),
              double(st.journal_bytes) / (1 << 20));
}

}  // namespace

void add_job_commands(CLI::App& app) {
  auto resume_dir = std::make_shared<std::string>();
  auto args = std::make_shared<FuseArgs>();
  CLI::App* resume = app.add_subcommand("resume", "continue a job from its last checkpoint (same inputs and parameters)");
  resume->add_option("dir", *resume_dir, "job directory")->required();
  add_job_options(resume, *args);
  resume->callback([resume_dir, args] { rerun_job(*resume_dir, *args, "", ""); });

  auto add_dir = std::make_shared<std::string>(), add_input = std::make_shared<std::string>();
  auto add_args = std::make_shared<FuseArgs>();
  CLI::App* add = app.add_subcommand(
      "add", "integrate more depth maps into a job (same octree; regularization and extraction run again)");
  add->add_option("dir", *add_dir, "job directory")->required();
  add->add_option("input", *add_input, "folder with the new depth maps (any supported format)")->required();
  add_job_options(add, *add_args);
  add->callback([add_dir, add_input, add_args] { rerun_job(*add_dir, *add_args, *add_input, ""); });

  auto status_dir = std::make_shared<std::string>();
  auto json = std::make_shared<bool>(false);
  CLI::App* status = app.add_subcommand("status", "print a job's progress");
  status->add_option("dir", *status_dir, "job directory")->required();
  status->add_flag("--json", *json, "as JSON");
  status->callback([status_dir, json] { run_status(*status_dir, *json); });
}

}  // namespace sf::cli
