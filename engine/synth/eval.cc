#include "engine/synth/eval.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>

#include "engine/error.h"
#include "engine/synth/mesh_query.h"

namespace sf {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

struct Region {
  const EvalOptions& o;
  bool contains(const Eigen::Vector3d& p) const {
    if (o.sphere && (p - o.sphere->centre).squaredNorm() > o.sphere->radius * o.sphere->radius) return false;
    if (o.box && !o.box->contains(p)) return false;
    return true;
  }
  // Bounding box of the region (unbounded: everything).
  Eigen::AlignedBox3d bounds() const {
    const double inf = std::numeric_limits<double>::infinity();
    Eigen::AlignedBox3d b(Eigen::Vector3d::Constant(-inf), Eigen::Vector3d::Constant(inf));
    if (o.sphere)
      b = b.intersection(Eigen::AlignedBox3d(o.sphere->centre - Eigen::Vector3d::Constant(o.sphere->radius),
                                             o.sphere->centre + Eigen::Vector3d::Constant(o.sphere->radius)));
    if (o.box) b = b.intersection(*o.box);
    return b;
  }
};

struct Samples {
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector3d> normals;  // unit face normal of the triangle each point lies on
};

// The triangles that may reach into `bounds`, with their cumulative areas.
struct Candidates {
  std::vector<std::uint32_t> faces;
  std::vector<double> cumulative;  // cumulative[i] = area of faces[0..i]
  double area() const { return cumulative.empty() ? 0.0 : cumulative.back(); }
};

Candidates candidates(const Mesh& m, const Eigen::AlignedBox3d& bounds) {
  Candidates c;
  double sum = 0;
  for (std::size_t f = 0; f < m.faces.size(); ++f) {
    const auto& t = m.faces[f];
    const Eigen::Vector3d a = m.vertices[t[0]].cast<double>(), b = m.vertices[t[1]].cast<double>(),
                          d = m.vertices[t[2]].cast<double>();
    Eigen::AlignedBox3d tb(a);
    tb.extend(b);
    tb.extend(d);
    if (!bounds.intersects(tb)) continue;
    const double area = 0.5 * (b - a).cross(d - a).norm();
    if (!(area > 0) || !std::isfinite(area)) continue;
    sum += area;
    c.faces.push_back(std::uint32_t(f));
    c.cumulative.push_back(sum);
  }
  return c;
}

double uniform01(std::mt19937_64& rng) { return double(rng() >> 11) * 0x1.0p-53; }

// n samples, stratified along the cumulative area (sample i falls in [i, i+1) * area / n).
Samples sample(const Mesh& m, const Candidates& c, std::size_t n, std::uint64_t seed) {
  Samples s;
  if (n == 0 || c.faces.empty()) return s;
  s.points.reserve(n);
  s.normals.reserve(n);
  std::mt19937_64 rng(seed);
  const double total = c.area();
  for (std::size_t i = 0; i < n; ++i) {
    const double u = (double(i) + uniform01(rng)) / double(n) * total;
    const std::size_t k = std::min(std::size_t(std::upper_bound(c.cumulative.begin(), c.cumulative.end(), u) -
                                               c.cumulative.begin()),
                                   c.faces.size() - 1);
    const auto& t = m.faces[c.faces[k]];
    const Eigen::Vector3d a = m.vertices[t[0]].cast<double>(), b = m.vertices[t[1]].cast<double>(),
                          d = m.vertices[t[2]].cast<double>();
    const double r1 = std::sqrt(uniform01(rng)), r2 = uniform01(rng);
    s.points.push_back((1 - r1) * a + r1 * (1 - r2) * b + r1 * r2 * d);
    s.normals.push_back((b - a).cross(d - a).normalized());
  }
  return s;
}

// Keeps the samples for which keep[i] is set.
void filter(Samples& s, const std::vector<std::uint8_t>& keep) {
  std::size_t j = 0;
  for (std::size_t i = 0; i < s.points.size(); ++i)
    if (keep[i]) {
      s.points[j] = s.points[i];
      s.normals[j] = s.normals[i];
      ++j;
    }
  s.points.resize(j);
  s.normals.resize(j);
}

std::vector<double> distances(const MeshQuery& to, const std::vector<Eigen::Vector3d>& points) {
  std::vector<double> d(points.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 1024), [&](const auto& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) d[i] = std::sqrt(to.squared_distance(points[i]));
  });
  return d;
}

DistanceStats stats(std::vector<double> d) {
  DistanceStats s;
  s.count = d.size();
  if (d.empty()) {
    s.mean = s.median = s.p90 = s.max = kNaN;
    return s;
  }
  std::sort(d.begin(), d.end());
  double sum = 0;
  for (double v : d) sum += v;
  s.mean = sum / double(d.size());
  auto quantile = [&](double q) { return d[std::size_t(std::floor(q * double(d.size() - 1)))]; };
  s.median = quantile(0.5);
  s.p90 = quantile(0.9);
  s.max = d.back();
  return s;
}

double fraction_below(const std::vector<double>& d, double tau) {
  if (d.empty()) return 0;
  std::size_t n = 0;
  for (double v : d) n += v < tau ? 1 : 0;
  return double(n) / double(d.size());
}

}  // namespace

void EvalOptions::check() const {
  for (double t : taus)
    if (!(t > 0) || !std::isfinite(t)) throw InputError("eval: tau must be > 0 (got " + num(t) + ")");
  if (!(spacing >= 0) || !std::isfinite(spacing)) throw InputError("eval: spacing must be >= 0 (got " + num(spacing) + ")");
  if (max_samples < 1) throw InputError("eval: max_samples must be >= 1");
  if (sphere && (!(sphere->radius > 0) || !sphere->centre.allFinite()))
    throw InputError("eval: region sphere needs a finite centre and a radius > 0 (got radius " + num(sphere->radius) + ")");
  if (box && (box->isEmpty() || !box->min().allFinite() || !box->max().allFinite()))
    throw InputError("eval: region box must have min <= max, finite");
}

EvalResult evaluate(const Mesh& recon, const Mesh& reference, const EvalOptions& o, const ProgressFn& progress) {
  o.check();
  const Region region{o};
  const Eigen::AlignedBox3d bounds = region.bounds();

  Eigen::AlignedBox3d ref_box;
  for (const auto& f : reference.faces)
    for (auto v : f) ref_box.extend(reference.vertices.at(v).cast<double>());
  const Eigen::AlignedBox3d clipped = ref_box.intersection(bounds);
  if (ref_box.isEmpty()) throw InputError("eval: the reference mesh has no faces");
  if (clipped.isEmpty()) throw InputError("eval: the region does not overlap the reference mesh");
  const double D = clipped.sizes().norm();

  EvalResult result;
  const Candidates ref_c = candidates(reference, bounds), rec_c = candidates(recon, bounds);
  if (ref_c.faces.empty()) throw InputError("eval: the reference mesh has no triangle in the region");
  // One spacing for both sides, from the reference; grown if either side needs too many samples.
  double spacing = o.spacing > 0 ? o.spacing : D / 1000.0;
  const double largest = std::max(ref_c.area(), rec_c.area());
  if (largest / (spacing * spacing) > double(o.max_samples)) spacing = std::sqrt(largest / double(o.max_samples));
  result.spacing = spacing;
  auto count = [&](double area) { return area > 0 ? std::max<std::size_t>(1, std::size_t(std::ceil(area / (spacing * spacing)))) : 0; };

  report(progress, "sample", 0, 2);
  Samples ref_s = sample(reference, ref_c, count(ref_c.area()), o.seed);
  Samples rec_s = sample(recon, rec_c, count(rec_c.area()), o.seed ^ 0x5DEECE66Dull);
  {
    std::vector<std::uint8_t> keep(rec_s.points.size());
    for (std::size_t i = 0; i < keep.size(); ++i) keep[i] = region.contains(rec_s.points[i]);
    filter(rec_s, keep);
  }
  const MeshQuery ref_query(reference);
  {
    std::vector<std::uint8_t> keep(ref_s.points.size());
    const double eps = 1e-4 * D;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, keep.size(), 256), [&](const auto& r) {
      for (std::size_t i = r.begin(); i != r.end(); ++i) {
        const Eigen::Vector3d& p = ref_s.points[i];
        if (!region.contains(p)) continue;
        bool seen = o.observers.empty();
        for (std::size_t c = 0; !seen && c < o.observers.size(); ++c) {
          const SceneCamera& cam = o.observers[c];
          Eigen::Vector2d uv;
          if (!cam.sensor.project(p, &uv) || uv.x() < 0 || uv.y() < 0 || uv.x() >= cam.width || uv.y() >= cam.height)
            continue;
          const Eigen::Vector3d C = cam.sensor.centre();
          if (ref_s.normals[i].dot(C - p) <= 0) continue;  // faces away
          const double len = (p - C).norm();
          const auto hit = ref_query.first_hit(C, p - C);  // distance in units of |p - C|
          seen = !hit || hit->distance * len >= len - eps;
        }
        keep[i] = seen;
      }
    });
    filter(ref_s, keep);
  }
  if (ref_s.points.empty()) throw InputError("eval: no reference sample lies in the region (or is observed)");
  result.reference_samples = ref_s.points.size();
  result.recon_samples = rec_s.points.size();
  report(progress, "sample", 2, 2);

  report(progress, "distance", 0, 2);
  const std::vector<double> acc = distances(ref_query, rec_s.points);
  report(progress, "distance", 1, 2);
  std::vector<double> comp;
  {
    const MeshQuery rec_query(recon);
    comp = distances(rec_query, ref_s.points);  // +inf for an empty recon
  }
  report(progress, "distance", 2, 2);

  std::vector<double> taus = o.taus;
  if (taus.empty()) taus.push_back(D / 200.0);
  for (double tau : taus) {
    FScore f;
    f.tau = tau;
    f.precision = fraction_below(acc, tau);
    f.recall = fraction_below(comp, tau);
    f.fscore = f.precision + f.recall > 0 ? 2 * f.precision * f.recall / (f.precision + f.recall) : 0.0;
    result.scores.push_back(f);
  }
  result.accuracy = stats(acc);
  result.completeness = stats(comp);
  return result;
}

}  // namespace sf
