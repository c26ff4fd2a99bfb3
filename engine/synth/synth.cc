#include "engine/synth/synth.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <string>

#include "engine/error.h"
#include "engine/synth/mesh_query.h"

namespace sf {

namespace {

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

void require(bool ok, const std::string& field, const std::string& rule, double value) {
  if (!ok) throw InputError("synth option " + field + " must be " + rule + " (got " + num(value) + ")");
}

// Per-vertex normals: area-weighted sums of the incident face normals.
std::vector<Eigen::Vector3f> vertex_normals(const Mesh& mesh) {
  std::vector<Eigen::Vector3d> acc(mesh.vertices.size(), Eigen::Vector3d::Zero());
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3d a = mesh.vertices[f[0]].cast<double>(), b = mesh.vertices[f[1]].cast<double>(),
                          c = mesh.vertices[f[2]].cast<double>();
    const Eigen::Vector3d n = (b - a).cross(c - a);  // |n| = 2 * area
    for (auto v : f) acc[v] += n;
  }
  std::vector<Eigen::Vector3f> out(acc.size());
  for (std::size_t i = 0; i < acc.size(); ++i) {
    const double len = acc[i].norm();
    out[i] = len > 0 ? Eigen::Vector3f((acc[i] / len).cast<float>()) : Eigen::Vector3f::Zero();
  }
  return out;
}

// Everything the ray caster needs, built once per mesh.
struct Caster {
  const Mesh& mesh;
  MeshQuery query;
  std::vector<Eigen::Vector3f> normals;
  explicit Caster(const Mesh& m) : mesh(m), query(m), normals(vertex_normals(m)) {}
};

std::uint8_t to_byte(double v) { return std::uint8_t(std::clamp(std::lround(v), 0L, 255L)); }

double median(std::vector<float> v) {
  if (v.empty()) return 0;
  const auto mid = v.begin() + std::ptrdiff_t(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

std::vector<float> footprints(const SynthView& view) {
  const double f = std::sqrt(view.sensor.fx * view.sensor.fy);
  std::vector<float> out;
  out.reserve(view.valid_pixels);
  for (float z : view.depth)
    if (z > 0) out.push_back(float(z / f));
  return out;
}

void cast_view(const Caster& caster, SynthView& view) {
  const Sensor& s = view.sensor;
  const std::size_t n = view.size();
  view.depth.assign(n, 0.f);
  view.colour.assign(n, Rgb8{0, 0, 0});
  view.normal.assign(n, Eigen::Vector3f::Zero());
  const Eigen::Vector3d centre = s.centre();
  const Eigen::Matrix3d Rt = s.R.transpose();
  const Mesh& mesh = caster.mesh;
  const bool mesh_colours = !mesh.colours.empty();

  tbb::parallel_for(tbb::blocked_range<int>(0, view.height), [&](const tbb::blocked_range<int>& rows) {
    for (int row = rows.begin(); row != rows.end(); ++row) {
      for (int col = 0; col < view.width; ++col) {
        const Eigen::Vector3d ray_cam((col + 0.5 - s.cx) / s.fx, (row + 0.5 - s.cy) / s.fy, 1.0);
        const auto hit = caster.query.first_hit(centre, Rt * ray_cam);
        if (!hit) continue;
        const double z = (s.R * hit->point + s.t).z();
        if (!(z > 0)) continue;
        const std::size_t i = std::size_t(row) * view.width + col;
        view.depth[i] = float(z);
        // Barycentric coordinates of the hit in its triangle, for smooth normals and colours.
        const auto& f = mesh.faces[hit->face];
        const Eigen::Vector3d a = mesh.vertices[f[0]].cast<double>(), b = mesh.vertices[f[1]].cast<double>(),
                              c = mesh.vertices[f[2]].cast<double>();
        const Eigen::Vector3d e0 = b - a, e1 = c - a, e2 = hit->point - a;
        const double d00 = e0.dot(e0), d01 = e0.dot(e1), d11 = e1.dot(e1), d20 = e2.dot(e0), d21 = e2.dot(e1);
        const double den = d00 * d11 - d01 * d01;
        double wb = den != 0 ? (d11 * d20 - d01 * d21) / den : 1.0 / 3;
        double wc = den != 0 ? (d00 * d21 - d01 * d20) / den : 1.0 / 3;
        wb = std::clamp(wb, 0.0, 1.0);
        wc = std::clamp(wc, 0.0, 1.0 - wb);
        const double wa = 1.0 - wb - wc;
        Eigen::Vector3d nrm = wa * caster.normals[f[0]].cast<double>() + wb * caster.normals[f[1]].cast<double>() +
                              wc * caster.normals[f[2]].cast<double>();
        if (nrm.squaredNorm() == 0) nrm = e0.cross(e1);
        nrm.normalize();
        view.normal[i] = nrm.cast<float>();
        if (mesh_colours) {
          const Rgb8 &ca = mesh.colours[f[0]], &cb = mesh.colours[f[1]], &cc = mesh.colours[f[2]];
          for (int k = 0; k < 3; ++k) view.colour[i][k] = to_byte(wa * ca[k] + wb * cb[k] + wc * cc[k]);
        } else {
          for (int k = 0; k < 3; ++k) view.colour[i][k] = to_byte(127.5 * (nrm[k] + 1.0));
        }
      }
    }
  });
  view.valid_pixels = std::size_t(std::count_if(view.depth.begin(), view.depth.end(), [](float z) { return z > 0; }));
  view.median_footprint = median(footprints(view));
}

// A copy of `view` with every dimension divided by `factor` (for cheap calibration renders).
SynthView downsized(const SynthView& view, int factor) {
  SynthView low = view;
  low.width = std::max(8, view.width / factor);
  low.height = std::max(8, view.height / factor);
  const double sx = double(low.width) / view.width, sy = double(low.height) / view.height;
  low.sensor.fx *= sx;
  low.sensor.cx *= sx;
  low.sensor.fy *= sy;
  low.sensor.cy *= sy;
  return low;
}

// Deterministic per-view seed (splitmix64 of seed and view index).
std::uint64_t view_seed(std::uint64_t seed, std::size_t view) {
  std::uint64_t z = seed + 0x9E3779B97F4A7C15ull * (view + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

std::string view_name(const char* prefix, int i, int digits) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%s_%0*d", prefix, digits, i);
  return buf;
}

}  // namespace

void SynthOptions::check() const {
  require(size > 0 && std::isfinite(size), "size", "> 0", size);
  require(far_views >= 0 && far_views <= 10000, "far_views", "in [0, 10000]", far_views);
  require(close_views >= 0 && close_views <= 10000, "close_views", "in [0, 10000]", close_views);
  require(far_views > 0 || close_views == 0, "far_views", "> 0 when there are close views (they are placed by the far views' footprint)", far_views);
  require(far_views + close_views > 0, "far_views + close_views", "> 0", far_views + close_views);
  require(far_width >= 8 && far_width <= 16384, "far_width", "in [8, 16384]", far_width);
  require(far_height >= 8 && far_height <= 16384, "far_height", "in [8, 16384]", far_height);
  require(close_width >= 8 && close_width <= 16384, "close_width", "in [8, 16384]", close_width);
  require(close_height >= 8 && close_height <= 16384, "close_height", "in [8, 16384]", close_height);
  require(far_fill > 0 && far_fill <= 1, "far_fill", "in (0, 1]", far_fill);
  require(footprint_ratio >= 1 && footprint_ratio <= 1000, "footprint_ratio", "in [1, 1000]", footprint_ratio);
  require(close_tilt_deg >= 0 && close_tilt_deg <= 80, "close_tilt_deg", "in [0, 80]", close_tilt_deg);
  require(focal > 0.05 && focal < 100, "focal", "in (0.05, 100) image widths", focal);
  require(noise >= 0 && noise <= 100, "noise", "in [0, 100] footprints", noise);
  if (focus) require(focus->allFinite(), "focus", "finite", focus->norm());
}

Sensor look_at(const Eigen::Vector3d& centre, const Eigen::Vector3d& target, double focal_px, int width, int height,
               const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - centre).normalized();
  Eigen::Vector3d down = -up.normalized();
  if (std::abs(z.dot(down)) > 0.99) down = Eigen::Vector3d::UnitZ();  // looking along up: any roll will do
  const Eigen::Vector3d x = down.cross(z).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Sensor s;
  s.kind = Sensor::Kind::Perspective;
  s.R.row(0) = x.transpose();
  s.R.row(1) = y.transpose();
  s.R.row(2) = z.transpose();
  s.t = -s.R * centre;
  s.fx = s.fy = focal_px;
  s.cx = 0.5 * width;
  s.cy = 0.5 * height;
  return s;
}

void render_view(const Mesh& mesh, SynthView& view) {
  const Caster caster(mesh);
  cast_view(caster, view);
}

SyntheticScene render_scene(const Mesh& mesh, const SynthOptions& o, const ProgressFn& progress) {
  o.check();
  SyntheticScene scene;
  scene.options = o;

  // Normalization, over the vertices that faces use.
  std::vector<std::uint8_t> used(mesh.vertices.size(), 0);
  for (const auto& f : mesh.faces)
    for (auto v : f) used.at(v) = 1;
  Eigen::AlignedBox3d box;
  for (std::size_t i = 0; i < used.size(); ++i)
    if (used[i]) box.extend(mesh.vertices[i].cast<double>());
  if (box.isEmpty()) throw InputError("synth: the mesh has no faces");
  const double measure =
      o.size_measure == SynthOptions::SizeMeasure::Extent ? box.sizes().maxCoeff() : box.sizes().norm();
  if (!(measure > 0) || !std::isfinite(measure)) throw InputError("synth: the mesh is degenerate (zero size)");
  scene.scale = o.size / measure;
  scene.source_centre = box.center();
  Mesh& ref = scene.reference;
  ref.vertices.reserve(mesh.vertices.size());
  for (const auto& v : mesh.vertices)
    ref.vertices.push_back((scene.scale * (v.cast<double>() - scene.source_centre)).cast<float>());
  ref.faces = mesh.faces;
  ref.colours = mesh.colours;

  const Caster caster(ref);
  if (caster.query.empty()) throw InputError("synth: the mesh has only degenerate triangles");
  double bound = 0;  // bounding sphere about the origin
  for (std::size_t i = 0; i < used.size(); ++i)
    if (used[i]) bound = std::max(bound, double(ref.vertices[i].norm()));

  const int total = o.far_views + o.close_views;
  int done = 0;
  auto render = [&](SynthView& view) {
    cast_view(caster, view);
    if (view.valid_pixels == 0)
      throw InputError("synth: view " + view.name + " sees no surface (check the focus and the view options)");
    report(progress, "render", ++done, total);
  };

  // Far views.
  {
    const double f_nominal = o.focal * o.far_width;
    const double half_fov = std::atan(0.5 * std::min(o.far_width, o.far_height) / f_nominal);
    const double distance = bound / (o.far_fill * std::sin(half_fov));
    const int w = o.uniform_resolution ? o.close_width : o.far_width;
    const int h = o.uniform_resolution ? o.close_height : o.far_height;
    const double f = o.focal * w;
    const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
    std::vector<float> fp;
    for (int i = 0; i < o.far_views; ++i) {
      const double y = 1.0 - 2.0 * (i + 0.5) / o.far_views;
      const double r = std::sqrt(std::max(0.0, 1.0 - y * y));
      const Eigen::Vector3d dir(r * std::cos(golden * i), y, r * std::sin(golden * i));
      SynthView view;
      view.name = view_name("far", i, 3);
      view.width = o.far_width;
      view.height = o.far_height;
      view.sensor = look_at(distance * dir, Eigen::Vector3d::Zero(), f_nominal, o.far_width, o.far_height);
      if (o.uniform_resolution) {
        // Same footprint with a k times longer focal length: move back along the axis until the
        // median depth is k times the nominal one (measured on a half-resolution render).
        SynthView nominal = downsized(view, 2);
        cast_view(caster, nominal);
        const double k = f / f_nominal;
        const double z_med = nominal.median_footprint * std::sqrt(nominal.sensor.fx * nominal.sensor.fy);
        const double back = z_med > 0 ? (k - 1) * z_med : (k - 1) * distance;
        view.width = w;
        view.height = h;
        view.sensor = look_at((distance + back) * dir, Eigen::Vector3d::Zero(), f, w, h);
      }
      render(view);
      const auto v = footprints(view);
      fp.insert(fp.end(), v.begin(), v.end());
      scene.views.push_back(std::move(view));
    }
    scene.coarse_footprint = median(std::move(fp));
  }

  // Focus and its normal.
  if (o.focus) {
    scene.focus = caster.query.closest(*o.focus)->point;
  } else {
    std::size_t best = 0;
    bool any = false;
    for (std::size_t i = 0; i < used.size(); ++i)
      if (used[i] && (!any || ref.vertices[i].y() > ref.vertices[best].y())) best = i, any = true;
    scene.focus = ref.vertices[best].cast<double>();
  }
  {
    // Average over a patch about half the size the close views will cover (at least 2% of the
    // object), so that the close views face the region rather than one triangle.
    const double rho = std::max(0.02 * o.size, 0.25 * std::min(o.close_width, o.close_height) *
                                                   scene.coarse_footprint / o.footprint_ratio);
    Eigen::Vector3d n = Eigen::Vector3d::Zero();
    for (const auto& f : ref.faces) {
      const Eigen::Vector3d a = ref.vertices[f[0]].cast<double>(), b = ref.vertices[f[1]].cast<double>(),
                            c = ref.vertices[f[2]].cast<double>();
      if (((a + b + c) / 3 - scene.focus).norm() <= rho) n += (b - a).cross(c - a);
    }
    if (n.norm() == 0) {
      const auto& f = ref.faces[caster.query.closest(scene.focus)->face];
      n = (ref.vertices[f[1]] - ref.vertices[f[0]]).cast<double>().cross((ref.vertices[f[2]] - ref.vertices[f[0]]).cast<double>());
    }
    scene.focus_normal = n.normalized();
  }

  // Close views.
  if (o.close_views > 0) {
    const Eigen::Vector3d& n = scene.focus_normal;
    const Eigen::Vector3d a = (std::abs(n.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitZ()).cross(n).normalized();
    const Eigen::Vector3d b = n.cross(a);
    const double tilt = o.close_tilt_deg * std::numbers::pi / 180.0;
    std::vector<Eigen::Vector3d> dirs;
    for (int k = 0; k < o.close_views; ++k) {
      if (o.close_views == 1) {
        dirs.push_back(n);
        break;
      }
      const double phi = 2.0 * std::numbers::pi * k / o.close_views;
      dirs.push_back(std::cos(tilt) * n + std::sin(tilt) * (std::cos(phi) * a + std::sin(phi) * b));
    }
    const double f = o.focal * o.close_width;
    const double target = scene.coarse_footprint / o.footprint_ratio;
    auto make = [&](int k, double distance) {
      SynthView view;
      view.name = view_name("close", k, 2);
      view.close = true;
      view.width = o.close_width;
      view.height = o.close_height;
      view.sensor = look_at(scene.focus + distance * dirs[k], scene.focus, f, o.close_width, o.close_height);
      return view;
    };
    // Calibrate the distance on 1/8-resolution renders: the median footprint of the close views
    // scales (nearly) with their distance to the focus.
    double distance = target * f;
    for (int iter = 0; iter < 4; ++iter) {
      std::vector<float> fp;
      for (int k = 0; k < o.close_views; ++k) {
        SynthView low = downsized(make(k, distance), 8);
        cast_view(caster, low);
        for (float z : low.depth)
          if (z > 0) fp.push_back(float(z / f));
      }
      if (fp.empty()) throw InputError("synth: the close views see no surface (check the focus)");
      const double ratio = target / median(std::move(fp));
      distance *= ratio;
      if (std::abs(ratio - 1) < 0.005) break;
    }
    // Full resolution; the median can differ a little from the low-resolution one (thin parts,
    // silhouettes), so one more placement if it is off by more than 2%.
    std::vector<SynthView> close;
    for (int pass = 0; pass < 2; ++pass) {
      close.clear();
      std::vector<float> fp;
      for (int k = 0; k < o.close_views; ++k) {
        SynthView view = make(k, distance);
        if (pass == 0) {
          render(view);
        } else {
          cast_view(caster, view);
          report(progress, "render (close views placed again)", k + 1, o.close_views);
        }
        const auto v = footprints(view);
        fp.insert(fp.end(), v.begin(), v.end());
        close.push_back(std::move(view));
      }
      scene.fine_footprint = median(std::move(fp));
      const double ratio = target / scene.fine_footprint;
      if (std::abs(ratio - 1) <= 0.02) break;
      distance *= ratio;
    }
    double radius = std::numeric_limits<double>::infinity();
    for (SynthView& view : close) {
      if (view.valid_pixels == 0) throw InputError("synth: view " + view.name + " sees no surface (check the focus)");
      const double z_focus = (view.sensor.R * scene.focus + view.sensor.t).z();
      radius = std::min(radius, 0.8 * 0.5 * std::min(view.width, view.height) * z_focus / f);
      scene.views.push_back(std::move(view));
    }
    scene.close_radius = radius;
  }

  // Noise, after the footprints were measured on the exact depths.
  add_depth_noise(scene.views, o.noise, o.seed);
  return scene;
}

void render_views(const Mesh& mesh, std::vector<SynthView>& views, const ProgressFn& progress) {
  const Caster caster(mesh);
  if (caster.query.empty()) throw InputError("synth: the mesh has only degenerate triangles");
  for (std::size_t i = 0; i < views.size(); ++i) {
    cast_view(caster, views[i]);
    report(progress, "render", double(i + 1), double(views.size()));
  }
}

void add_depth_noise(std::vector<SynthView>& views, double noise, std::uint64_t seed) {
  if (!(noise > 0)) return;
  for (std::size_t v = 0; v < views.size(); ++v) {
    SynthView& view = views[v];
    std::mt19937_64 rng(view_seed(seed, v));
    std::normal_distribution<double> gauss(0.0, 1.0);
    const double sigma_per_z = noise / std::sqrt(view.sensor.fx * view.sensor.fy);
    for (float& z : view.depth) {
      if (!(z > 0)) continue;
      const double noisy = z * (1.0 + sigma_per_z * gauss(rng));
      if (noisy > 0) z = float(noisy);
    }
  }
}

}  // namespace sf
