// scalefuse plan | run-tile | merge | slurm: one job split into tiles that cluster nodes integrate
// independently (scheduler/cluster.h, docs/cluster.md).
#include <tbb/info.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <sstream>

#include "cli/commands.h"
#include "cli/progress_printer.h"
#include "engine/error.h"
#include "scheduler/cluster.h"
#include "scheduler/cluster_stage.h"
#include "scheduler/job.h"

namespace sf::cli {

namespace {

std::string this_program() {
  std::error_code ec;
  const std::filesystem::path p = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::string("scalefuse") : p.string();
}

struct PlanArgs {
  FuseArgs fuse;
  std::size_t tiles = 0;
};

struct TileArgs {
  FuseArgs fuse;
  std::string dir, stage = "integrate";
  long tile = -1;
};

// What a tile's stages after integration need: the plan, the job's parameters, the budget.
TileStageContext stage_context(const std::filesystem::path& dir, const ClusterPlan& plan, const FuseArgs& options) {
  TileStageContext c;
  c.job_dir = dir;
  c.plan = plan;
  FuseArgs a;
  a.config = (dir / "config.toml").string();
  a.quiet = true;
  ParameterSet params;
  c.options = fusion_options(a, params);
  c.memory_limit = options.memory_limit.empty() ? default_memory_limit()
                                                : parse_byte_size(options.memory_limit, "--memory-limit");
  c.checkpoint_seconds = options.checkpoint_seconds;
  if (const char* k = std::getenv("SCALEFUSE_TEST_KILL_IN_EXTRACTION")) c.kill_in_extraction = std::strtoull(k, nullptr, 10);
  return c;
}

// Runs `f` in an arena of the requested threads with a progress line.
template <typename F>
void in_arena(const FuseArgs& options, F&& f, TileStageContext& c) {
  ProgressPrinter printer(options.quiet);
  c.progress = [&](std::string_view stage, double done, double total) { printer(stage, done, total); };
  tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::info::default_concurrency());
  arena.execute(f);
  printer.finish();
  c.progress = nullptr;
}

struct MergeArgs {
  FuseArgs fuse;
  std::string dir, output;
};

}  // namespace

void run_plan(const FuseArgs& a, std::size_t tiles) {
  if (a.job.empty()) throw InputError("plan: give the job directory (--job DIR)");
  ParameterSet params;
  const FusionOptions options = fusion_options(a, params);
  std::string input_abs;
  std::unique_ptr<FrameSource> source = open_inputs(a, options, &input_abs);
  const std::filesystem::path dir = a.job;
  const std::string identity = params.assignments(kIntegrationParameters);
  if (std::filesystem::exists(dir / "plan.json")) {
    const ClusterPlan old = read_cluster_plan(dir);
    std::string old_identity;
    const JobStatus st = Job::recorded(dir, &old_identity);
    if (old.tiles.size() != tiles || old_identity != identity || st.input != input_abs)
      throw InputError(dir.string() + ": already holds a plan (" + std::to_string(old.tiles.size()) +
                       " tiles) of other inputs, parameters or tile count; use a new --job directory");
    std::printf("already planned: %s (%zu tiles)\n", std::filesystem::absolute(dir).c_str(), old.tiles.size());
    return;
  }
  if (std::filesystem::exists(dir / "job.sqlite") && Job::status(dir).integrated > 0)
    throw InputError(dir.string() + ": holds a job that has integrated depth maps; plan into a new --job directory");
  const int threads = a.threads > 0 ? a.threads : tbb::info::default_concurrency();
  FusionPlan plan;
  {
    ProgressPrinter printer(a.quiet);
    tbb::task_arena arena(threads);
    arena.execute([&] {
      plan = plan_fusion(*source, options, tiles,
                         [&](std::string_view stage, double done, double total) { printer(stage, done, total); });
    });
    printer.finish();
  }
  std::filesystem::create_directories(dir);
  report_skipped(*source, dir);
  // The job: its inputs (identities), octree and configuration, as a single-machine fuse records
  // them; the merge resumes it.
  JobOptions jo;
  jo.dir = dir;
  jo.root = plan.root;
  jo.brick_level = plan.brick_level;
  const std::string output = a.output.empty() ? (dir / "mesh.ply").string() : a.output;
  {
    Job job(jo, identity, input_abs, std::filesystem::absolute(output).string());
    BrickMap map(plan.brick_level);
    job.begin(plan.identities, plan.root, map);
  }
  write_text_atomically(dir / "config.toml",
                        "# effective configuration of this job (scalefuse resume reads it)\n" + params.assignments());
  const ClusterPlan cp = cluster_plan_of(plan);
  write_cluster_plan(dir, cp);  // last: a plan.json means a complete plan
  double total = 0;
  for (const auto& t : cp.tiles) total += t.work;
  if (!a.quiet) {
    std::fprintf(stderr, "plan: %zu depth maps, root cube %.4g m, bricks of level %d (%.4g m), %zu tiles\n",
                 cp.depth_maps, cp.root.size, cp.brick_level, cp.root.cell_size(cp.brick_level), cp.tiles.size());
    std::fprintf(stderr, "  tile  bricks (box)                 depth maps  estimated field\n");
    for (std::size_t t = 0; t < cp.tiles.size(); ++t) {
      const BrickBox& b = cp.tiles[t].box;
      char box[64];
      std::snprintf(box, sizeof box, "%u-%u x %u-%u x %u-%u", b.lo.x, b.hi.x, b.lo.y, b.hi.y, b.lo.z, b.hi.z);
      std::fprintf(stderr, "  %4zu  %-27s  %10zu  %8.1f MiB (%4.1f %%)\n", t, box, cp.tiles[t].frames.size(),
                   cp.tiles[t].work / (1 << 20), total > 0 ? 100.0 * cp.tiles[t].work / total : 0.0);
    }
  }
  const std::string abs = std::filesystem::absolute(dir).string();
  std::printf("planned %s: %zu tiles; run each with: scalefuse run-tile %s --tile K (or scalefuse slurm %s), then: "
              "scalefuse merge %s\n",
              abs.c_str(), cp.tiles.size(), abs.c_str(), abs.c_str(), abs.c_str());
}

void run_tile(const std::string& job_dir, long tile_number, const FuseArgs& options, const std::string& stage) {
  const std::filesystem::path dir = job_dir;
  const ClusterPlan plan = read_cluster_plan(dir);
  const long k = tile_number >= 0 ? tile_number : tile_from_environment();
  if (k < 0) throw InputError("run-tile: give --tile K (or run it as a Slurm array task / indexed job)");
  if (std::size_t(k) >= plan.tiles.size())
    throw InputError((dir / "plan.json").string() + ": has " + std::to_string(plan.tiles.size()) + " tiles, no tile " +
                     std::to_string(k));
  const ClusterPlan::Tile& tile = plan.tiles[std::size_t(k)];
  // Testing aid: this tile fails (as a node's crash or a bad file would), for the tests of the
  // cluster engines' failure handling.
  if (const char* f = std::getenv("SCALEFUSE_TEST_FAIL_TILE"); f && std::to_string(k) == f)
    throw std::runtime_error("tile " + std::to_string(k) + ": failure injected by SCALEFUSE_TEST_FAIL_TILE");
  const auto& stages = tile_stages();
  if (std::find(stages.begin(), stages.end(), stage) == stages.end())
    throw InputError("run-tile: no stage '" + stage + "' (stages, in order: integrate, regularize, prepare, "
                     "tetrahedralize, snap, march, number, faces, sort)");
  TileStageContext context = stage_context(dir, plan, options);
  const auto clock = std::chrono::steady_clock::now();
  const auto seconds = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - clock).count(); };
  if (stage != "integrate") {
    bool ran = false;
    in_arena(options, [&] { ran = run_tile_stage(context, std::size_t(k), stage); }, context);
    if (ran) std::printf("tile %ld: stage %s done in %.1f s\n", k, stage.c_str(), seconds());
    else std::printf("tile %ld: stage %s was done before; nothing to do\n", k, stage.c_str());
    return;
  }
  const auto boundary = [&] {
    in_arena(options, [&] { write_tile_boundary(context, std::size_t(k)); }, context);
  };
  if (tile.frames.empty()) {
    boundary();
    std::printf("tile %ld: no depth map reaches it; nothing to integrate\n", k);
    return;
  }
  const std::filesystem::path tile_dir = tile_job_dir(dir, std::size_t(k));
  if (std::filesystem::exists(tile_dir / "job.sqlite")) {
    const JobStatus st = Job::status(tile_dir);
    if ((st.stage == "integrated" || st.stage == "extracting") && st.integrated == tile.frames.size()) {
      boundary();
      std::printf("tile %ld: already integrated (%zu depth maps, %zu bricks); nothing to do\n", k, st.integrated, st.bricks);
      return;
    }
  }
  const JobStatus job = Job::recorded(dir, nullptr);
  FuseArgs args = options;
  std::istringstream inputs(job.input);
  std::string line;
  std::getline(inputs, args.input);
  while (std::getline(inputs, line)) args.more_inputs.push_back(line);
  args.output = job.output;  // not written: a tile run stops after integration
  args.job = tile_dir.string();
  args.config = (dir / "config.toml").string();
  args.tile = FuseArgs::TileRun{std::size_t(k), tile.frames, tile.box, plan.root, plan.brick_level, dir / "plan.json"};
  run_fuse(args);
  boundary();  // what the neighbouring tiles' regularization needs of this one
}

void run_merge(const std::string& job_dir, const std::string& output, const FuseArgs& options) {
  const std::filesystem::path dir = job_dir;
  const ClusterPlan plan = read_cluster_plan(dir);
  TileStageContext context = stage_context(dir, plan, options);
  const StagesStatus stages = tile_stages_status(context);
  const bool regularized_any = [&] {
    for (std::size_t t = 0; t < plan.tiles.size(); ++t)
      if (tile_stage_finished(context, t, "regularize")) return true;
    return false;
  }();
  if (stages.pending.empty()) {
    // Every tile ran every stage: only the last pass is left.
    const std::string mesh = output.empty() ? Job::status(dir).output : output;
    ExtractStats es;
    std::pair<std::size_t, std::size_t> counts;
    const auto clock = std::chrono::steady_clock::now();
    in_arena(options, [&] {
      counts = write_job_mesh(mesh, dir, [&](MeshStream& out) { write_tiles_mesh(context, out, &es); });
    }, context);
    {
      JobOptions jo;
      jo.dir = dir;
      Job job(jo, "", "", "");
      job.finished(std::filesystem::absolute(mesh));
    }
    if (!options.quiet)
      std::fprintf(stderr, "merge: %zu tiles' extraction written in %.1f s: %zu voxels, %zu vertices, %zu triangles\n",
                   plan.tiles.size(), std::chrono::duration<double>(std::chrono::steady_clock::now() - clock).count(),
                   std::size_t(es.voxels), counts.first, counts.second);
    FusionStats fs;
    fs.format = "cluster tiles";
    fs.extract = es;
    fs.times.push_back({"write", std::chrono::duration<double>(std::chrono::steady_clock::now() - clock).count()});
    fs.peak_rss_bytes = peak_rss_bytes();
    write_stats_file(options.stats_json, fs, counts.first, counts.second);
    std::printf("mesh written to %s\n", std::filesystem::absolute(mesh).c_str());
    return;
  }
  if (regularized_any) {
    std::string tiles;
    for (std::size_t i = 0; i < stages.tiles.size() && i < 8; ++i) tiles += (i ? ", " : "") + std::to_string(stages.tiles[i]);
    if (stages.tiles.size() > 8) tiles += ", ...";
    throw InputError(dir.string() + ": " + std::to_string(stages.tiles.size()) + " of " + std::to_string(plan.tiles.size()) +
                     " tiles have not finished stage " + stages.pending + " (tiles " + tiles +
                     "); run: scalefuse run-tile " + std::filesystem::absolute(dir).string() + " --stage " +
                     stages.pending + " --tile K");
  }
  // No tile ran the stages after integration: the merge regularizes and extracts on this node.
  const JobStatus st = Job::status(dir);
  if (st.stage == "integrating" && st.integrated == 0) {
    // Every tile integrated, or say which are not and how to run them.
    std::vector<Job::Field> fields;
    std::string missing;
    std::size_t n_missing = 0;
    for (std::size_t t = 0; t < plan.tiles.size(); ++t) {
      if (plan.tiles[t].frames.empty()) continue;
      const std::filesystem::path tile_dir = tile_job_dir(dir, t);
      std::string why = "not started";
      if (std::filesystem::exists(tile_dir / "job.sqlite")) {
        const JobStatus ts = Job::status(tile_dir);
        if ((ts.stage == "integrated" || ts.stage == "extracting") && ts.integrated == plan.tiles[t].frames.size()) {
          fields.push_back(Job::field(tile_dir));
          continue;
        }
        why = ts.stage + ", " + std::to_string(ts.integrated) + " of " + std::to_string(plan.tiles[t].frames.size()) +
              " depth maps";
      }
      if (n_missing++ < 8) missing += (missing.empty() ? "" : ", ") + std::to_string(t) + " (" + why + ")";
    }
    if (n_missing > 0)
      throw InputError(dir.string() + ": " + std::to_string(n_missing) + " of " + std::to_string(plan.tiles.size()) +
                       " tiles are not integrated: " + missing + (n_missing > 8 ? ", ..." : "") +
                       "; run: scalefuse run-tile " + std::filesystem::absolute(dir).string() + " --tile K");
    JobOptions jo;
    jo.dir = dir;
    Job job(jo, "", "", "");
    job.adopt(fields, plan.depth_maps);
    if (!options.quiet)
      std::fprintf(stderr, "merge: the fields of %zu tiles adopted; regularizing and extracting\n", fields.size());
  }
  rerun_job(job_dir, options, "", output);
}

namespace {

struct SlurmArgs {
  std::string dir;
  SlurmOptions slurm;
  bool submit = false;
};

void run_slurm(SlurmArgs sa) {
  const std::filesystem::path dir = sa.dir;
  const ClusterPlan plan = read_cluster_plan(dir);
  if (sa.slurm.scalefuse.empty()) sa.slurm.scalefuse = this_program();
  if (sa.slurm.output.empty()) sa.slurm.output = Job::status(dir).output;
  sa.slurm.output = std::filesystem::absolute(sa.slurm.output).string();
  const SlurmScripts s = slurm_scripts(dir, plan.tiles.size(), sa.slurm);
  const std::filesystem::path logs = std::filesystem::absolute(dir) / "slurm";
  std::filesystem::create_directories(logs);
  write_text_atomically(logs / "tiles.sbatch", s.tiles);
  write_text_atomically(logs / "merge.sbatch", s.merge);
  write_text_atomically(logs / "submit.sh", s.submit);
  std::filesystem::permissions(logs / "submit.sh", std::filesystem::perms::owner_exec | std::filesystem::perms::group_exec,
                               std::filesystem::perm_options::add);
  std::printf("wrote %s/{tiles.sbatch,merge.sbatch,submit.sh} (an array of %zu tasks per stage, %zu stages, then "
              "the merge)\n",
              logs.c_str(), plan.tiles.size(), tile_stages().size());
  if (!sa.submit) {
    std::printf("submit with: %s/submit.sh\n", logs.c_str());
    return;
  }
  const std::string command = "sh '" + (logs / "submit.sh").string() + "'";
  const int rc = std::system(command.c_str());
  if (rc != 0)
    throw std::runtime_error("slurm: " + command + " failed (exit status " + std::to_string(rc) +
                             "); is sbatch on the PATH and the cluster reachable?");
}

}  // namespace

#ifndef SCALEFUSE_HAVE_MPI
void run_fuse_mpi(const FuseArgs&, std::size_t) {
  throw InputError("fuse --mpi: this scalefuse was built without MPI (install libopenmpi-dev and rebuild)");
}
#endif

void add_cluster_commands(CLI::App& app) {
  {
    auto pa = std::make_shared<PlanArgs>();
    FuseArgs& a = pa->fuse;
    CLI::App* cmd = app.add_subcommand("plan", "split a job into tiles of equal estimated work for cluster nodes");
    cmd->add_option("input", a.input, "COLMAP workspace, MVE scene, RGB-D folder or range-grid folder")->required();
    cmd->add_option("--tiles", pa->tiles, "number of tiles")->required()->check(CLI::PositiveNumber);
    cmd->add_option("--job", a.job, "job directory (shared by the nodes)")->required();
    cmd->add_option("-o,--output", a.output, "the mesh the merge writes (default: JOB/mesh.ply)");
    cmd->add_option("--config", a.config, "TOML parameter file (see configs/)");
    cmd->add_option("--set", a.sets, "override a parameter: key=value (repeatable)");
    cmd->add_option("--format", a.format, "input format: auto|colmap|mve|rgbd|rangegrid");
    cmd->add_option("--colmap-maps", a.colmap_maps, "COLMAP depth maps: geometric|photometric");
    cmd->add_option("--depth", a.mve_depth, "MVE depth embedding (e.g. depth-L2)");
    cmd->add_option("--image", a.mve_image, "MVE colour embedding (e.g. undist-L2)");
    cmd->add_option("--confidence", a.mve_confidence, "MVE confidence embedding (e.g. conf-L2)");
    cmd->add_option("--bbox", a.bbox, "clip box xmin,ymin,zmin,xmax,ymax,zmax (metres)");
    cmd->add_option("--brick-size", a.brick_size, "brick edge in metres at most");
    cmd->add_option("--extract", a.extract_mode, "tetrahedralization of the merge: global | bricks | auto");
    cmd->add_option("--threads", a.threads, "worker threads (default: all cores)")->check(CLI::NonNegativeNumber);
    cmd->add_flag("--skip-bad", a.skip_bad, "skip depth maps that fail to read (= --set job.skip_bad=true; the tiles skip them too)");
    cmd->add_flag("-q,--quiet", a.quiet, "no progress");
    cmd->callback([pa] { run_plan(pa->fuse, pa->tiles); });
  }
  {
    auto ta = std::make_shared<TileArgs>();
    CLI::App* cmd = app.add_subcommand(
        "run-tile", "integrate one tile of a planned job (resumes a killed run; a finished tile is a no-op)");
    cmd->add_option("dir", ta->dir, "job directory made by scalefuse plan")->required();
    cmd->add_option("--tile", ta->tile, "tile number (default: SLURM_ARRAY_TASK_ID or JOB_COMPLETION_INDEX)")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option("--stage", ta->stage,
                    "integrate (default), then once every tile has finished the one before: regularize, prepare, "
                    "tetrahedralize, snap, march, number, faces, sort (docs/cluster.md)");
    add_job_options(cmd, ta->fuse);
    cmd->callback([ta] { run_tile(ta->dir, ta->tile, ta->fuse, ta->stage); });
  }
  {
    auto ma = std::make_shared<MergeArgs>();
    CLI::App* cmd = app.add_subcommand(
        "merge", "once every tile is integrated: regularize and extract the whole field into one mesh (resumable)");
    cmd->add_option("dir", ma->dir, "job directory made by scalefuse plan")->required();
    cmd->add_option("-o,--output", ma->output, "output mesh (default: the plan's)");
    add_job_options(cmd, ma->fuse);
    cmd->callback([ma] { run_merge(ma->dir, ma->output, ma->fuse); });
  }
  {
    auto sa = std::make_shared<SlurmArgs>();
    SlurmOptions& o = sa->slurm;
    CLI::App* cmd = app.add_subcommand("slurm", "write (and submit) Slurm batch scripts: a tile array, then the merge");
    cmd->add_option("dir", sa->dir, "job directory made by scalefuse plan")->required();
    cmd->add_flag("--submit", sa->submit, "submit them now (sbatch)");
    cmd->add_option("-o,--output", o.output, "the mesh the merge writes (default: the plan's)");
    cmd->add_option("--scalefuse", o.scalefuse, "the program the nodes run (default: this one)");
    cmd->add_option("--partition", o.partition, "Slurm partition");
    cmd->add_option("--account", o.account, "Slurm account");
    cmd->add_option("--time", o.time, "time limit per tile (default 24:00:00)");
    cmd->add_option("--merge-time", o.merge_time, "time limit of the merge (default 24:00:00)");
    cmd->add_option("--cpus", o.cpus, "cores per tile (default 8)")->check(CLI::PositiveNumber);
    cmd->add_option("--merge-cpus", o.merge_cpus, "cores of the merge (default: --cpus)")->check(CLI::PositiveNumber);
    cmd->add_option("--mem", o.memory, "memory per tile, Slurm's --mem (default 16G)");
    cmd->add_option("--merge-mem", o.merge_memory, "memory of the merge (default: --mem)");
    cmd->add_option("--memory-limit", o.memory_limit, "scalefuse's --memory-limit (default: 3/4 of --mem)");
    cmd->add_option("--sbatch", o.extra, "a further #SBATCH option, verbatim (repeatable)");
    cmd->callback([sa] { run_slurm(*sa); });
  }
}

}  // namespace sf::cli
