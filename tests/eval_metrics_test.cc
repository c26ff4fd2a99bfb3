// Evaluation metrics on shapes whose distances are known.
#include <gtest/gtest.h>

#include <cmath>

#include "engine/error.h"
#include "engine/synth/eval.h"
#include "engine/synth/shapes.h"
#include "engine/synth/synth.h"

namespace sf {
namespace {

Mesh concat(Mesh a, const Mesh& b) {
  const auto off = std::uint32_t(a.vertices.size());
  a.vertices.insert(a.vertices.end(), b.vertices.begin(), b.vertices.end());
  for (auto f : b.faces) a.faces.push_back({f[0] + off, f[1] + off, f[2] + off});
  return a;
}

TEST(EvalMetrics, SphereAgainstItself) {
  const Mesh s = make_sphere(Eigen::Vector3d(1, 2, 3), 1.0, 4);
  EvalOptions o;
  o.taus = {1e-4};
  o.spacing = 0.01;
  const EvalResult r = evaluate(s, s, o);
  EXPECT_GT(r.recon_samples, 100000u);  // area 12.5 m^2
  EXPECT_EQ(r.recon_samples, r.reference_samples);
  EXPECT_LT(r.accuracy.max, 1e-6);
  EXPECT_LT(r.completeness.max, 1e-6);
  ASSERT_EQ(r.scores.size(), 1u);
  EXPECT_EQ(r.scores[0].precision, 1.0);
  EXPECT_EQ(r.scores[0].recall, 1.0);
  EXPECT_EQ(r.scores[0].fscore, 1.0);
}

TEST(EvalMetrics, ConcentricSpheres) {
  // Recon: radius R + delta around the reference's R. Every distance is delta, up to the
  // tessellation (faces sit inside the sphere by < 0.002 R at 5 subdivisions).
  const double R = 1.0, delta = 0.05;
  const Mesh ref = make_sphere(Eigen::Vector3d::Zero(), R, 5);
  const Mesh rec = make_sphere(Eigen::Vector3d::Zero(), R + delta, 5);
  EvalOptions o;
  o.taus = {0.04, 0.06};
  o.spacing = 0.01;
  const EvalResult r = evaluate(rec, ref, o);
  EXPECT_NEAR(r.spacing, 0.01, 1e-12);
  EXPECT_NEAR(r.accuracy.mean, delta, 0.003);
  EXPECT_NEAR(r.accuracy.median, delta, 0.003);
  EXPECT_NEAR(r.completeness.mean, delta, 0.003);
  EXPECT_LE(r.accuracy.median, r.accuracy.p90);
  EXPECT_LE(r.accuracy.p90, r.accuracy.max);
  // Samples per unit area are the same on both sides: ~ 4 pi r^2 / spacing^2.
  EXPECT_NEAR(double(r.reference_samples), 4 * M_PI * R * R / 1e-4, 0.01 * 4 * M_PI / 1e-4);
  EXPECT_EQ(r.scores[0].precision, 0.0);  // tau < delta
  EXPECT_EQ(r.scores[0].recall, 0.0);
  EXPECT_EQ(r.scores[0].fscore, 0.0);
  EXPECT_EQ(r.scores[1].precision, 1.0);  // tau > delta
  EXPECT_EQ(r.scores[1].recall, 1.0);
  EXPECT_EQ(r.scores[1].fscore, 1.0);
}

TEST(EvalMetrics, RegionRestriction) {
  // Recon: the reference sphere plus a box far away (a phantom). Inside a sphere region around
  // the object the phantom does not count; outside it, nothing of the reference does.
  const Mesh ref = make_sphere(Eigen::Vector3d::Zero(), 1.0, 4);
  const Mesh rec = concat(ref, make_box(Eigen::Vector3d(5, 0, 0), Eigen::Vector3d(6, 1, 1)));
  EvalOptions o;
  o.taus = {0.01};
  o.spacing = 0.02;
  const EvalResult whole = evaluate(rec, ref, o);
  EXPECT_LT(whole.scores[0].precision, 0.7);  // the box has half the sphere's area
  EXPECT_EQ(whole.scores[0].recall, 1.0);
  o.sphere = EvalOptions::Sphere{Eigen::Vector3d::Zero(), 2.0};
  const EvalResult inside = evaluate(rec, ref, o);
  EXPECT_EQ(inside.scores[0].precision, 1.0);
  EXPECT_EQ(inside.recon_samples, inside.reference_samples);  // same surface, same spacing & seed
  // A half-space box: only x > 0 of the sphere, on both sides.
  o.sphere.reset();
  o.box = Eigen::AlignedBox3d(Eigen::Vector3d(0, -2, -2), Eigen::Vector3d(2, 2, 2));
  const EvalResult half = evaluate(rec, ref, o);
  EXPECT_EQ(half.scores[0].precision, 1.0);
  EXPECT_NEAR(double(half.reference_samples), 0.5 * whole.reference_samples, 0.05 * whole.reference_samples);
  // A small region on the surface: the spacing follows the region's size.
  o.box.reset();
  o.sphere = EvalOptions::Sphere{Eigen::Vector3d(0, 1, 0), 0.1};
  o.spacing = 0;
  const EvalResult cap = evaluate(rec, ref, o);
  EXPECT_LT(cap.spacing, 0.001);
  EXPECT_GT(cap.reference_samples, 10000u);
  // A region away from the reference is an input error.
  o.sphere = EvalOptions::Sphere{Eigen::Vector3d(5.5, 0.5, 0.5), 0.2};
  EXPECT_THROW(evaluate(rec, ref, o), InputError);
}

TEST(EvalMetrics, ObservedPartOnly) {
  // One camera in front of the z = 0 side of the unit cube sees exactly that side: 1/6 of the area.
  const Mesh cube = make_box(Eigen::Vector3d::Zero(), Eigen::Vector3d::Ones());
  EvalOptions o;
  o.spacing = 0.01;
  const EvalResult all = evaluate(cube, cube, o);
  SceneCamera cam;
  cam.width = 200;
  cam.height = 200;
  cam.sensor = look_at(Eigen::Vector3d(0.5, 0.5, -3), Eigen::Vector3d(0.5, 0.5, 0.5), 200, 200, 200);
  o.observers = {cam};
  const EvalResult seen = evaluate(cube, cube, o);
  EXPECT_NEAR(double(seen.reference_samples), all.reference_samples / 6.0, 0.02 * all.reference_samples);
  EXPECT_EQ(seen.recon_samples, all.recon_samples);  // the recon side is not filtered
  // A sphere behind a box: occluded samples are not observed.
  const Mesh scene = concat(make_box(Eigen::Vector3d(-2, -2, -0.5), Eigen::Vector3d(2, 2, 0)),
                            make_sphere(Eigen::Vector3d(0, 0, 3), 1.0, 3));
  cam.sensor = look_at(Eigen::Vector3d(0, 0, -5), Eigen::Vector3d(0, 0, 0), 100, 200, 200);
  o.observers = {cam};
  o.spacing = 0.02;
  o.sphere = EvalOptions::Sphere{Eigen::Vector3d(0, 0, 3), 1.5};  // the sphere only
  EXPECT_THROW(evaluate(scene, scene, o), InputError);            // nothing of it is seen
}

TEST(EvalMetrics, EmptyRecon) {
  const Mesh ref = make_sphere(Eigen::Vector3d::Zero(), 1.0, 2);
  EvalOptions o;
  const EvalResult r = evaluate(Mesh{}, ref, o);
  EXPECT_EQ(r.recon_samples, 0u);
  EXPECT_NEAR(r.spacing, std::sqrt(12.0) / 1000, 1e-4);  // default: bounding-box diagonal / 1000
  EXPECT_EQ(r.accuracy.count, 0u);
  EXPECT_TRUE(std::isnan(r.accuracy.mean));
  EXPECT_TRUE(std::isinf(r.completeness.median));
  ASSERT_EQ(r.scores.size(), 1u);  // default tau
  EXPECT_NEAR(r.scores[0].tau, std::sqrt(12.0) / 200, 1e-4);
  EXPECT_EQ(r.scores[0].fscore, 0.0);
}

TEST(EvalMetrics, DeterministicAndCapped) {
  const Mesh ref = make_sphere(Eigen::Vector3d::Zero(), 1.0, 3);
  const Mesh rec = make_sphere(Eigen::Vector3d(0.01, 0, 0), 1.0, 3);
  EvalOptions o;
  o.max_samples = 5000;
  const EvalResult a = evaluate(rec, ref, o), b = evaluate(rec, ref, o);
  EXPECT_EQ(a.accuracy.mean, b.accuracy.mean);
  EXPECT_EQ(a.completeness.p90, b.completeness.p90);
  EXPECT_LE(a.reference_samples, 5001u);
  EXPECT_GT(a.spacing, std::sqrt(12.0) / 1000);
  o.seed = 2;
  EXPECT_NE(evaluate(rec, ref, o).accuracy.mean, a.accuracy.mean);
}

TEST(EvalMetrics, OptionsAreChecked) {
  const Mesh s = make_sphere(Eigen::Vector3d::Zero(), 1.0, 1);
  EvalOptions o;
  o.taus = {-1};
  EXPECT_THROW(evaluate(s, s, o), InputError);
  o.taus.clear();
  o.sphere = EvalOptions::Sphere{Eigen::Vector3d::Zero(), 0};
  EXPECT_THROW(evaluate(s, s, o), InputError);
  o.sphere.reset();
  EXPECT_THROW(evaluate(s, Mesh{}, o), InputError);
}

}  // namespace
}  // namespace sf
