// scalefuse synth MESH -o DIR: renders a synthetic multi-scale scene (see engine/synth/synth.h).
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "cli/commands.h"
#include "cli/progress_printer.h"
#include "engine/error.h"
#include "engine/parameters.h"
#include "engine/meshio/ply_io.h"
#include "engine/synth/scene_writer.h"
#include "engine/synth/city.h"
#include "engine/synth/synth.h"

namespace sf::cli {

namespace {

namespace fs = std::filesystem;

struct SynthArgs {
  std::vector<std::string> meshes;
  std::string mesh, output, format = "colmap", focus, far_size = "160x120", close_size = "640x480",
                            size_measure = "extent";
  SynthOptions synth;
  SceneWriteOptions write;
  bool overwrite = false, quiet = false;
  bool city = false;
  CityOptions city_options;
  std::string view_size = "500x375";
  bool far_given = false;
};

void parse_size(const std::string& text, const std::string& option, int* w, int* h) {
  char x = 0;
  std::istringstream ss(text);
  if (!(ss >> *w >> x >> *h) || x != 'x' || !ss.eof()) throw InputError(option + ": '" + text + "' is not WIDTHxHEIGHT");
}

std::string mm(double metres) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f mm", metres * 1000.0);
  return buf;
}

void prepare_output(const SynthArgs& a) {
  const fs::path out = a.output;
  std::error_code ec;
  if (fs::exists(out, ec)) {
    if (!fs::is_directory(out, ec)) throw input_error(a.output, "output exists and is not a folder");
    if (!fs::is_empty(out, ec)) {
      if (!a.overwrite) throw input_error(a.output, "output folder is not empty (use --overwrite to replace a scene)");
      clear_scene_outputs(out);
    }
  }
}

// synth --city: the Citywall-sized block of engine/synth/city.h.
void run_city(SynthArgs a) {
  const auto t0 = std::chrono::steady_clock::now();
  const auto format = parse_scene_format(a.format);
  if (!format) throw InputError("--format: '" + a.format + "' is not one of colmap, mve, rgbd");
  a.write.format = *format;
  for (const auto& m : a.meshes) a.write.source += (a.write.source.empty() ? "city of " : ", ") + m;
  parse_size(a.view_size, "--view-size", &a.city_options.width, &a.city_options.height);
  if (a.far_given) a.city_options.far_views = a.synth.far_views;
  a.city_options.noise = a.synth.noise;
  a.city_options.seed = a.synth.seed;
  a.city_options.focal = a.synth.focal;
  a.city_options.check();
  a.write.check();
  prepare_output(a);
  std::vector<Mesh> props;
  for (const auto& m : a.meshes) props.push_back(read_ply_mesh(m));
  ProgressPrinter printer(a.quiet);
  const SyntheticScene scene = render_city(
      props, a.city_options, [&](std::string_view stage, double done, double total) { printer(stage, done, total); });
  printer.finish();
  const auto t1 = std::chrono::steady_clock::now();
  const WrittenScene written = write_scene(scene, a.output, a.write);
  const auto t2 = std::chrono::steady_clock::now();
  if (a.quiet) return;
  auto secs = [](auto d) { return std::chrono::duration<double>(d).count(); };
  std::size_t samples = 0;
  for (const auto& v : scene.views) samples += v.valid_pixels;
  const CityOptions& c = a.city_options;
  std::printf("scalefuse synth --city: %zu statue meshes -> %s (%s)\n", a.meshes.size(), a.output.c_str(),
              format_name(*format));
  std::printf("  block        %zu vertices, %zu triangles, %d statues\n", scene.reference.vertices.size(),
              scene.reference.faces.size(), c.props);
  std::printf("  views        %zu of %dx%d: %d far, %d facade, %d street; %zu valid samples\n", scene.views.size(), c.width,
              c.height, c.far_views, c.facade_views, c.street_views, samples);
  std::printf("  footprints   far (median) %s, street (median) %s, ratio %.1f\n", mm(scene.coarse_footprint).c_str(),
              mm(scene.fine_footprint).c_str(),
              scene.fine_footprint > 0 ? scene.coarse_footprint / scene.fine_footprint : 0.0);
  std::printf("  wrote        %zu frames, %zu files in %.1f s (render %.1f s, write %.1f s)\n", written.frames,
              written.files.size(), secs(t2 - t0), secs(t1 - t0), secs(t2 - t1));
}

void run_synth(SynthArgs a) {
  if (a.city) return run_city(std::move(a));
  if (a.meshes.size() != 1) throw InputError("synth: give one mesh (several only with --city)");
  a.mesh = a.meshes.front();
  const auto t0 = std::chrono::steady_clock::now();
  const auto format = parse_scene_format(a.format);
  if (!format) throw InputError("--format: '" + a.format + "' is not one of colmap, mve, rgbd");
  a.write.format = *format;
  a.write.source = a.mesh;
  if (!a.focus.empty()) {
    const auto f = parse_number_list(a.focus, 3, "--focus");
    a.synth.focus = Eigen::Vector3d(f[0], f[1], f[2]);
  }
  if (a.size_measure == "extent") a.synth.size_measure = SynthOptions::SizeMeasure::Extent;
  else if (a.size_measure == "diagonal") a.synth.size_measure = SynthOptions::SizeMeasure::Diagonal;
  else throw InputError("--size-of: '" + a.size_measure + "' is not extent or diagonal");
  parse_size(a.far_size, "--far-size", &a.synth.far_width, &a.synth.far_height);
  parse_size(a.close_size, "--close-size", &a.synth.close_width, &a.synth.close_height);
  // RGB-D stores one K for the whole sequence.
  if (*format == SceneFormat::Rgbd) a.synth.uniform_resolution = true;
  a.synth.check();
  a.write.check();

  const fs::path out = a.output;
  prepare_output(a);

  const Mesh mesh = read_ply_mesh(a.mesh);
  const auto t1 = std::chrono::steady_clock::now();
  ProgressPrinter printer(a.quiet);
  const SyntheticScene scene =
      render_scene(mesh, a.synth, [&](std::string_view stage, double done, double total) { printer(stage, done, total); });
  printer.finish();
  const auto t2 = std::chrono::steady_clock::now();
  const WrittenScene written = write_scene(scene, out, a.write);
  const auto t3 = std::chrono::steady_clock::now();
  auto secs = [](auto d) { return std::chrono::duration<double>(d).count(); };

  if (a.quiet) return;
  const SynthOptions& o = scene.options;
  std::size_t n_far = 0, n_close = 0;
  for (const auto& v : scene.views) (v.close ? n_close : n_far)++;
  const SynthView* far = n_far ? &scene.views.front() : nullptr;
  const SynthView* close = n_close ? &scene.views.back() : nullptr;
  std::printf("scalefuse synth: %s -> %s (%s)\n", a.mesh.c_str(), a.output.c_str(), format_name(*format));
  std::printf("  mesh         %zu vertices, %zu triangles; scaled by %.6g to %s %.3g m\n", mesh.vertices.size(),
              mesh.faces.size(), scene.scale, o.size_measure == SynthOptions::SizeMeasure::Extent ? "extent" : "diagonal",
              o.size);
  if (far)
    std::printf("  far views    %zu x %dx%d, coarse footprint %s\n", n_far, far->width, far->height,
                mm(scene.coarse_footprint).c_str());
  if (close) {
    std::printf("  close views  %zu x %dx%d, fine footprint %s\n", n_close, close->width, close->height,
                mm(scene.fine_footprint).c_str());
    std::printf("  focus        %.4f,%.4f,%.4f  close-up radius %.4f m\n", scene.focus.x(), scene.focus.y(),
                scene.focus.z(), scene.close_radius);
  }
  if (far && close) std::printf("  ratio        coarse / fine = %.2f\n", scene.coarse_footprint / scene.fine_footprint);
  if (o.noise > 0) std::printf("  noise        sigma = %.3g footprint (seed %llu)\n", o.noise, (unsigned long long)o.seed);
  if (written.rgbd_clipped)
    std::printf("  warning      %zu depths beyond the 16-bit range were written as 0 (invalid)\n", written.rgbd_clipped);
  std::printf("  wrote        %zu frames, %zu files (reference.ply, synth.json) in %.2f s: read %.2f s, render %.2f s, write %.2f s\n",
              written.frames, written.files.size(), secs(t3 - t0), secs(t1 - t0), secs(t2 - t1), secs(t3 - t2));
}

}  // namespace

void add_synth_command(CLI::App& app) {
  auto args = std::make_shared<SynthArgs>();
  CLI::App* cmd = app.add_subcommand("synth", "Render a mesh into a synthetic multi-scale depth-map scene");
  SynthOptions& s = args->synth;
  cmd->add_option("mesh", args->meshes, "Input mesh (PLY); with --city, one or more statue meshes")->required();
  cmd->add_option("-o,--output", args->output, "Output folder")->required();
  cmd->add_option("--format", args->format, "colmap | mve | rgbd (rgbd renders every view at the close size)")
      ->capture_default_str();
  cmd->add_flag("--colmap-binary", args->write.colmap_binary, "COLMAP: write sparse/*.bin instead of *.txt");
  cmd->add_option("--depth-scale", args->write.rgbd_depth_scale, "RGB-D: metres per depth-PNG unit")->capture_default_str();
  cmd->add_option("--size", s.size, "Object size after normalization, metres")->capture_default_str();
  cmd->add_option("--size-of", args->size_measure, "What --size measures: extent (largest side) | diagonal")
      ->capture_default_str();
  cmd->add_option("--far", s.far_views, "Number of far views (--city: 64)")
      ->capture_default_str()
      ->each([args](const std::string&) { args->far_given = true; });
  cmd->add_option("--far-size", args->far_size, "Far view resolution WxH")->capture_default_str();
  cmd->add_option("--far-fill", s.far_fill, "Fraction of the smaller image side the object spans in far views")
      ->capture_default_str();
  cmd->add_option("--close", s.close_views, "Number of close views")->capture_default_str();
  cmd->add_option("--close-size", args->close_size, "Close view resolution WxH")->capture_default_str();
  cmd->add_option("--ratio", s.footprint_ratio, "Coarse / fine footprint ratio the close views aim at")
      ->capture_default_str();
  cmd->add_option("--tilt", s.close_tilt_deg, "Close views: degrees between view direction and surface normal")
      ->capture_default_str();
  cmd->add_option("--focus", args->focus, "Close-up point x,y,z in the normalized frame (default: top vertex)");
  cmd->add_option("--focal", s.focal, "Focal length in image widths")->capture_default_str();
  cmd->add_option("--noise", s.noise, "Depth noise sigma, in pixel footprints")->capture_default_str();
  cmd->add_option("--seed", s.seed, "Noise seed")->capture_default_str();
  CityOptions& c = args->city_options;
  cmd->add_flag("--city", args->city,
                "A city block the size of the paper's Citywall: statues (the meshes) before a street front, "
                "far, facade and street views (engine/synth/city.h)");
  cmd->add_option("--props", c.props, "--city: statues")->capture_default_str();
  cmd->add_option("--facade", c.facade_views, "--city: views of the street front")->capture_default_str();
  cmd->add_option("--street", c.street_views, "--city: street-level views of the statues")->capture_default_str();
  cmd->add_option("--view-size", args->view_size, "--city: resolution of every view WxH")->capture_default_str();
  cmd->add_option("--street-distance", c.street_distance, "--city: metres from a street camera to its statue")
      ->capture_default_str();
  cmd->add_option("--far-distance", c.far_distance, "--city: metres from a far camera to the block")
      ->capture_default_str();
  cmd->add_flag("--overwrite", args->overwrite, "Replace a scene already in the output folder");
  cmd->add_flag("-q,--quiet", args->quiet, "No progress or summary");
  cmd->callback([args] { run_synth(*args); });
}

}  // namespace sf::cli
