// scalefuse fuse INPUT -o mesh.ply: the whole pipeline on one machine.
#include <tbb/info.h>
#include <tbb/task_arena.h>

#include <signal.h>
#include <unistd.h>

#include <atomic>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <nlohmann/json.hpp>

#include "cli/commands.h"
#include "cli/progress_printer.h"
#include "engine/error.h"
#include "engine/fusion.h"
#include "engine/input/follow_source.h"
#include "engine/input/skipping_source.h"
#include "engine/meshio/atomic_file.h"
#include "engine/meshio/ply_io.h"
#include "engine/vdb_export.h"
#include "scheduler/job.h"
#include "scheduler/tile_rebuild.h"

namespace sf::cli {

namespace {

// The flag signal handlers set: the one piece of process-wide state, owned by this boundary.
std::atomic<bool> g_stop{false};
std::atomic<int> g_signal{0};
extern "C" void on_stop_signal(int sig) {
  if (g_stop.load()) {  // a second signal: the user insists; the last checkpoint stays resumable
    ::signal(sig, SIG_DFL);
    ::raise(sig);
    return;
  }
  g_signal.store(sig);
  g_stop.store(true);
}

// Installs SIGINT/SIGTERM handlers for its lifetime.
class StopSignals {
 public:
  StopSignals() {
    g_stop = false;
    g_signal = 0;
    struct sigaction sa {};
    sa.sa_handler = on_stop_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, &old_int_);
    sigaction(SIGTERM, &sa, &old_term_);
  }
  ~StopSignals() {
    sigaction(SIGINT, &old_int_, nullptr);
    sigaction(SIGTERM, &old_term_, nullptr);
  }

 private:
  struct sigaction old_int_ {}, old_term_ {};
};


struct MeshCounts {
  std::size_t vertices = 0, triangles = 0;
};

// The output PLY, refused (before anything is written) when the mesh has no triangle.
class NonEmptyPly : public PlyStreamWriter {
 public:
  NonEmptyPly(const std::string& path, MeshCounts* counts) : PlyStreamWriter(path), counts_(counts) {}
  void begin(std::size_t vertices, std::size_t faces) override {
    if (faces == 0) throw InputError("the fused field has no surface (no zero crossing survived); nothing written");
    *counts_ = {vertices, faces};
    PlyStreamWriter::begin(vertices, faces);
  }

 private:
  MeshCounts* counts_;
};

nlohmann::json stats_json(const FusionStats& s, const MeshCounts& mesh) {
  nlohmann::json j;
  j["format"] = s.format;
  j["depth_maps"] = s.depth_maps;
  j["resumed_at"] = s.resumed_at;
  j["brick_level"] = s.brick_level;
  j["tiles"] = s.tiles;
  j["sweep_steps"] = s.sweep_steps;
  j["frame_reads"] = s.frame_reads;
  j["plan_estimate_bytes"] = s.plan_estimate_bytes;
  j["field_bytes"] = s.field_bytes;
  j["samples"] = s.samples;
  j["samples_outside_root"] = s.samples_outside_root;
  j["triangles_in"] = s.triangles;
  j["contributions"] = s.contributions;
  j["root"] = {{"min", {s.root.min.x(), s.root.min.y(), s.root.min.z()}}, {"size", s.root.size}};
  nlohmann::json levels = nlohmann::json::array();
  for (int l = 0; l <= kMaxLevel; ++l)
    if (s.voxels_fused[l] || s.triangles_per_level[l])
      levels.push_back({{"level", l}, {"cell_size", s.root.cell_size(l)}, {"triangles", s.triangles_per_level[l]},
                        {"voxels_fused", s.voxels_fused[l]}, {"voxels_regularized", s.voxels_regularized[l]}});
  j["levels"] = levels;
  j["regularize"] = {{"blended", s.regularize.blended}, {"deleted_unconfident", s.regularize.deleted_unconfident},
                     {"deleted_duplicates", s.regularize.deleted_duplicates}};
  j["extract"] = {{"voxels", s.extract.voxels}, {"tetrahedra", s.extract.tetrahedra},
                  {"kept_tetrahedra", s.extract.kept_tetrahedra}, {"snapped_voxels", s.extract.snapped_voxels},
                  {"removed_components", s.extract.removed_components}, {"windows", s.extract.windows},
                  {"window_points", s.extract.window_points},
                  {"window_voxels_in_cubes", s.extract.window_voxels_in_cubes}, {"windows_regrown", s.extract.windows_regrown},
                  {"windows_split", s.extract.windows_split},
                  {"resumed_items", s.extract.resumed_items},
                  {"window_cells_rejected", s.extract.window_cells_rejected},
                  {"mode", s.extract.by_brick ? "bricks" : "global"}};
  if (!s.extract.pass_seconds.empty()) {
    nlohmann::json passes = nlohmann::json::object();
    for (const auto& [pass, seconds] : s.extract.pass_seconds) passes[pass] = seconds;
    j["extract"]["pass_seconds"] = passes;
  }
  j["mesh"] = {{"vertices", mesh.vertices}, {"triangles", mesh.triangles}};
  nlohmann::json times = nlohmann::json::object();
  for (const auto& t : s.times) times[t.stage] = t.seconds;
  j["seconds"] = times;
  j["peak_rss_bytes"] = s.peak_rss_bytes;
  j["peak_rss_integrate_bytes"] = s.peak_rss_integrate_bytes;
  j["peak_rss_regularize_bytes"] = s.peak_rss_regularize_bytes;
  j["spill"] = {{"bricks_spilled", s.spill.spilled}, {"bricks_reloaded", s.spill.reloaded},
                {"bytes_written", s.spill.bytes_written}, {"bytes_read", s.spill.bytes_read}};
  return j;
}

void print_summary(const FusionStats& s, const MeshCounts& mesh, const std::string& output) {
  std::fprintf(stderr, "\nsummary (%s input)\n", s.format.c_str());
  std::fprintf(stderr, "  depth maps       %zu\n  samples          %zu\n  triangles in     %zu\n", s.depth_maps,
               s.samples, s.triangles);
  std::fprintf(stderr, "  root cube        %.4g m at (%.4g, %.4g, %.4g)\n", s.root.size, s.root.min.x(), s.root.min.y(),
               s.root.min.z());
  std::fprintf(stderr, "  bricks           level %d (%.4g m edge)\n", s.brick_level, s.root.cell_size(s.brick_level));
  if (s.samples_outside_root)
    std::fprintf(stderr, "  outside root     %zu samples of depth maps that arrived while following (dropped; give --bbox)\n",
                 s.samples_outside_root);
  std::fprintf(stderr, "  level  cell size    triangles   voxels fused  voxels kept\n");
  for (int l = 0; l <= kMaxLevel; ++l)
    if (s.voxels_fused[l] || s.triangles_per_level[l])
      std::fprintf(stderr, "  %5d  %9.4g m  %10zu  %13zu  %11zu\n", l, s.root.cell_size(l), s.triangles_per_level[l],
                   s.voxels_fused[l], s.voxels_regularized[l]);
  std::fprintf(stderr, "  regularized      %zu blended, %zu unconfident and %zu duplicate voxels deleted\n",
               s.regularize.blended, s.regularize.deleted_unconfident, s.regularize.deleted_duplicates);
  std::fprintf(stderr, "  tetrahedra       %zu (%zu kept by the neighbourhood rule)\n", s.extract.tetrahedra,
               s.extract.kept_tetrahedra);
  std::fprintf(stderr, "  output           %zu vertices, %zu triangles\n", mesh.vertices, mesh.triangles);
  double total = 0;
  for (const auto& t : s.times) {
    std::fprintf(stderr, "  time %-11s %8.2f s\n", t.stage.c_str(), t.seconds);
    total += t.seconds;
  }
  std::fprintf(stderr, "  time total       %8.2f s\n  peak memory      %.1f MiB\n", total,
               double(s.peak_rss_bytes) / (1024.0 * 1024.0));
  std::printf("mesh written to %s\n", std::filesystem::absolute(output).string().c_str());
}

}  // namespace

// Parameters that shape the integrated field: a job refuses to resume when they change.
// (Regularization and extraction may change: they rerun from the job's tiles. octree.brick_size
// only picks a new job's brick level, which the job records.)
const std::vector<std::string> kIntegrationParameters = {"input.",        "triangulate.",   "integrate.",
                                                         "octree.bbox",   "octree.padding", "octree.brick_level"};

std::size_t default_memory_limit() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGE_SIZE);
  if (pages <= 0 || page <= 0) return std::size_t{1} << 30;
  return std::size_t(pages) * std::size_t(page) / 4;  // a quarter of RAM for resident bricks
}

void write_text_atomically(const std::filesystem::path& path, const std::string& text) {
  write_file_atomic(path, text);
}

namespace {

// The job's copy of the mesh: a hard link to the output where the file system allows, else a copy.
void link_into_job(const std::filesystem::path& output, const std::filesystem::path& job_mesh) {
  std::error_code ec;
  std::filesystem::remove(job_mesh, ec);
  std::filesystem::create_hard_link(output, job_mesh, ec);
  if (ec) std::filesystem::copy_file(output, job_mesh, std::filesystem::copy_options::overwrite_existing);
}

}  // namespace

void write_stats_file(const std::string& path, const FusionStats& stats, std::size_t vertices, std::size_t triangles) {
  if (path.empty()) return;
  const std::string tmp = path + ".tmp";
  std::ofstream(tmp) << stats_json(stats, MeshCounts{vertices, triangles}).dump(2) << "\n";
  std::filesystem::rename(tmp, path);
}

std::pair<std::size_t, std::size_t> write_job_mesh(const std::string& output, const std::filesystem::path& job_dir,
                                                   const std::function<void(MeshStream&)>& produce) {
  MeshCounts counts;
  {
    NonEmptyPly ply(output, &counts);
    produce(ply);
  }
  link_into_job(output, job_dir / "mesh.ply");
  return {counts.vertices, counts.triangles};
}

FusionOptions fusion_options(const FuseArgs& a, ParameterSet& params) {
  FusionOptions options;
  register_parameters(params, options);
  if (!a.config.empty()) {
    if (!std::filesystem::exists(a.config)) throw input_error(a.config, "config file not found");
    params.load_toml(a.config);
  }
  // Shorthand flags are --set assignments under their parameter names.
  auto shorthand = [&](const std::string& value, const char* name) {
    if (!value.empty()) params.set(name, value, std::string("--") + name);
  };
  shorthand(a.format, "input.format");
  shorthand(a.colmap_maps, "input.colmap_maps");
  shorthand(a.mve_depth, "input.mve_depth");
  shorthand(a.mve_image, "input.mve_image");
  shorthand(a.mve_confidence, "input.mve_confidence");
  shorthand(a.bbox, "octree.bbox");
  shorthand(a.extract_mode, "extract.mode");
  shorthand(a.brick_size, "octree.brick_size");
  if (a.skip_bad) params.set("job.skip_bad", "true", "--skip-bad");
  for (const auto& s : a.sets) params.set_assignment(s);
  try {
    options.check();
  } catch (const InputError& e) {
    throw InputError(params.with_origin(e.what()));
  }
  if (!a.quiet || a.print_params) std::fprintf(stderr, "effective parameters:\n%s", params.describe().c_str());
  return options;
}

std::unique_ptr<FrameSource> open_inputs(const FuseArgs& a, const FusionOptions& options, std::string* input_abs) {
  *input_abs = std::filesystem::absolute(a.input).string();
  std::vector<std::unique_ptr<FrameSource>> parts;
  parts.push_back(open_input(a.input, options.input));
  for (const std::string& more : a.more_inputs) {
    parts.push_back(open_input(more, options.input));
    *input_abs += "\n" + std::filesystem::absolute(more).string();
  }
  std::unique_ptr<FrameSource> source = concatenate_inputs(std::move(parts));
  if (options.input.skip_bad) return std::make_unique<SkippingSource>(std::move(source));
  return source;
}

std::vector<SkippedFrame> report_skipped(const FrameSource& source, const std::filesystem::path& job_dir) {
  const auto* skipping = dynamic_cast<const SkippingSource*>(&source);
  if (!skipping) return {};
  std::vector<SkippedFrame> skipped = skipping->skipped();
  const std::filesystem::path list = job_dir / "skipped.txt";
  std::error_code ec;
  if (skipped.empty()) {
    std::filesystem::remove(list, ec);
    return skipped;
  }
  write_text_atomically(list, describe_skipped(skipped));
  // Even with -q: the user asked to go on past bad files and must learn which.
  std::fprintf(stderr, "skipped %zu bad depth map%s (listed in %s):\n", skipped.size(), skipped.size() == 1 ? "" : "s",
               std::filesystem::absolute(list).c_str());
  const std::size_t shown = std::min<std::size_t>(skipped.size(), 20);
  for (std::size_t i = 0; i < shown; ++i)
    std::fprintf(stderr, "  %s\n", describe_skipped(skipped[i]).c_str());
  if (shown < skipped.size()) std::fprintf(stderr, "  ... and %zu more\n", skipped.size() - shown);
  return skipped;
}

nlohmann::json skipped_json(const std::vector<SkippedFrame>& skipped) {
  nlohmann::json j = nlohmann::json::array();
  for (const SkippedFrame& s : skipped) j.push_back({{"file", s.file}, {"error", s.error}});
  return j;
}

void run_fuse(const FuseArgs& a) {
  ParameterSet params;
  const FusionOptions options = fusion_options(a, params);
  if (a.print_params) return;

  const int threads = a.threads > 0 ? a.threads : tbb::info::default_concurrency();
  // The job directory: given, or next to the output.
  const bool implicit_job = a.job.empty();
  JobOptions job_options;
  job_options.dir = implicit_job ? std::filesystem::path(a.output + ".job") : std::filesystem::path(a.job);
  // A job started with --follow keeps its order of depth maps when resumed, followed or not.
  const bool followed_job =
      !implicit_job && std::filesystem::exists(job_options.dir / "job.sqlite") && Job::status(job_options.dir).follow;
  job_options.follow = a.follow || followed_job;

  std::string input_abs = std::filesystem::absolute(a.input).string();
  std::unique_ptr<FrameSource> source;
  FollowSource* follow = nullptr;
  const std::filesystem::path stop_file =
      a.stop_file.empty() ? job_options.dir / "STOP" : std::filesystem::path(a.stop_file);
  if (job_options.follow) {
    if (!a.more_inputs.empty()) throw InputError("--follow takes one input folder");
    FollowOptions fo;
    fo.settle_seconds = a.settle_seconds;
    fo.poll_seconds = a.poll_seconds;
    fo.stop_file = stop_file;
    fo.stop = &g_stop;
    fo.until_idle = !a.follow;
    if (!a.quiet) fo.notice = [](const std::string& line) { std::fprintf(stderr, "follow: %s\n", line.c_str()); };
    auto fs = std::make_unique<FollowSource>(a.input, options.input, fo, Job::recorded_inputs(job_options.dir));
    follow = fs.get();
    follow->rescan();
    source = std::move(fs);
    if (options.input.skip_bad) source = std::make_unique<SkippingSource>(std::move(source));
    if (a.follow && !a.quiet)
      std::fprintf(stderr, "following %s: integrating depth maps as they complete; stop with: touch %s (or SIGTERM)\n",
                   input_abs.c_str(), std::filesystem::absolute(stop_file).c_str());
  } else {
    source = open_inputs(a, options, &input_abs);
  }
  if (a.tile)
    for (std::size_t i : a.tile->frames)
      if (i >= source->size())
        throw input_error(a.tile->plan_file.string(), "tile " + std::to_string(a.tile->tile) + " names depth map " +
                                                          std::to_string(i) + ", the input has " +
                                                          std::to_string(source->size()));
  job_options.memory_limit = a.memory_limit.empty() ? default_memory_limit() : parse_byte_size(a.memory_limit, "--memory-limit");
  job_options.checkpoint_every = a.checkpoint_every;
  job_options.checkpoint_seconds = a.checkpoint_seconds;
  job_options.allow_new_inputs = a.add;
  if (a.tile) {
    job_options.root = a.tile->root;
    job_options.brick_level = a.tile->brick_level;
  }
  if (const char* k = std::getenv("SCALEFUSE_TEST_KILL_AFTER")) job_options.kill_after = std::strtoull(k, nullptr, 10);
  if (const char* k = std::getenv("SCALEFUSE_TEST_TERM_AFTER")) job_options.term_after = std::strtoull(k, nullptr, 10);
  if (const char* k = std::getenv("SCALEFUSE_TEST_KILL_IN_EXTRACTION"))
    job_options.kill_in_extraction = std::strtoull(k, nullptr, 10);
  if (const char* k = std::getenv("SCALEFUSE_TEST_TERM_IN_EXTRACTION"))
    job_options.term_in_extraction = std::strtoull(k, nullptr, 10);
  const std::string identity = params.assignments(kIntegrationParameters);
  const std::string output_abs = std::filesystem::absolute(a.output).string();
  if (implicit_job && std::filesystem::exists(job_options.dir / "job.sqlite")) {
    // An implicit job left by an earlier run with other settings is stale: start over.
    std::string old_identity;
    const JobStatus old = Job::recorded(job_options.dir, &old_identity);
    if (old_identity != identity || old.input != input_abs) {
      if (!a.quiet) std::fprintf(stderr, "starting over: %s was made with other inputs or parameters\n", job_options.dir.c_str());
      std::filesystem::remove_all(job_options.dir);
    }
  }
  std::vector<SkippedFrame> skipped;
  auto run_job = [&](Job& job, MeshCounts& mesh, FusionStats& stats) -> bool {
    write_text_atomically(job.dir() / "config.toml",
                          "# effective configuration of this job (scalefuse resume reads it)\n" + params.assignments());
    if (!a.quiet)
      std::fprintf(stderr, "job: %s (bricks in memory up to %.2f GiB, checkpoint every %zu steps, %.0f s and tile)\n",
                   std::filesystem::absolute(job.dir()).c_str(), double(job_options.memory_limit) / double(1u << 30),
                   job_options.checkpoint_every, job_options.checkpoint_seconds);
    if (!a.quiet)
      std::fprintf(stderr, "input: %s (%s, %zu depth maps%s), %d threads\n", a.input.c_str(), source->format().c_str(),
                   source->size(), follow ? " complete so far" : "", threads);
    ProgressPrinter printer(a.quiet);
    FusionHooks hooks;
    hooks.progress = [&](std::string_view stage, double done, double total) { printer(stage, done, total); };
    if (!a.export_vdb.empty())  // the plugin is loaded now, so that a missing one fails before the work
      hooks.on_regularized = [&a, vdb = VdbExporter::load()](const std::vector<SurfaceVoxel>& voxels, const RootCube& root) {
        vdb.write(a.export_vdb, voxels, root);
      };
    // SIGINT/SIGTERM stop the run at the next safe point (after the depth maps or bricks in
    // flight), with the job checkpointed, and the process exits with 128 + the signal.
    StopSignals stop_signals;
    hooks.stop = &g_stop;
    hooks.follow = follow;
    // Following, a signal ends the feed and the job goes on to extract: that request is spent.
    if (follow) hooks.integrated = [] {
      g_stop = false;
      g_signal = 0;
    };
    hooks.stop_after_integration = a.integrate_only || a.tile.has_value();
    if (a.tile) {
      hooks.frames = &a.tile->frames;
      hooks.region = &a.tile->region;
      hooks.count_fused_voxels = false;
    }
    // The mesh streams into the output (temporary name until complete); the extraction's scratch
    // files live in the job.
    NonEmptyPly ply(a.output, &mesh);
    hooks.mesh_out = &ply;
    hooks.scratch = job.dir() / "scratch";
    tbb::task_arena arena(threads);
    try {
      arena.execute([&] { fuse(*source, options, hooks, &stats, &job); });
    } catch (const Interrupted& e) {
      printer.finish();
      report_skipped(*source, job.dir());
      throw JobInterrupted(std::string(e.what()) + "; checkpoint written; continue with: scalefuse resume " +
                               std::filesystem::absolute(job.dir()).string(),
                           g_signal.load());
    } catch (const InputError& e) {
      printer.finish();
      const std::vector<SkippedFrame> bad = report_skipped(*source, job.dir());
      if (bad.empty()) throw;
      throw InputError(std::string(e.what()) + " (" + std::to_string(bad.size()) + " of " +
                       std::to_string(source->size()) + " depth maps were skipped as bad)");
    }
    printer.finish();
    skipped = report_skipped(*source, job.dir());
    return !hooks.stop_after_integration;
  };
  // An implicit job whose depth maps changed is started over (once); an explicit one is refused.
  std::optional<Job> job_holder;
  std::set<std::uint64_t> rebuilt_bricks;
  FusionStats stats;
  MeshCounts mesh;
  bool extracted = false;
  // A job this run created that stopped (bad input, a full disk) before integrating anything holds
  // no work: remove it rather than leave an empty or half-made job behind.
  const bool job_existed = std::filesystem::exists(job_options.dir);
  auto removed_empty_job = [&]() -> bool {
    if (job_existed || job_options.follow) return false;
    std::error_code ec;
    if (std::filesystem::exists(job_options.dir / "skipped.txt", ec)) return false;
    bool empty = true;  // a journal this run could not even finish creating holds nothing
    try {
      empty = Job::status(job_options.dir).integrated == 0;
    } catch (const std::exception&) {
    }
    if (empty) std::filesystem::remove_all(job_options.dir, ec);
    return empty && !ec;
  };
  for (int attempt = 0;; ++attempt) {
    try {
      job_holder.emplace(job_options, identity, input_abs, output_abs);
      extracted = run_job(*job_holder, mesh, stats);
      break;
    } catch (const ResourceError& e) {
      job_holder.reset();  // releases the lock
      if (removed_empty_job())
        throw ResourceError(std::string(e.what()) + "; nothing was integrated yet: once fixed, run the command again");
      // The last checkpoint is intact (tiles are written before the journal commits them).
      throw ResourceError(std::string(e.what()) + "; once fixed, continue with: scalefuse resume " +
                          std::filesystem::absolute(job_options.dir).string());
    } catch (const JobMismatch& e) {
      if (!implicit_job || attempt > 0) throw;
      if (!a.quiet) std::fprintf(stderr, "starting over: %s\n", e.what());
      job_holder.reset();
      std::filesystem::remove_all(job_options.dir);
    } catch (const DamagedTile& e) {
      // A tile of the checkpoint is missing or damaged: every damaged tile of the checkpoint is
      // rebuilt from the depth maps the job integrated (once per brick), then the run goes on from
      // the checkpoint.
      if (!job_holder || !rebuilt_bricks.insert(e.coord.packed()).second) {
        job_holder.reset();
        throw;
      }
      tbb::task_arena arena(threads);
      std::vector<DamagedTile> damage;
      arena.execute([&] { damage = job_holder->damaged_tiles(); });
      if (std::none_of(damage.begin(), damage.end(), [&](const DamagedTile& d) { return d.coord.packed() == e.coord.packed(); }))
        damage.insert(damage.begin(), e);  // found by the run but not by the check (a file that changed since)
      for (const DamagedTile& d : damage)
        if (d.coord.packed() != e.coord.packed() && !rebuilt_bricks.insert(d.coord.packed()).second) {
          job_holder.reset();
          throw d;
        }
      TileRebuild r;
      arena.execute([&] { r = rebuild_tiles(*job_holder, damage, *source, options, a.tile ? &a.tile->frames : nullptr); });
      job_holder.reset();
      // Even with -q: the user should learn that the job's storage was damaged.
      const std::string together = damage.size() == 1 ? ""
                                   : " for the " + std::to_string(damage.size()) + " tiles, in " +
                                         std::to_string(r.passes) + (r.passes == 1 ? " pass" : " passes");
      for (std::size_t i = 0; i < damage.size(); ++i)
        std::fprintf(stderr, "%s; rebuilt it by re-integrating the %zu of the job's %zu depth maps that reach it (%.1f s%s)\n",
                     damage[i].what(), r.reaching[i], r.depth_maps[i], r.seconds, together.c_str());
    } catch (const InputError&) {
      job_holder.reset();
      removed_empty_job();
      throw;
    }
  }
  Job& job = *job_holder;
  auto write_stats = [&] {
    if (a.stats_json.empty()) return;
    const std::string tmp = a.stats_json + ".tmp";
    nlohmann::json j = stats_json(stats, mesh);
    if (options.input.skip_bad) j["skipped"] = skipped_json(skipped);
    std::ofstream(tmp) << j.dump(2) << "\n";
    std::filesystem::rename(tmp, a.stats_json);
  };
  if (!extracted && a.tile) {
    write_stats();
    std::printf("tile %zu integrated: %zu depth maps into %zu bricks; when every tile is, merge with: scalefuse merge %s\n",
                a.tile->tile, stats.depth_maps, Job::status(job.dir()).bricks,
                std::filesystem::absolute(job.dir().parent_path().parent_path()).c_str());
    return;
  }
  if (!extracted) {
    write_stats();
    std::printf("integrated %zu depth maps (bricks of level %d); extract with: scalefuse resume %s\n", stats.depth_maps,
                stats.brick_level, std::filesystem::absolute(job.dir()).c_str());
    return;
  }
  link_into_job(a.output, job.dir() / "mesh.ply");
  job.finished(std::filesystem::absolute(a.output));
  if (follow) {  // consumed: a later --follow of this job must not stop at once
    std::error_code ec;
    std::filesystem::remove(stop_file, ec);
  }
  if (!a.quiet && stats.resumed_at > 0)
    std::fprintf(stderr, "resumed: %zu of %zu depth maps were already integrated\n", stats.resumed_at, stats.depth_maps);
  write_stats();
  if (!a.quiet) print_summary(stats, mesh, a.output);
  else std::printf("mesh written to %s\n", std::filesystem::absolute(a.output).string().c_str());
}

void add_job_options(CLI::App* cmd, FuseArgs& args) {
  cmd->add_option("--threads", args.threads, "worker threads (default: all cores)")->check(CLI::NonNegativeNumber);
  cmd->add_option("--memory-limit", args.memory_limit, "memory for bricks, e.g. 1.5G (default: a quarter of RAM)");
  cmd->add_option("--checkpoint-every", args.checkpoint_every, "checkpoint after this many integration steps, a step being one depth map into one tile (default 200; also at each tile's end)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--checkpoint-seconds", args.checkpoint_seconds, "checkpoint at least this often (default 300 s)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--export-vdb", args.export_vdb, "also write the regularized field as OpenVDB grids (holds every surviving voxel in memory, 32 bytes each)");
  cmd->add_option("--stats", args.stats_json, "write the run's statistics as JSON");
  cmd->add_flag("-q,--quiet", args.quiet, "no progress or summary");
}

void add_fuse_command(CLI::App& app) {
  auto args = std::make_shared<FuseArgs>();
  CLI::App* cmd = app.add_subcommand("fuse", "fuse registered depth maps into one adaptive mesh");
  cmd->add_option("input", args->input, "COLMAP workspace, MVE scene, RGB-D folder or range-grid folder")->required();
  cmd->add_option("-o,--output", args->output, "output mesh (binary PLY)")->required();
  cmd->add_option("--config", args->config, "TOML parameter file (see configs/)");
  cmd->add_option("--set", args->sets, "override a parameter: key=value (repeatable)");
  cmd->add_option("--format", args->format, "input format: auto|colmap|mve|rgbd|rangegrid");
  cmd->add_option("--colmap-maps", args->colmap_maps, "COLMAP depth maps: geometric|photometric");
  cmd->add_option("--depth", args->mve_depth, "MVE depth embedding (e.g. depth-L2)");
  cmd->add_option("--image", args->mve_image, "MVE colour embedding (e.g. undist-L2)");
  cmd->add_option("--confidence", args->mve_confidence, "MVE confidence embedding (e.g. conf-L2)");
  cmd->add_option("--bbox", args->bbox, "clip box xmin,ymin,zmin,xmax,ymax,zmax (metres)");
  cmd->add_option("--brick-size", args->brick_size,
                  "brick edge in metres at most (bricks are the unit of paging and of extraction; default: the finest "
                  "level - 8)");
  cmd->add_option("--extract", args->extract_mode, "tetrahedralization: global (at once) | bricks (per brick window; the same mesh) | auto (default: bricks when global would exceed --memory-limit)");
  cmd->add_option("--job", args->job, "job directory (default: OUTPUT.job); an unfinished job there resumes");
  cmd->add_flag("--follow", args->follow,
                "keep integrating depth maps as they appear in INPUT until the stop file exists or SIGTERM");
  cmd->add_option("--stop-file", args->stop_file, "with --follow: stop when this file exists (default: JOB/STOP)");
  cmd->add_option("--settle-seconds", args->settle_seconds,
                  "with --follow: a depth map is complete once unchanged this long and readable (default 2)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--poll-seconds", args->poll_seconds, "with --follow: look at the folder this often (default 1)")
      ->check(CLI::PositiveNumber);
  add_job_options(cmd, *args);
  cmd->add_flag("--skip-bad", args->skip_bad,
                "skip depth maps that fail to read instead of stopping (they are listed at the end and in "
                "JOB/skipped.txt; = --set job.skip_bad=true)");
  cmd->add_flag("--print-params", args->print_params, "print the effective parameters and exit");
  cmd->add_flag("--integrate-only", args->integrate_only,
                "stop once every depth map is integrated and checkpointed; `scalefuse resume DIR` extracts");
  cmd->add_flag("--mpi", args->mpi,
                "run as MPI ranks (mpirun -n P scalefuse fuse ... --mpi): plan --tiles N tiles in the --job "
                "directory, ranks integrate them, rank 0 merges (docs/cluster.md)");
  cmd->add_option("--tiles", args->tiles, "with --mpi: number of tiles (default: 4 per rank)")->check(CLI::PositiveNumber);
  cmd->callback([args] {
    if (args->mpi) {
      if (args->follow || args->add || args->integrate_only)
        throw InputError("fuse --mpi: --follow and --integrate-only do not apply");
      run_fuse_mpi(*args, args->tiles);
    } else {
      if (args->tiles > 0) throw InputError("fuse: --tiles goes with --mpi (or use scalefuse plan)");
      run_fuse(*args);
    }
  });
}

}  // namespace sf::cli
