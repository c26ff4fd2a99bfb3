#pragma once
// Comparing a reconstructed mesh with a reference mesh (as Tanks and Temples does with points).
//
// Both surfaces are sampled uniformly by area at the same spacing (stratified, seeded, so the
// result is reproducible). Then
//   accuracy      distances from recon samples to the reference surface,
//   completeness  distances from reference samples to the recon surface,
//   precision(τ)  fraction of recon samples with accuracy distance < τ,
//   recall(τ)     fraction of reference samples with completeness distance < τ,
//   F(τ)          2 P R / (P + R), 0 when P + R = 0.
// A region (sphere and/or box) keeps only the samples inside it, on both sides; the distances are
// still measured to the whole other surface. Observers (cameras) keep only the reference samples
// that at least one of them sees (in its image, facing it, not occluded by the reference): the
// completeness of what the input could show.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <optional>
#include <vector>

#include "engine/mesh.h"
#include "engine/progress.h"
#include "engine/synth/scene_writer.h"

namespace sf {

struct EvalOptions {
  std::vector<double> taus;   // F-score thresholds, metres; empty: one, at D / 200 (D below)
  // Sample spacing, metres; 0: D / 1000, where D is the diagonal of the reference's bounding box
  // clipped to the region. The spacing grows when a surface would need more than max_samples.
  double spacing = 0;
  std::size_t max_samples = 4'000'000;  // per surface
  std::uint64_t seed = 1;

  struct Sphere {
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    double radius = 0;
  };
  std::optional<Sphere> sphere;
  std::optional<Eigen::AlignedBox3d> box;
  std::vector<SceneCamera> observers;  // empty: every reference sample counts

  void check() const;  // throws InputError
};

struct DistanceStats {  // metres; NaN when count == 0
  std::size_t count = 0;
  double mean = 0, median = 0, p90 = 0, max = 0;
};

struct FScore {
  double tau = 0, precision = 0, recall = 0, fscore = 0;
};

struct EvalResult {
  double spacing = 0;                 // the spacing actually used
  std::size_t recon_samples = 0;      // samples kept (inside the region)
  std::size_t reference_samples = 0;  // samples kept (inside the region, observed)
  DistanceStats accuracy, completeness;
  std::vector<FScore> scores;         // one per tau
};

// Throws InputError if the reference has no triangle (or none in the region). An empty recon gives
// accuracy count 0, completeness +inf and all scores 0. Distances are computed with
// tbb::parallel_for in the caller's task arena; the result does not depend on the thread count.
// Progress stages: "sample", "distance".
EvalResult evaluate(const Mesh& recon, const Mesh& reference, const EvalOptions& options,
                    const ProgressFn& progress = {});

}  // namespace sf
