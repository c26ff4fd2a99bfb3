#pragma once
// Ray and distance queries against a triangle mesh (a CGAL AABB tree behind a pimpl, so that CGAL
// stays out of this header). Built once, then const and safe to query from many threads.
#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <optional>

#include "engine/mesh.h"

namespace sf {

class MeshQuery {
 public:
  // Builds the tree over the mesh's non-degenerate triangles (zero-area ones cannot be hit and
  // are left out), and the accelerator for distance queries. The mesh may be freed afterwards.
  explicit MeshQuery(const Mesh& mesh);
  ~MeshQuery();
  MeshQuery(const MeshQuery&) = delete;
  MeshQuery& operator=(const MeshQuery&) = delete;

  bool empty() const;  // no (non-degenerate) triangle

  struct Hit {
    double distance = 0;            // along the ray, in units of |direction|
    std::uint32_t face = 0;         // index into mesh.faces
    Eigen::Vector3d point = Eigen::Vector3d::Zero();
  };
  // The first surface point on the ray origin + s * direction, s > 0.
  std::optional<Hit> first_hit(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction) const;

  struct Closest {
    double squared_distance = 0;
    std::uint32_t face = 0;
    Eigen::Vector3d point = Eigen::Vector3d::Zero();
  };
  // Closest surface point; nullopt if the mesh is empty.
  std::optional<Closest> closest(const Eigen::Vector3d& p) const;
  // Squared distance to the surface; +infinity if the mesh is empty.
  double squared_distance(const Eigen::Vector3d& p) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sf
