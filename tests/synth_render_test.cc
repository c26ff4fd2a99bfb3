// Ray casting and scene layout, checked against depths worked out by hand.
#include <gtest/gtest.h>

#include <cmath>
#include <numeric>

#include "engine/error.h"
#include "engine/meshio/ply_io.h"
#include "engine/synth/city.h"
#include "engine/synth/mesh_query.h"
#include "engine/synth/shapes.h"
#include "engine/synth/synth.h"
#include "tests/test_util.h"

namespace sf {
namespace {

// A camera at the origin looking along +z (R = I, t = 0).
SynthView axis_view(int w, int h, double f) {
  SynthView v;
  v.name = "test";
  v.width = w;
  v.height = h;
  v.sensor.fx = v.sensor.fy = f;
  v.sensor.cx = 0.5 * w;
  v.sensor.cy = 0.5 * h;
  return v;
}

TEST(SynthRender, PlaneAtZ2HasDepth2Everywhere) {
  const Mesh plane = make_rectangle(-10, 10, -10, 10, 2.0);
  SynthView v = axis_view(64, 48, 50);
  render_view(plane, v);
  EXPECT_EQ(v.valid_pixels, v.size());
  for (float z : v.depth) ASSERT_NEAR(z, 2.0, 1e-6);
  EXPECT_NEAR(v.median_footprint, 2.0 / 50, 1e-9);
  // The plane faces -z: every normal is (0,0,-1), shown as RGB (127.5 * (n + 1)).
  EXPECT_NEAR(v.normal[100].z(), -1.0, 1e-6);
  EXPECT_EQ(v.colour[100], (Rgb8{128, 128, 0}));
}

TEST(SynthRender, PlaneSeenPartly) {
  // The plane covers x >= 0 only: the left half of the image sees nothing (depth 0, black).
  const Mesh plane = make_rectangle(0, 10, -10, 10, 2.0);
  SynthView v = axis_view(64, 48, 50);
  render_view(plane, v);
  EXPECT_EQ(v.valid_pixels, v.size() / 2);
  EXPECT_EQ(v.depth[10 * 64 + 5], 0.f);
  EXPECT_EQ(v.colour[10 * 64 + 5], (Rgb8{0, 0, 0}));
  EXPECT_NEAR(v.depth[10 * 64 + 40], 2.0, 1e-6);
}

TEST(SynthRender, SphereDepthMatchesTheAnalyticIntersection) {
  // Unit sphere at distance 5. Odd size: the centre pixel's ray is the optical axis.
  const double r = 1.0, c = 5.0;
  const Mesh sphere = make_sphere(Eigen::Vector3d(0, 0, c), r, 5);
  SynthView v = axis_view(65, 49, 60);
  render_view(sphere, v);
  const std::size_t centre = 24 * 65 + 32;
  // Tessellation: faces lie inside the sphere by at most r * (1 - cos(edge / 2r)) < 1e-3 here.
  EXPECT_NEAR(v.depth[centre], c - r, 1.5e-3);
  EXPECT_GE(v.depth[centre], c - r - 1e-9);
  std::size_t compared = 0;
  for (int row = 0; row < v.height; ++row)
    for (int col = 0; col < v.width; ++col) {
      const Eigen::Vector3d d = Eigen::Vector3d((col + 0.5 - v.sensor.cx) / 60, (row + 0.5 - v.sensor.cy) / 60, 1).normalized();
      const double b = d.z() * c, disc = b * b - (c * c - r * r);
      const float z = v.depth[std::size_t(row) * v.width + col];
      if (disc < 0.02) continue;  // skip the silhouette, where the tessellation decides
      ASSERT_GT(z, 0) << row << "," << col;
      const double t = b - std::sqrt(disc);
      EXPECT_NEAR(z, t * d.z(), 3e-3) << row << "," << col;
      ++compared;
    }
  EXPECT_GT(compared, 300u);  // the sphere covers ~470 pixels
}

TEST(SynthRender, LookAtConventions) {
  const Sensor s = look_at(Eigen::Vector3d(0, 0, -3), Eigen::Vector3d::Zero(), 100, 80, 60);
  EXPECT_TRUE(s.R.isUnitary(1e-12));
  EXPECT_NEAR(s.R.determinant(), 1.0, 1e-12);
  EXPECT_TRUE(s.centre().isApprox(Eigen::Vector3d(0, 0, -3)));
  Eigen::Vector2d uv;
  ASSERT_TRUE(s.project(Eigen::Vector3d::Zero(), &uv));
  EXPECT_TRUE(uv.isApprox(Eigen::Vector2d(40, 30)));
  ASSERT_TRUE(s.project(Eigen::Vector3d(0, 1, 0), &uv));  // world up is image up (smaller row)
  EXPECT_LT(uv.y(), 30);
  // Looking straight down still gives a valid rotation.
  const Sensor down = look_at(Eigen::Vector3d(0, 5, 0), Eigen::Vector3d::Zero(), 100, 80, 60);
  EXPECT_NEAR(down.R.determinant(), 1.0, 1e-12);
  EXPECT_TRUE(down.axis().isApprox(Eigen::Vector3d(0, -1, 0)));
}

SynthOptions small_options() {
  SynthOptions o;
  o.far_views = 6;
  o.far_width = 80;
  o.far_height = 60;
  o.close_views = 2;
  o.close_width = 160;
  o.close_height = 120;
  return o;
}

TEST(SynthRender, SphereSceneLayout) {
  const Mesh sphere = make_sphere(Eigen::Vector3d(3, 4, 5), 2.0, 4);
  SynthOptions o = small_options();
  const SyntheticScene s = render_scene(sphere, o);
  // Normalized: extent 1.6 -> radius 0.8 about the origin.
  EXPECT_NEAR(s.scale, 0.4, 1e-3);
  EXPECT_TRUE(s.source_centre.isApprox(Eigen::Vector3d(3, 4, 5), 1e-3));
  ASSERT_EQ(s.views.size(), 8u);
  EXPECT_FALSE(s.views[5].close);
  EXPECT_TRUE(s.views[6].close);
  EXPECT_EQ(s.views[6].width, 160);
  for (const auto& v : s.views) EXPECT_GT(v.valid_pixels, v.size() / 10) << v.name;
  // Default focus: the top vertex, normal up.
  EXPECT_NEAR(s.focus.y(), 0.8, 1e-3);
  EXPECT_NEAR(s.focus_normal.y(), 1.0, 1e-2);
  // Calibrated close distance: the ratio is what was asked for.
  EXPECT_NEAR(s.coarse_footprint / s.fine_footprint, o.footprint_ratio, 0.05 * o.footprint_ratio);
  EXPECT_GT(s.close_radius, 0);
  // Every far view sees the whole sphere (no pixel on the border hits it), and the sphere spans
  // about far_fill of the image height.
  const SynthView& far = s.views[0];
  for (int col = 0; col < far.width; ++col) EXPECT_EQ(far.depth[col], 0.f);
  // Each far camera sits at distance 0.8 / (0.9 * sin(atan(30 / 80))) from the centre.
  const double expected = 0.8 / (0.9 * std::sin(std::atan(30.0 / 80.0)));
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(s.views[i].sensor.centre().norm(), expected, 1e-3 * expected);
}

TEST(SynthRender, FocusOptionSnapsToTheSurface) {
  const Mesh sphere = make_sphere(Eigen::Vector3d::Zero(), 1.0, 4);
  SynthOptions o = small_options();
  o.far_views = 2;
  o.close_views = 1;
  o.focus = Eigen::Vector3d(2, 0, 0);
  const SyntheticScene s = render_scene(sphere, o);
  EXPECT_NEAR(s.focus.x(), 0.8, 2e-3);
  EXPECT_NEAR(s.focus_normal.x(), 1.0, 1e-2);
  // A single close view looks straight along the normal.
  EXPECT_TRUE(s.views.back().sensor.axis().isApprox(-s.focus_normal, 1e-9));
}

TEST(SynthRender, NoiseHasTheRequestedSigmaAndIsSeeded) {
  const Mesh sphere = make_sphere(Eigen::Vector3d::Zero(), 1.0, 4);
  SynthOptions o = small_options();
  const SyntheticScene clean = render_scene(sphere, o);
  o.noise = 0.5;
  o.seed = 7;
  const SyntheticScene noisy = render_scene(sphere, o), again = render_scene(sphere, o);
  o.seed = 8;
  const SyntheticScene other = render_scene(sphere, o);
  double sum = 0, sum2 = 0;
  std::size_t n = 0;
  for (std::size_t v = 0; v < clean.views.size(); ++v) {
    const SynthView &c = clean.views[v], &x = noisy.views[v];
    EXPECT_EQ(x.depth, again.views[v].depth);
    EXPECT_NE(x.depth, other.views[v].depth);
    const double f = std::sqrt(c.sensor.fx * c.sensor.fy);
    for (std::size_t i = 0; i < c.size(); ++i) {
      if (!(c.depth[i] > 0)) continue;
      ASSERT_GT(x.depth[i], 0);
      const double e = (x.depth[i] - c.depth[i]) / (c.depth[i] / f);  // in footprints
      sum += e;
      sum2 += e * e;
      ++n;
    }
  }
  ASSERT_GT(n, 10000u);
  const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
  EXPECT_NEAR(mean, 0.0, 0.02);
  EXPECT_NEAR(sd, 0.5, 0.02);
}

TEST(SynthRender, IgeaFootprintRatioIsMultiScale) {
  const Mesh igea = read_ply_mesh(test::shared_data() / "meshes" / "igea.ply");
  SynthOptions o;  // default resolutions and ratio; fewer views to keep the test short
  o.far_views = 8;
  o.close_views = 2;
  const SyntheticScene s = render_scene(igea, o);
  const double ratio = s.coarse_footprint / s.fine_footprint;
  EXPECT_GE(ratio, 8.0);
  EXPECT_LE(ratio, 16.0);
  EXPECT_NEAR(ratio, 14.0, 0.7);
  // The NOTES scene's scale: ~14.5 mm far, ~1 mm close for a 1.6 m object.
  EXPECT_GT(s.coarse_footprint, 0.008);
  EXPECT_LT(s.coarse_footprint, 0.025);
  // The default focus is the top of the head.
  double top = -1e9;
  for (const auto& v : s.reference.vertices) top = std::max(top, double(v.y()));
  EXPECT_NEAR(s.focus.y(), top, 1e-6);
  for (const auto& v : s.views) EXPECT_GT(v.valid_pixels, v.size() / 20) << v.name;
}

TEST(SynthRender, MeshQueryDistances) {
  const Mesh box = make_box(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 2, 3));
  const MeshQuery q(box);
  EXPECT_NEAR(q.squared_distance(Eigen::Vector3d(0.5, 1, -2)), 4.0, 1e-12);
  EXPECT_NEAR(q.squared_distance(Eigen::Vector3d(0.5, 1, 1.5)), 0.25, 1e-12);  // inside: to the nearest side
  const auto hit = q.first_hit(Eigen::Vector3d(0.5, 1, -2), Eigen::Vector3d(0, 0, 2));
  ASSERT_TRUE(hit);
  EXPECT_NEAR(hit->distance, 1.0, 1e-12);  // in units of |direction|
  EXPECT_TRUE(hit->point.isApprox(Eigen::Vector3d(0.5, 1, 0)));
  EXPECT_FALSE(q.first_hit(Eigen::Vector3d(0.5, 1, -2), Eigen::Vector3d(0, 0, -1)));
  const MeshQuery empty{Mesh{}};
  EXPECT_TRUE(empty.empty());
  EXPECT_TRUE(std::isinf(empty.squared_distance(Eigen::Vector3d::Zero())));
}

TEST(SynthRender, OptionsAreChecked) {
  const Mesh sphere = make_sphere(Eigen::Vector3d::Zero(), 1.0, 2);
  auto bad = [&](auto change) {
    SynthOptions o = small_options();
    change(o);
    EXPECT_THROW(render_scene(sphere, o), InputError);
  };
  bad([](SynthOptions& o) { o.size = 0; });
  bad([](SynthOptions& o) { o.far_views = -1; });
  bad([](SynthOptions& o) { o.far_views = 0, o.close_views = 0; });
  bad([](SynthOptions& o) { o.close_width = 2; });
  bad([](SynthOptions& o) { o.noise = -1; });
  bad([](SynthOptions& o) { o.footprint_ratio = 0.5; });
  bad([](SynthOptions& o) { o.focus = Eigen::Vector3d(NAN, 0, 0); });
  EXPECT_THROW(render_scene(Mesh{}, small_options()), InputError);
}

}  // namespace
TEST(SynthCity, BlockLayoutViewsAndFootprints) {
  // Two sphere "statues" (alternating), small images: the layout, not the size, is under test.
  const std::vector<Mesh> props = {make_sphere(Eigen::Vector3d::Zero(), 1.0, 3),
                                   make_box(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 2, 1))};
  CityOptions o;
  o.props = 3;
  o.far_views = 4;
  o.facade_views = 2;
  o.street_views = 6;
  o.width = 120;
  o.height = 90;
  const SyntheticScene scene = render_city(props, o);
  ASSERT_EQ(scene.views.size(), 12u);
  EXPECT_EQ(scene.views[0].name, "far_000");
  EXPECT_EQ(scene.views[4].name, "facade_000");
  EXPECT_EQ(scene.views[6].name, "street_000");
  for (const auto& v : scene.views) {
    EXPECT_GT(v.valid_pixels, v.size() / 10) << v.name;
    EXPECT_EQ(v.close, v.name.rfind("street_", 0) == 0) << v.name;
  }
  // Ground slab (12 triangles), 8 buildings (+ set-backs), 3 plinths, 3 statues.
  EXPECT_GT(scene.reference.faces.size(), 12u + 8 * 12 + 3 * 12 + 2 * 1280);
  // The far views see the block from ~85 m; the street views see their statue from ~3 m.
  EXPECT_GT(scene.coarse_footprint, 40.0 / (o.focal * o.width));
  EXPECT_LT(scene.fine_footprint, 4.0 / (o.focal * o.width));
  // Statue 0 is the close-up: a statue of height 1.2-2 m on a 0.8 m plinth.
  EXPECT_GT(scene.focus.y(), 0.8 + 0.6 - 1e-9);
  EXPECT_LT(scene.focus.y(), 0.8 + 1.0 + 1e-9);
  EXPECT_GT(scene.close_radius, 0.6);
  // Seeded: the same options give the same depths.
  const SyntheticScene again = render_city(props, o);
  EXPECT_TRUE(again.views[7].depth == scene.views[7].depth);
  o.props = 0;
  test::expect_input_error([&] { render_city(props, o); }, "synth --city", "--props");
}

}  // namespace sf
