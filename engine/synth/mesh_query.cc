#include "engine/synth/mesh_query.h"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>

#include <cmath>
#include <limits>
#include <mutex>
#include <utility>
#include <vector>

namespace sf {

namespace {
// Inexact double arithmetic is what a renderer and a distance metric want: the filtered exact
// kernels cost several times more per ray and buy nothing at pixel resolution.
using Kernel = CGAL::Simple_cartesian<double>;
using Point = Kernel::Point_3;
using Triangle = Kernel::Triangle_3;
using Iterator = std::vector<Triangle>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<Kernel, Iterator>;
using Traits = CGAL::AABB_traits<Kernel, Primitive>;
using Tree = CGAL::AABB_tree<Traits>;

Point to_point(const Eigen::Vector3d& p) { return Point(p.x(), p.y(), p.z()); }
Eigen::Vector3d to_eigen(const Point& p) { return {p.x(), p.y(), p.z()}; }
}  // namespace

struct MeshQuery::Impl {
  std::vector<Triangle> triangles;
  std::vector<std::uint32_t> face_of;  // triangles[i] is mesh.faces[face_of[i]]
  Tree tree;
  std::once_flag distance_accelerator;  // built by the first distance query (rendering needs none)

  const Tree& distance_tree() {
    std::call_once(distance_accelerator, [this] { tree.accelerate_distance_queries(); });
    return tree;
  }
};

MeshQuery::MeshQuery(const Mesh& mesh) : impl_(std::make_unique<Impl>()) {
  impl_->triangles.reserve(mesh.faces.size());
  impl_->face_of.reserve(mesh.faces.size());
  for (std::size_t f = 0; f < mesh.faces.size(); ++f) {
    const auto& v = mesh.faces[f];
    const Eigen::Vector3d a = mesh.vertices[v[0]].cast<double>(), b = mesh.vertices[v[1]].cast<double>(),
                          c = mesh.vertices[v[2]].cast<double>();
    if ((b - a).cross(c - a).squaredNorm() == 0) continue;
    impl_->triangles.emplace_back(to_point(a), to_point(b), to_point(c));
    impl_->face_of.push_back(std::uint32_t(f));
  }
  if (impl_->triangles.empty()) return;
  impl_->tree.insert(impl_->triangles.cbegin(), impl_->triangles.cend());
  impl_->tree.build();
}

MeshQuery::~MeshQuery() = default;

bool MeshQuery::empty() const { return impl_->triangles.empty(); }

namespace {

// Nearest hit along a ray, as traits for AABB_tree::traversal_with_priority (the hook CGAL's own
// Polygon_mesh_processing distance code uses): children are visited nearest box first, and a box is
// entered only if the ray reaches it before the best hit so far. This replaces
// AABB_tree::first_intersection, which builds a heap and a Point/Segment variant per candidate and
// measured ~4x slower per ray on igea.ply. Triangles: Moller-Trumbore in doubles; rays lying in a
// triangle's plane do not hit it (its neighbours catch them).
struct Ray {
  double o[3], d[3];
};

class FirstHitTraits {
 public:
  using Priority = double;
  FirstHitTraits() = default;

  bool go_further() const { return true; }  // pruning happens per box, against best_

  template <typename Primitive>
  void intersection(const Ray& r, const Primitive& p) {
    const Triangle& tri = *p.id();
    const Point &a = tri[0], &b = tri[1], &c = tri[2];
    const double e1[3] = {b.x() - a.x(), b.y() - a.y(), b.z() - a.z()};
    const double e2[3] = {c.x() - a.x(), c.y() - a.y(), c.z() - a.z()};
    const double pv[3] = {r.d[1] * e2[2] - r.d[2] * e2[1], r.d[2] * e2[0] - r.d[0] * e2[2], r.d[0] * e2[1] - r.d[1] * e2[0]};
    const double det = e1[0] * pv[0] + e1[1] * pv[1] + e1[2] * pv[2];
    if (det == 0 || !std::isfinite(det)) return;
    const double inv = 1.0 / det;
    const double tv[3] = {r.o[0] - a.x(), r.o[1] - a.y(), r.o[2] - a.z()};
    const double u = (tv[0] * pv[0] + tv[1] * pv[1] + tv[2] * pv[2]) * inv;
    if (u < 0 || u > 1) return;
    const double qv[3] = {tv[1] * e1[2] - tv[2] * e1[1], tv[2] * e1[0] - tv[0] * e1[2], tv[0] * e1[1] - tv[1] * e1[0]};
    const double v = (r.d[0] * qv[0] + r.d[1] * qv[1] + r.d[2] * qv[2]) * inv;
    if (v < 0 || u + v > 1) return;
    const double t = (e2[0] * qv[0] + e2[1] * qv[1] + e2[2] * qv[2]) * inv;
    if (t > 0 && t < best_) {
      best_ = t;
      hit_ = p.id();
      found_ = true;
    }
  }

  template <typename Node>
  bool do_intersect(const Ray& r, const Node& node) const {
    return do_intersect_with_priority(r, node).first;
  }

  // Entry parameter of the ray into the node's box (priority: nearer first).
  template <typename Node>
  std::pair<bool, Priority> do_intersect_with_priority(const Ray& r, const Node& node) const {
    const CGAL::Bbox_3& b = node.bbox();
    double t0 = 0, t1 = best_;
    for (int k = 0; k < 3; ++k) {
      const double lo = b.min_coord(k), hi = b.max_coord(k);
      if (r.d[k] == 0) {
        if (r.o[k] < lo || r.o[k] > hi) return {false, 0};
        continue;
      }
      const double inv = 1.0 / r.d[k];
      double ta = (lo - r.o[k]) * inv, tb = (hi - r.o[k]) * inv;
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
      if (t0 > t1) return {false, 0};
    }
    return {true, -t0};
  }

  bool found() const { return found_; }
  double best() const { return best_; }
  Iterator hit() const { return hit_; }

 private:
  double best_ = std::numeric_limits<double>::infinity();
  Iterator hit_{};
  bool found_ = false;
};

}  // namespace

std::optional<MeshQuery::Hit> MeshQuery::first_hit(const Eigen::Vector3d& origin,
                                                   const Eigen::Vector3d& direction) const {
  if (empty()) return std::nullopt;
  const Ray ray{{origin.x(), origin.y(), origin.z()}, {direction.x(), direction.y(), direction.z()}};
  FirstHitTraits traits;
  impl_->tree.traversal_with_priority(ray, traits);
  if (!traits.found()) return std::nullopt;
  Hit h;
  h.distance = traits.best();
  h.face = impl_->face_of[std::size_t(traits.hit() - impl_->triangles.cbegin())];
  h.point = origin + h.distance * direction;
  return h;
}

std::optional<MeshQuery::Closest> MeshQuery::closest(const Eigen::Vector3d& p) const {
  if (empty()) return std::nullopt;
  const auto [point, id] = impl_->distance_tree().closest_point_and_primitive(to_point(p));
  Closest c;
  c.point = to_eigen(point);
  c.face = impl_->face_of[std::size_t(id - impl_->triangles.cbegin())];
  c.squared_distance = (c.point - p).squaredNorm();
  return c;
}

double MeshQuery::squared_distance(const Eigen::Vector3d& p) const {
  if (empty()) return std::numeric_limits<double>::infinity();
  return impl_->distance_tree().squared_distance(to_point(p));
}

}  // namespace sf
