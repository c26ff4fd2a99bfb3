#include "scheduler/cluster.h"

#include <fcntl.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <sstream>

#include "engine/error.h"
#include "engine/input/file_util.h"
#include "engine/meshio/atomic_file.h"
#include "scheduler/job.h"

namespace sf {

namespace {

constexpr int kPlanVersion = 1;

nlohmann::json coord_json(const BrickCoord& c) { return {c.x, c.y, c.z}; }

BrickCoord coord_of(const nlohmann::json& j) {
  if (!j.is_array() || j.size() != 3) throw std::runtime_error("a brick coordinate is not 3 integers");
  return {j[0].get<std::uint32_t>(), j[1].get<std::uint32_t>(), j[2].get<std::uint32_t>()};
}

// Single-quoted for a POSIX shell.
std::string quoted(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

}  // namespace

ClusterPlan cluster_plan_of(const FusionPlan& p) {
  ClusterPlan c;
  c.root = p.root;
  c.brick_level = p.brick_level;
  c.depth_maps = p.frames.size();
  c.samples = p.samples;
  for (std::size_t t = 0; t < p.tiles.size(); ++t) c.tiles.push_back({p.tiles[t], p.work[t], p.tile_frames[t]});
  return c;
}

void write_cluster_plan(const std::filesystem::path& dir, const ClusterPlan& plan) {
  nlohmann::json j;
  j["version"] = kPlanVersion;
  // Exact doubles: the tiles' octree must be the very one the merge and a single-machine run use.
  char buffer[64];
  auto exact = [&](double v) {
    std::snprintf(buffer, sizeof buffer, "%a", v);
    return std::string(buffer);
  };
  j["root"] = {{"min", {exact(plan.root.min.x()), exact(plan.root.min.y()), exact(plan.root.min.z())}},
               {"size", exact(plan.root.size)}};
  j["brick_level"] = plan.brick_level;
  j["depth_maps"] = plan.depth_maps;
  j["samples"] = plan.samples;
  nlohmann::json tiles = nlohmann::json::array();
  for (std::size_t t = 0; t < plan.tiles.size(); ++t) {
    const ClusterPlan::Tile& tile = plan.tiles[t];
    tiles.push_back({{"tile", t},
                     {"lo", coord_json(tile.box.lo)},
                     {"hi", coord_json(tile.box.hi)},
                     {"work_bytes", tile.work},
                     {"frames", tile.frames}});
  }
  j["tiles"] = tiles;
  write_file_atomic(dir / "plan.json", j.dump(1) + "\n");
}

ClusterPlan read_cluster_plan(const std::filesystem::path& dir) {
  const std::filesystem::path path = dir / "plan.json";
  std::error_code ec;
  if (!std::filesystem::exists(path, ec))
    throw input_error(path.string(), "no plan here (make one with: scalefuse plan INPUT --tiles N --job DIR)");
  const std::string text = input_detail::read_file_text(path);  // names the file and the reason
  ClusterPlan plan;
  try {
    const nlohmann::json j = nlohmann::json::parse(text);
    if (j.at("version").get<int>() != kPlanVersion)
      throw std::runtime_error("plan version " + j.at("version").dump() + ", this build reads " +
                               std::to_string(kPlanVersion));
    auto exact = [](const nlohmann::json& v) {
      const std::string s = v.get<std::string>();
      char* end = nullptr;
      const double d = std::strtod(s.c_str(), &end);
      if (end == s.c_str() || *end != '\0') throw std::runtime_error("not a number: " + s);
      return d;
    };
    const auto& root = j.at("root");
    plan.root.min = {exact(root.at("min").at(0)), exact(root.at("min").at(1)), exact(root.at("min").at(2))};
    plan.root.size = exact(root.at("size"));
    if (!(plan.root.size > 0)) throw std::runtime_error("the root cube's size must be > 0");
    plan.brick_level = j.at("brick_level").get<int>();
    if (plan.brick_level < 0 || plan.brick_level > 10) throw std::runtime_error("brick_level must be in 0..10");
    plan.depth_maps = j.at("depth_maps").get<std::size_t>();
    plan.samples = j.at("samples").get<std::size_t>();
    const std::uint32_t grid = 1u << plan.brick_level;
    for (const auto& t : j.at("tiles")) {
      ClusterPlan::Tile tile;
      tile.box = {coord_of(t.at("lo")), coord_of(t.at("hi"))};
      for (std::uint32_t v : {tile.box.hi.x, tile.box.hi.y, tile.box.hi.z})
        if (v > grid) throw std::runtime_error("a tile reaches past the brick grid");
      if (tile.box.lo.x > tile.box.hi.x || tile.box.lo.y > tile.box.hi.y || tile.box.lo.z > tile.box.hi.z)
        throw std::runtime_error("a tile's lo exceeds its hi");
      tile.work = t.at("work_bytes").get<double>();
      tile.frames = t.at("frames").get<std::vector<std::size_t>>();
      if (t.at("tile").get<std::size_t>() != plan.tiles.size()) throw std::runtime_error("tiles out of order");
      plan.tiles.push_back(std::move(tile));
    }
    if (plan.tiles.empty()) throw std::runtime_error("no tiles");
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw input_error(path.string(), std::string("malformed plan: ") + e.what());
  }
  return plan;
}

std::filesystem::path tile_job_dir(const std::filesystem::path& dir, std::size_t tile) {
  char name[32];
  std::snprintf(name, sizeof name, "tile-%04zu", tile);
  return dir / "cluster" / name;
}

long tile_from_environment() {
  for (const char* name : {"SLURM_ARRAY_TASK_ID", "JOB_COMPLETION_INDEX"}) {
    const char* v = std::getenv(name);
    if (!v || !*v) continue;
    char* end = nullptr;
    errno = 0;
    const long k = std::strtol(v, &end, 10);
    if (errno != 0 || *end != '\0' || k < 0)
      throw InputError(std::string(name) + "=" + v + ": not a tile number");
    return k;
  }
  return -1;
}

SlurmScripts slurm_scripts(const std::filesystem::path& job_dir, std::size_t tiles, const SlurmOptions& o) {
  if (tiles == 0) throw InputError("slurm: the plan has no tiles");
  const std::string dir = std::filesystem::absolute(job_dir).lexically_normal().string();
  const std::string logs = dir + "/slurm";
  const int merge_cpus = o.merge_cpus > 0 ? o.merge_cpus : o.cpus;
  const std::string merge_memory = o.merge_memory.empty() ? o.memory : o.merge_memory;
  // scalefuse's brick budget: 3/4 of the task's memory, the rest for depth maps, triangulations
  // and the program.
  auto budget = [&](const std::string& mem) {
    if (!o.memory_limit.empty()) return o.memory_limit;
    // Slurm's --mem is in MiB without a unit.
    const bool bare = !mem.empty() && std::isdigit(static_cast<unsigned char>(mem.back()));
    const std::size_t bytes = parse_byte_size(bare ? mem + "M" : mem, "slurm --mem");
    return std::to_string(bytes / 4 * 3);
  };
  auto header = [&](const std::string& name, int cpus, const std::string& mem, const std::string& time,
                    const std::string& log) {
    std::ostringstream s;
    s << "#!/bin/bash\n# written by scalefuse slurm for the job " << dir << "\n";
    s << "#SBATCH --job-name=" << name << "\n";
    s << "#SBATCH --cpus-per-task=" << cpus << "\n#SBATCH --ntasks=1\n";
    s << "#SBATCH --mem=" << mem << "\n#SBATCH --time=" << time << "\n";
    s << "#SBATCH --output=" << log << "\n";
    if (!o.partition.empty()) s << "#SBATCH --partition=" << o.partition << "\n";
    if (!o.account.empty()) s << "#SBATCH --account=" << o.account << "\n";
    for (const std::string& e : o.extra) s << "#SBATCH " << e << "\n";
    return s.str();
  };
  SlurmScripts out;
  {
    std::ostringstream s;
    s << header("scalefuse-tiles", o.cpus, o.memory, o.time, logs + "/tile-%a.log");
    s << "#SBATCH --array=0-" << tiles - 1 << "\n";
    s << "set -euo pipefail\n";
    s << "# the tile is SLURM_ARRAY_TASK_ID, the stage $1 (submit.sh submits one array per stage, each after\n";
    s << "# the one before); a finished stage is a no-op, a killed one resumes\n";
    s << "exec " << quoted(o.scalefuse) << " run-tile " << quoted(dir) << " --stage \"${1:-integrate}\" --threads \"${SLURM_CPUS_PER_TASK:-"
      << o.cpus << "}\" --memory-limit " << budget(o.memory) << "\n";
    out.tiles = s.str();
  }
  {
    std::ostringstream s;
    s << header("scalefuse-merge", merge_cpus, merge_memory, o.merge_time, logs + "/merge.log");
    s << "#SBATCH --kill-on-invalid-dep=yes\n";
    s << "set -euo pipefail\n";
    s << "exec " << quoted(o.scalefuse) << " merge " << quoted(dir) << " -o " << quoted(o.output)
      << " --threads \"${SLURM_CPUS_PER_TASK:-" << merge_cpus << "}\" --memory-limit " << budget(merge_memory) << "\n";
    out.merge = s.str();
  }
  {
    std::ostringstream s;
    s << "#!/bin/sh\n# written by scalefuse slurm: submits one array of the tiles per stage, each after every task\n";
    s << "# of the one before succeeded, then the merge after the last (a failure cancels what follows)\n";
    s << "set -eu\ncd " << quoted(logs) << "\n";
    s << "first= prev= all=\n";
    s << "for stage in";
    for (const char* stage : {"integrate", "regularize", "prepare", "tetrahedralize", "snap", "march", "number", "faces", "sort"})
      s << ' ' << stage;
    s << "; do\n";
    s << "  id=$(sbatch --parsable ${prev:+--dependency=afterok:$prev --kill-on-invalid-dep=yes} "
         "--job-name=\"scalefuse-$stage\" --output=" << quoted(logs) << "\"/$stage-%a.log\" tiles.sbatch \"$stage\")\n";
    s << "  id=${id%%;*}\n  first=${first:-$id} prev=$id all=\"$all $id\"\ndone\n";
    s << "merge=$(sbatch --parsable --dependency=afterok:$prev --kill-on-invalid-dep=yes merge.sbatch)\n";
    s << "merge=${merge%%;*}\n";
    s << "echo \"tiles: Slurm jobs$all (an array of " << tiles << " per stage); merge: Slurm job $merge\"\n";
    s << "printf '%s %s\\nstages:%s\\n' \"$first\" \"$merge\" \"$all\" > submitted\n";
    out.submit = s.str();
  }
  return out;
}

}  // namespace sf
