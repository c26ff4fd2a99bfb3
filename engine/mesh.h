#pragma once
// An indexed triangle mesh with the per-vertex attributes scalefuse writes.
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

#include "engine/depth_frame.h"

namespace sf {

struct Mesh {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<Rgb8> colours;        // empty or one per vertex
  std::vector<float> confidence;    // empty or one per vertex: interpolated voxel weight
  std::vector<float> scale;         // empty or one per vertex: interpolated octree cell size, metres
  std::vector<std::array<std::uint32_t, 3>> faces;
};

// A mesh written as it is produced (the brick-by-brick extraction never holds it whole): begin
// with the final counts, then every vertex in order, then every face, then end.
class MeshStream {
 public:
  virtual ~MeshStream() = default;
  virtual void begin(std::size_t vertices, std::size_t faces) = 0;
  virtual void vertex(const Eigen::Vector3f& position, const Rgb8& colour, float confidence, float scale) = 0;
  virtual void face(const std::array<std::uint32_t, 3>& face) = 0;
  virtual void end() = 0;
};

// Streams a mesh held in memory.
inline void stream_mesh(const Mesh& mesh, MeshStream& out) {
  const std::size_t n = mesh.vertices.size();
  out.begin(n, mesh.faces.size());
  for (std::size_t i = 0; i < n; ++i)
    out.vertex(mesh.vertices[i], mesh.colours.empty() ? Rgb8{} : mesh.colours[i],
               mesh.confidence.empty() ? 0.f : mesh.confidence[i], mesh.scale.empty() ? 0.f : mesh.scale[i]);
  for (const auto& f : mesh.faces) out.face(f);
  out.end();
}

// Collects a streamed mesh in memory.
class MeshCollector : public MeshStream {
 public:
  void begin(std::size_t vertices, std::size_t faces) override {
    mesh = Mesh{};
    mesh.vertices.reserve(vertices);
    mesh.colours.reserve(vertices);
    mesh.confidence.reserve(vertices);
    mesh.scale.reserve(vertices);
    mesh.faces.reserve(faces);
  }
  void vertex(const Eigen::Vector3f& position, const Rgb8& colour, float confidence, float scale) override {
    mesh.vertices.push_back(position);
    mesh.colours.push_back(colour);
    mesh.confidence.push_back(confidence);
    mesh.scale.push_back(scale);
  }
  void face(const std::array<std::uint32_t, 3>& f) override { mesh.faces.push_back(f); }
  void end() override {}
  Mesh mesh;
};

}  // namespace sf
