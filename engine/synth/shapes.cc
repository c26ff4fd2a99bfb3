#include "engine/synth/shapes.h"

#include <cmath>
#include <map>
#include <utility>

namespace sf {

Mesh make_sphere(const Eigen::Vector3d& centre, double radius, int subdivisions) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> v = {{-1, t, 0}, {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                                    {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (auto& p : v) p.normalize();
  std::vector<std::array<std::uint32_t, 3>> f = {
      {0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
      {11, 10, 2}, {10, 7, 6}, {7, 1, 8},   {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
      {3, 8, 9},  {4, 9, 5},  {2, 4, 11},  {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint32_t> mid;
    auto midpoint = [&](std::uint32_t a, std::uint32_t b) {
      const auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[a] + v[b]).normalized());
      const auto id = std::uint32_t(v.size() - 1);
      mid.emplace(key, id);
      return id;
    };
    std::vector<std::array<std::uint32_t, 3>> next;
    next.reserve(f.size() * 4);
    for (const auto& tri : f) {
      const std::uint32_t a = midpoint(tri[0], tri[1]), b = midpoint(tri[1], tri[2]), c = midpoint(tri[2], tri[0]);
      next.push_back({tri[0], a, c});
      next.push_back({tri[1], b, a});
      next.push_back({tri[2], c, b});
      next.push_back({a, b, c});
    }
    f = std::move(next);
  }
  Mesh m;
  m.vertices.reserve(v.size());
  for (const auto& p : v) m.vertices.push_back((centre + radius * p).cast<float>());
  m.faces = std::move(f);
  return m;
}

Mesh make_box(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  Mesh m;
  for (int i = 0; i < 8; ++i)
    m.vertices.emplace_back(float(i & 1 ? hi.x() : lo.x()), float(i & 2 ? hi.y() : lo.y()), float(i & 4 ? hi.z() : lo.z()));
  // Corner i has x from bit 0, y from bit 1, z from bit 2.
  m.faces = {{0, 2, 1}, {1, 2, 3},   // z = lo
             {4, 5, 6}, {5, 7, 6},   // z = hi
             {0, 1, 4}, {1, 5, 4},   // y = lo
             {2, 6, 3}, {3, 6, 7},   // y = hi
             {0, 4, 2}, {2, 4, 6},   // x = lo
             {1, 3, 5}, {3, 7, 5}};  // x = hi
  return m;
}

Mesh make_rectangle(double x0, double x1, double y0, double y1, double z) {
  Mesh m;
  m.vertices = {Eigen::Vector3f(float(x0), float(y0), float(z)), Eigen::Vector3f(float(x1), float(y0), float(z)),
                Eigen::Vector3f(float(x1), float(y1), float(z)), Eigen::Vector3f(float(x0), float(y1), float(z))};
  // Normal (b - a) x (c - a) = +x * +y = +z for (0,1,2); we want -z: wind (0,2,1), (0,3,2).
  m.faces = {{0, 2, 1}, {0, 3, 2}};
  return m;
}

}  // namespace sf
