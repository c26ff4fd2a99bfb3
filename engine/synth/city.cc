#include "engine/synth/city.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <string>

#include "engine/error.h"
#include "engine/synth/shapes.h"

namespace sf {

namespace {

constexpr double kPi = std::numbers::pi;

// The block's fixed dimensions, metres.
constexpr double kGroundHalfX = 45, kGroundHalfZ = 30;
constexpr double kFrontZ = -15;                // the street front of the buildings
constexpr double kBackZ = -25;
constexpr double kStreetHalfX = 40;            // buildings and statues span x in [-40, 40]
constexpr double kPlinthHeight = 0.8, kPlinthHalf = 0.6;
constexpr double kRowZ[2] = {-9.0, 3.0};       // the two rows of statues

void append(Mesh& into, const Mesh& part) {
  const auto base = std::uint32_t(into.vertices.size());
  into.vertices.insert(into.vertices.end(), part.vertices.begin(), part.vertices.end());
  for (const auto& f : part.faces) into.faces.push_back({f[0] + base, f[1] + base, f[2] + base});
}

// `mesh` scaled so that its bounding box is `height` tall, turned by `turn` about y, and placed
// with its bounding box's bottom centre at `base`.
Mesh placed(const Mesh& mesh, double height, double turn, const Eigen::Vector3d& base) {
  Eigen::AlignedBox3d box;
  std::vector<std::uint8_t> used(mesh.vertices.size(), 0);
  for (const auto& f : mesh.faces)
    for (auto v : f) used.at(v) = 1;
  for (std::size_t i = 0; i < used.size(); ++i)
    if (used[i]) box.extend(mesh.vertices[i].cast<double>());
  if (box.isEmpty() || !(box.sizes().y() > 0)) throw InputError("synth --city: a statue mesh has no height");
  const double s = height / box.sizes().y();
  const Eigen::Vector3d foot(box.center().x(), box.min().y(), box.center().z());
  const Eigen::Matrix3d R = Eigen::AngleAxisd(turn, Eigen::Vector3d::UnitY()).toRotationMatrix();
  Mesh out;
  out.faces = mesh.faces;
  out.vertices.reserve(mesh.vertices.size());
  for (const auto& v : mesh.vertices) out.vertices.push_back((base + R * (s * (v.cast<double>() - foot))).cast<float>());
  return out;
}

struct Statue {
  Eigen::Vector3d base;  // bottom centre, on the plinth
  double height = 0;
  double radius = 0;     // of its bounding sphere about the centre
  Eigen::Vector3d centre() const { return base + Eigen::Vector3d(0, 0.5 * height, 0); }
};

std::string numbered(const char* prefix, int i) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%s_%03d", prefix, i);
  return buf;
}

}  // namespace

void CityOptions::check() const {
  auto bad = [](const std::string& what) { throw InputError("synth --city: " + what); };
  if (props < 1 || props > 200) bad("--props must be in 1..200");
  if (far_views < 0 || facade_views < 0 || street_views < 0) bad("view counts must be >= 0");
  if (far_views + facade_views + street_views < 1) bad("no views");
  if (width < 8 || height < 8 || width > 20000 || height > 20000) bad("view size must be 8..20000 pixels per side");
  if (!(focal > 0.05 && focal < 20)) bad("--focal must be in (0.05, 20) image widths");
  if (!(street_distance >= 1.5 && street_distance <= 20)) bad("--street-distance must be in [1.5, 20] m");
  if (!(far_distance >= 50 && far_distance <= 1000)) bad("--far-distance must be in [50, 1000] m");
  if (!(noise >= 0 && noise <= 10)) bad("--noise must be in [0, 10] footprints");
}

SyntheticScene render_city(const std::vector<Mesh>& props, const CityOptions& o, const ProgressFn& progress) {
  o.check();
  if (props.empty()) throw InputError("synth --city: give at least one statue mesh");
  std::mt19937_64 rng(o.seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);

  SyntheticScene scene;
  Mesh& city = scene.reference;
  append(city, make_box({-kGroundHalfX, -0.5, -kGroundHalfZ}, {kGroundHalfX, 0.0, kGroundHalfZ}));
  // The street front: eight buildings of different heights, with set-back upper floors on some.
  for (int b = 0; b < 8; ++b) {
    const double x0 = -kStreetHalfX + 10.0 * b, x1 = x0 + 10.0 - 0.2;
    const double h = 12.0 + 10.0 * unit(rng);
    const double front = kFrontZ - 1.5 * unit(rng);
    append(city, make_box({x0, 0.0, kBackZ}, {x1, h, front}));
    if (b % 3 == 1) append(city, make_box({x0 + 2.0, h, kBackZ + 1.0}, {x1 - 2.0, h + 4.0, front - 2.0}));
  }
  // Statues on plinths, two rows across the plaza.
  std::vector<Statue> statues;
  const int per_row = (o.props + 1) / 2;
  for (int k = 0; k < o.props; ++k) {
    const int row = k % 2, slot = k / 2;
    const int in_row = row == 0 ? per_row : o.props - per_row;
    const double x = in_row > 1 ? -32.0 + 64.0 * slot / (in_row - 1) : 0.0;
    const Eigen::Vector3d plinth(x, 0.0, kRowZ[row]);
    append(city, make_box(plinth + Eigen::Vector3d(-kPlinthHalf, 0, -kPlinthHalf),
                          plinth + Eigen::Vector3d(kPlinthHalf, kPlinthHeight, kPlinthHalf)));
    const Mesh& source = props[std::size_t(k) % props.size()];
    Statue s;
    s.height = 1.2 + 0.8 * unit(rng);
    s.base = plinth + Eigen::Vector3d(0, kPlinthHeight, 0);
    const Mesh statue = placed(source, s.height, 2.0 * kPi * unit(rng), s.base);
    for (const auto& v : statue.vertices) s.radius = std::max(s.radius, (v.cast<double>() - s.centre()).norm());
    append(city, statue);
    statues.push_back(s);
  }

  std::vector<SynthView> views;
  const double f = o.focal * o.width;
  auto add_view = [&](const char* kind, int i, bool close, const Eigen::Vector3d& eye, const Eigen::Vector3d& at) {
    SynthView v;
    v.name = numbered(kind, i);
    v.close = close;
    v.width = o.width;
    v.height = o.height;
    v.sensor = look_at(eye, at, f, o.width, o.height);
    views.push_back(std::move(v));
  };
  // Far: a ring around the block, 25-45 m up, looking at its middle.
  const Eigen::Vector3d middle(0.0, 6.0, -6.0);
  for (int i = 0; i < o.far_views; ++i) {
    const double a = 2.0 * kPi * (i + 0.5 * unit(rng)) / std::max(1, o.far_views);
    const double up = 25.0 + 20.0 * unit(rng);
    const double r = std::sqrt(std::max(1.0, o.far_distance * o.far_distance - up * up));
    add_view("far", i, false, middle + Eigen::Vector3d(r * std::sin(a), up, r * std::cos(a)), middle);
  }
  // Facade: from the plaza's far side, at 2-10 m, looking at points along the street front.
  for (int i = 0; i < o.facade_views; ++i) {
    const double x = -30.0 + 60.0 * (i + 0.5) / std::max(1, o.facade_views);
    const Eigen::Vector3d eye(x + 6.0 * (unit(rng) - 0.5), 2.0 + 8.0 * unit(rng), kFrontZ + 25.0);
    add_view("facade", i, false, eye, Eigen::Vector3d(x, 8.0, kFrontZ));
  }
  // Street: each statue from eye height, on an arc facing the plaza (+z), 150 degrees wide; a
  // statue's views are consecutive, as a photographer walking round it takes them.
  std::vector<std::size_t> statue_of_view(views.size(), statues.size());  // statues.size(): not a street view
  for (int k = 0, i = 0; k < o.props; ++k) {
    const int per = o.street_views / o.props + (k < o.street_views % o.props ? 1 : 0);
    const Statue& s = statues[std::size_t(k)];
    for (int j = 0; j < per; ++j, ++i) {
      const double a = (-75.0 + 150.0 * (j + 0.5) / per) * kPi / 180.0;
      const double d = o.street_distance * (0.9 + 0.2 * unit(rng));
      const Eigen::Vector3d eye =
          s.base + Eigen::Vector3d(d * std::sin(a), 1.6 - kPlinthHeight + 0.4 * unit(rng), d * std::cos(a));
      add_view("street", i, true, Eigen::Vector3d(eye.x(), std::max(eye.y(), 1.2), eye.z()), s.centre());
      statue_of_view.push_back(std::size_t(k));
    }
  }
  render_views(city, views, progress);
  for (const SynthView& v : views)
    if (v.valid_pixels == 0) throw InputError("synth --city: view " + v.name + " sees no surface");
  // Footprints: the far views' median, and the street views' median over the pixels on or about
  // their statue (depth within its bounding sphere), not the street front behind it.
  std::vector<double> far_fp, street_fp;
  for (std::size_t i = 0; i < views.size(); ++i) {
    const SynthView& v = views[i];
    const double fv = std::sqrt(v.sensor.fx * v.sensor.fy);
    if (v.name.rfind("far_", 0) == 0) far_fp.push_back(v.median_footprint);
    if (statue_of_view[i] == statues.size()) continue;
    const Statue& s = statues[statue_of_view[i]];
    const double z_max = (v.sensor.R * s.centre() + v.sensor.t).z() + s.radius;
    for (std::size_t p = 0; p < v.depth.size(); p += 7)  // a 1/7 subsample is plenty for a median
      if (v.depth[p] > 0 && v.depth[p] <= z_max) street_fp.push_back(v.depth[p] / fv);
  }
  auto median = [](std::vector<double> m) {
    if (m.empty()) return 0.0;
    std::nth_element(m.begin(), m.begin() + std::ptrdiff_t(m.size() / 2), m.end());
    return m[m.size() / 2];
  };
  scene.coarse_footprint = median(std::move(far_fp));
  scene.fine_footprint = median(std::move(street_fp));
  add_depth_noise(views, o.noise, o.seed);
  scene.views = std::move(views);

  // What scene_writer records of the options, in the single-object vocabulary.
  SynthOptions& so = scene.options;
  so.size = 2.0 * kGroundHalfX;
  so.far_views = o.far_views + o.facade_views;
  so.far_width = so.close_width = o.width;
  so.far_height = so.close_height = o.height;
  so.close_views = o.street_views;
  so.focal = o.focal;
  so.uniform_resolution = true;
  so.noise = o.noise;
  so.seed = o.seed;
  so.footprint_ratio = scene.fine_footprint > 0 ? scene.coarse_footprint / scene.fine_footprint : 0.0;
  scene.focus = statues.front().centre();
  scene.focus_normal = Eigen::Vector3d::UnitZ();
  scene.close_radius = statues.front().radius;
  return scene;
}

}  // namespace sf
