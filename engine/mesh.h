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

}  // namespace sf
