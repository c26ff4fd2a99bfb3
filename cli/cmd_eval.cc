// scalefuse eval RECON REFERENCE: accuracy / completeness / F-score of a mesh (engine/synth/eval.h).
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "cli/commands.h"
#include "cli/progress_printer.h"
#include "engine/error.h"
#include "engine/parameters.h"
#include "engine/meshio/ply_io.h"
#include "engine/synth/eval.h"
#include "engine/synth/scene_writer.h"

namespace sf::cli {

namespace {

struct EvalArgs {
  std::string recon, reference, region, box, scene;
  bool close_up = false, observed = false, json = false, quiet = false;
  EvalOptions eval;
};

std::string mm(double metres) {
  if (std::isnan(metres)) return "-";
  if (std::isinf(metres)) return "inf";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f mm", metres * 1000.0);
  return buf;
}

nlohmann::json stats_json(const DistanceStats& s) {
  return {{"count", s.count}, {"mean", s.mean}, {"median", s.median}, {"p90", s.p90}, {"max", s.max}};
}

void run_eval(EvalArgs a) {
  EvalOptions& o = a.eval;
  if (!a.region.empty()) {
    const auto v = parse_number_list(a.region, 4, "--region");
    o.sphere = EvalOptions::Sphere{Eigen::Vector3d(v[0], v[1], v[2]), v[3]};
  }
  if (!a.box.empty()) {
    const auto v = parse_number_list(a.box, 6, "--box");
    o.box = Eigen::AlignedBox3d(Eigen::Vector3d(v[0], v[1], v[2]), Eigen::Vector3d(v[3], v[4], v[5]));
  }
  if ((a.close_up || a.observed) && a.scene.empty()) throw InputError("--close-up and --observed need --scene synth.json");
  if (!a.scene.empty()) {
    const SceneInfo info = read_scene_info(a.scene);
    if (a.close_up) {
      if (o.sphere) throw InputError("--close-up and --region both give a sphere: use one");
      if (!(info.close_radius > 0)) throw input_error(a.scene, "the scene has no close views (close_radius 0)");
      o.sphere = EvalOptions::Sphere{info.focus, info.close_radius};
    }
    if (a.observed) o.observers = info.cameras;
  }
  o.check();
  const Mesh recon = read_ply_mesh(a.recon);
  const Mesh reference = read_ply_mesh(a.reference);
  ProgressPrinter printer(a.quiet);
  const EvalResult r =
      evaluate(recon, reference, o, [&](std::string_view stage, double done, double total) { printer(stage, done, total); });
  printer.finish();

  if (a.json) {
    nlohmann::json j;
    j["recon"] = a.recon;
    j["reference"] = a.reference;
    j["spacing"] = r.spacing;
    j["recon_samples"] = r.recon_samples;
    j["reference_samples"] = r.reference_samples;
    j["region"] = nullptr;
    if (o.sphere)
      j["region"]["sphere"] = {{"centre", {o.sphere->centre.x(), o.sphere->centre.y(), o.sphere->centre.z()}},
                               {"radius", o.sphere->radius}};
    if (o.box)
      j["region"]["box"] = {{"min", {o.box->min().x(), o.box->min().y(), o.box->min().z()}},
                            {"max", {o.box->max().x(), o.box->max().y(), o.box->max().z()}}};
    j["observed_only"] = !o.observers.empty();
    j["accuracy"] = stats_json(r.accuracy);
    j["completeness"] = stats_json(r.completeness);  // non-finite values are written as null
    j["scores"] = nlohmann::json::array();
    for (const FScore& f : r.scores)
      j["scores"].push_back({{"tau", f.tau}, {"precision", f.precision}, {"recall", f.recall}, {"fscore", f.fscore}});
    std::cout << j.dump(2) << "\n";
    return;
  }
  std::printf("recon      %s (%zu samples)\n", a.recon.c_str(), r.recon_samples);
  std::printf("reference  %s (%zu samples%s)\n", a.reference.c_str(), r.reference_samples,
              o.observers.empty() ? "" : ", observed only");
  std::printf("spacing    %s\n", mm(r.spacing).c_str());
  if (o.sphere)
    std::printf("region     sphere centre %.4f,%.4f,%.4f radius %.4f m\n", o.sphere->centre.x(), o.sphere->centre.y(),
                o.sphere->centre.z(), o.sphere->radius);
  if (o.box)
    std::printf("region     box %.4f,%.4f,%.4f .. %.4f,%.4f,%.4f\n", o.box->min().x(), o.box->min().y(),
                o.box->min().z(), o.box->max().x(), o.box->max().y(), o.box->max().z());
  std::printf("\n%-14s %12s %12s %12s %12s\n", "distance", "mean", "median", "p90", "max");
  for (const auto& [name, s] : {std::pair{"accuracy", r.accuracy}, std::pair{"completeness", r.completeness}})
    std::printf("%-14s %12s %12s %12s %12s\n", name, mm(s.mean).c_str(), mm(s.median).c_str(), mm(s.p90).c_str(),
                mm(s.max).c_str());
  std::printf("\n%-14s %12s %12s %12s\n", "tau", "precision", "recall", "F-score");
  for (const FScore& f : r.scores)
    std::printf("%-14s %12.4f %12.4f %12.4f\n", mm(f.tau).c_str(), f.precision, f.recall, f.fscore);
}

}  // namespace

void add_eval_command(CLI::App& app) {
  auto args = std::make_shared<EvalArgs>();
  CLI::App* cmd = app.add_subcommand("eval", "Accuracy, completeness and F-score of a mesh against a reference mesh");
  cmd->add_option("recon", args->recon, "Reconstructed mesh (PLY)")->required();
  cmd->add_option("reference", args->reference, "Reference mesh (PLY; for a synthetic scene: its reference.ply)")
      ->required();
  cmd->add_option("--tau", args->eval.taus, "F-score threshold in metres (repeatable; default: 1/200 of the size)");
  cmd->add_option("--region", args->region, "Keep samples inside the sphere x,y,z,r");
  cmd->add_option("--box", args->box, "Keep samples inside the box x0,y0,z0,x1,y1,z1");
  cmd->add_option("--scene", args->scene, "synth.json of a synthetic scene (for --close-up, --observed)");
  cmd->add_flag("--close-up", args->close_up, "Region: the scene's close-up sphere (focus, close radius)");
  cmd->add_flag("--observed", args->observed, "Count only reference samples some camera of --scene sees");
  cmd->add_option("--spacing", args->eval.spacing, "Sample spacing in metres (default: 1/1000 of the size)");
  cmd->add_option("--max-samples", args->eval.max_samples, "Most samples per surface")->capture_default_str();
  cmd->add_option("--seed", args->eval.seed, "Sampling seed")->capture_default_str();
  cmd->add_flag("--json", args->json, "Print JSON instead of a table");
  cmd->add_flag("-q,--quiet", args->quiet, "No progress on stderr");
  cmd->callback([args] { run_eval(*args); });
}

}  // namespace sf::cli
