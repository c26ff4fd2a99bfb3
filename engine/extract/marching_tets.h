#pragma once
// Section 7.2 on one tetrahedron: Marching Tetrahedra on distances that may be exactly zero (the
// case table and the zero-face rule are in extract.h). No CGAL here.
#include <Eigen/Core>
#include <array>
#include <cstdint>

namespace sf::extract_detail {

// An output vertex, named by the voxels (indices in key order) that define it:
//   a == b  the voxel a itself, whose distance is exactly 0;
//   a <  b  the crossing on the edge between voxels a and b (distances of opposite signs).
struct MtVertex {
  std::uint32_t a = 0, b = 0;
  // The identity as one sortable number: (a, b) lexicographically.
  constexpr std::uint64_t id() const { return (std::uint64_t(a) << 32) | b; }
  static constexpr MtVertex from_id(std::uint64_t id) { return {std::uint32_t(id >> 32), std::uint32_t(id)}; }
  static constexpr MtVertex voxel(std::uint32_t i) { return {i, i}; }
  static constexpr MtVertex edge(std::uint32_t i, std::uint32_t j) { return i < j ? MtVertex{i, j} : MtVertex{j, i}; }
  friend constexpr bool operator==(MtVertex x, MtVertex y) { return x.a == y.a && x.b == y.b; }
};

struct MtTriangle {
  std::array<MtVertex, 3> v;  // (v1 - v0) x (v2 - v0) points toward positive distance
  bool zero_face = false;     // a face of the tetrahedron whose three voxels are all zero
};

// Read-only per-voxel arrays, indexed by voxel index.
struct FieldView {
  const Eigen::Vector3d* position = nullptr;
  const float* distance = nullptr;
};

// Fraction of the edge (lo -> hi), lo < hi, at which the linear interpolant of the two distances
// (strictly opposite signs) is zero. Always evaluated from the lower index, so every tetrahedron
// and the snapping step get bit-identical results for the same edge.
inline double crossing_fraction(float d_lo, float d_hi) { return double(d_lo) / (double(d_lo) - double(d_hi)); }

inline Eigen::Vector3d lerp(const Eigen::Vector3d& p_lo, const Eigen::Vector3d& p_hi, double t) {
  return p_lo + t * (p_hi - p_lo);
}

// Position of an output vertex.
inline Eigen::Vector3d vertex_position(const FieldView& f, MtVertex v) {
  if (v.a == v.b) return f.position[v.a];
  return lerp(f.position[v.a], f.position[v.b], crossing_fraction(f.distance[v.a], f.distance[v.b]));
}

// The pattern of a tetrahedron: how many vertices are negative, zero, positive.
struct SignCount {
  int negative = 0, zero = 0, positive = 0;
};
SignCount count_signs(const std::array<float, 4>& d);

// True if a tetrahedron with these distances emits at least one triangle (before the zero-face
// cancellation between neighbours).
bool emits_triangles(const std::array<float, 4>& d);

// Marching Tetrahedra on one tetrahedron. tet: voxel indices, positively oriented (see Tet in
// delaunay.h). Writes 0, 1 or 2 triangles to out and returns their number. The result does not
// depend on the order of the vertices in tet, only on its orientation.
int march_tetrahedron(const std::array<std::uint32_t, 4>& tet, const FieldView& field, MtTriangle out[2]);

}  // namespace sf::extract_detail
