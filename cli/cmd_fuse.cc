// scalefuse fuse INPUT -o mesh.ply: the whole pipeline on one machine.
#include <tbb/info.h>
#include <tbb/task_arena.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>

#include "cli/commands.h"
#include "cli/progress_printer.h"
#include "engine/error.h"
#include "engine/fusion.h"
#include "engine/meshio/ply_io.h"
#include "engine/vdb_export.h"

namespace sf::cli {

namespace {

struct FuseArgs {
  std::string input, output, config, export_vdb, stats_json;
  std::string format, colmap_maps, mve_depth, mve_image, mve_confidence, bbox;
  std::vector<std::string> sets;
  int threads = 0;
  bool quiet = false, print_params = false;
};

nlohmann::json stats_json(const FusionStats& s, const Mesh& mesh) {
  nlohmann::json j;
  j["format"] = s.format;
  j["depth_maps"] = s.depth_maps;
  j["samples"] = s.samples;
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
                  {"removed_components", s.extract.removed_components}};
  j["mesh"] = {{"vertices", mesh.vertices.size()}, {"triangles", mesh.faces.size()}};
  nlohmann::json times = nlohmann::json::object();
  for (const auto& t : s.times) times[t.stage] = t.seconds;
  j["seconds"] = times;
  j["peak_rss_bytes"] = s.peak_rss_bytes;
  return j;
}

void print_summary(const FusionStats& s, const Mesh& mesh, const std::string& output) {
  std::fprintf(stderr, "\nsummary (%s input)\n", s.format.c_str());
  std::fprintf(stderr, "  depth maps       %zu\n  samples          %zu\n  triangles in     %zu\n", s.depth_maps,
               s.samples, s.triangles);
  std::fprintf(stderr, "  root cube        %.4g m at (%.4g, %.4g, %.4g)\n", s.root.size, s.root.min.x(), s.root.min.y(),
               s.root.min.z());
  std::fprintf(stderr, "  level  cell size    triangles   voxels fused  voxels kept\n");
  for (int l = 0; l <= kMaxLevel; ++l)
    if (s.voxels_fused[l] || s.triangles_per_level[l])
      std::fprintf(stderr, "  %5d  %9.4g m  %10zu  %13zu  %11zu\n", l, s.root.cell_size(l), s.triangles_per_level[l],
                   s.voxels_fused[l], s.voxels_regularized[l]);
  std::fprintf(stderr, "  regularized      %zu blended, %zu unconfident and %zu duplicate voxels deleted\n",
               s.regularize.blended, s.regularize.deleted_unconfident, s.regularize.deleted_duplicates);
  std::fprintf(stderr, "  tetrahedra       %zu (%zu kept by the neighbourhood rule)\n", s.extract.tetrahedra,
               s.extract.kept_tetrahedra);
  std::fprintf(stderr, "  output           %zu vertices, %zu triangles\n", mesh.vertices.size(), mesh.faces.size());
  double total = 0;
  for (const auto& t : s.times) {
    std::fprintf(stderr, "  time %-11s %8.2f s\n", t.stage.c_str(), t.seconds);
    total += t.seconds;
  }
  std::fprintf(stderr, "  time total       %8.2f s\n  peak memory      %.1f MiB\n", total,
               double(s.peak_rss_bytes) / (1024.0 * 1024.0));
  std::printf("mesh written to %s\n", std::filesystem::absolute(output).string().c_str());
}

void run_fuse(const FuseArgs& a) {
  FusionOptions options;
  ParameterSet params;
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
  for (const auto& s : a.sets) params.set_assignment(s);
  options.check();
  if (!a.quiet || a.print_params) std::fprintf(stderr, "effective parameters:\n%s", params.describe().c_str());
  if (a.print_params) return;

  const int threads = a.threads > 0 ? a.threads : tbb::info::default_concurrency();
  auto source = open_input(a.input, options.input);
  if (!a.quiet)
    std::fprintf(stderr, "input: %s (%s, %zu depth maps), %d threads\n", a.input.c_str(), source->format().c_str(),
                 source->size(), threads);
  ProgressPrinter printer(a.quiet);
  FusionHooks hooks;
  hooks.progress = [&](std::string_view stage, double done, double total) { printer(stage, done, total); };
  if (!a.export_vdb.empty())
    hooks.on_regularized = [&](const BrickMap& map, const RootCube& root) { export_vdb(a.export_vdb, map, root); };
  FusionStats stats;
  Mesh mesh;
  tbb::task_arena arena(threads);
  arena.execute([&] { mesh = fuse(*source, options, hooks, &stats); });
  printer.finish();
  if (mesh.faces.empty()) throw InputError("the fused field has no surface (no zero crossing survived); nothing written");
  write_ply_mesh(a.output, mesh);
  if (!a.stats_json.empty()) {
    const std::string tmp = a.stats_json + ".tmp";
    std::ofstream(tmp) << stats_json(stats, mesh).dump(2) << "\n";
    std::filesystem::rename(tmp, a.stats_json);
  }
  if (!a.quiet) print_summary(stats, mesh, a.output);
  else std::printf("mesh written to %s\n", std::filesystem::absolute(a.output).string().c_str());
}

}  // namespace

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
  cmd->add_option("--threads", args->threads, "worker threads (default: all cores)")->check(CLI::NonNegativeNumber);
  cmd->add_option("--export-vdb", args->export_vdb, "also write the regularized field as OpenVDB grids");
  cmd->add_option("--stats", args->stats_json, "write the run's statistics as JSON");
  cmd->add_flag("--print-params", args->print_params, "print the effective parameters and exit");
  cmd->add_flag("-q,--quiet", args->quiet, "no progress or summary");
  cmd->callback([args] { run_fuse(*args); });
}

}  // namespace sf::cli
