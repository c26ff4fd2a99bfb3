#include "engine/synth/mesh_query.h"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>

#include <limits>
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
Point to_point(const Eigen::Vector3f& p) { return Point(p.x(), p.y(), p.z()); }
Eigen::Vector3d to_eigen(const Point& p) { return {p.x(), p.y(), p.z()}; }
}  // namespace

struct MeshQuery::Impl {
  std::vector<Triangle> triangles;
  std::vector<std::uint32_t> face_of;  // triangles[i] is mesh.faces[face_of[i]]
  Tree tree;
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
  impl_->tree.accelerate_distance_queries();  // builds the internal KD-tree now, not in a query
}

MeshQuery::~MeshQuery() = default;

bool MeshQuery::empty() const { return impl_->triangles.empty(); }

std::optional<MeshQuery::Hit> MeshQuery::first_hit(const Eigen::Vector3d& origin,
                                                   const Eigen::Vector3d& direction) const {
  if (empty()) return std::nullopt;
  const Kernel::Ray_3 ray(to_point(origin), Kernel::Vector_3(direction.x(), direction.y(), direction.z()));
  const auto hit = impl_->tree.first_intersection(ray);
  if (!hit) return std::nullopt;
  Hit h;
  h.face = impl_->face_of[std::size_t(hit->second - impl_->triangles.cbegin())];
  if (const Point* p = boost::get<Point>(&hit->first)) {
    h.point = to_eigen(*p);
  } else if (const auto* s = boost::get<Kernel::Segment_3>(&hit->first)) {
    // The ray lies in the triangle's plane: its entry point is the end nearer the origin.
    const Eigen::Vector3d p0 = to_eigen(s->source()), p1 = to_eigen(s->target());
    h.point = (p0 - origin).squaredNorm() <= (p1 - origin).squaredNorm() ? p0 : p1;
  } else {
    return std::nullopt;
  }
  h.distance = (h.point - origin).norm() / direction.norm();
  return h;
}

std::optional<MeshQuery::Closest> MeshQuery::closest(const Eigen::Vector3d& p) const {
  if (empty()) return std::nullopt;
  const auto [point, id] = impl_->tree.closest_point_and_primitive(to_point(p));
  Closest c;
  c.point = to_eigen(point);
  c.face = impl_->face_of[std::size_t(id - impl_->triangles.cbegin())];
  c.squared_distance = (c.point - p).squaredNorm();
  return c;
}

double MeshQuery::squared_distance(const Eigen::Vector3d& p) const {
  if (empty()) return std::numeric_limits<double>::infinity();
  return impl_->tree.squared_distance(to_point(p));
}

}  // namespace sf
