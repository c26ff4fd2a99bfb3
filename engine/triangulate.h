#pragma once
// Section 5, first step: image-space triangulation of a depth map, dropping triangles across depth
// discontinuities.
#include <array>
#include <cstdint>
#include <vector>

#include "engine/depth_frame.h"

namespace sf {

struct TriangulateOptions {
  double rho = 5.0;  // discontinuity threshold: an edge breaks if |z_a - z_b| > rho * F of the nearer sample
  void check() const;
};

// Triangle of sample indices (row * width + col). Orientation in the sensor plane is not fixed
// (range grids are mirrored); consumers derive it from positions.
using FrameTriangle = std::array<std::uint32_t, 3>;

// Depth of each sample along the sensor axis (z in the sensor frame); 0 where invalid.
std::vector<float> sensor_depths(const DepthFrame& frame);

// True if samples a and b are separated by a depth discontinuity (section 5).
inline bool is_discontinuity(float depth_a, float depth_b, float footprint_a, float footprint_b, double rho) {
  const float nearer_footprint = depth_a <= depth_b ? footprint_a : footprint_b;
  const float gap = depth_a > depth_b ? depth_a - depth_b : depth_b - depth_a;
  return gap > rho * nearer_footprint;
}

// Two triangles per 2x2 block of valid samples (split along the diagonal with the smaller depth
// gap), one if exactly three are valid; triangles with a discontinuous edge are dropped.
std::vector<FrameTriangle> triangulate(const DepthFrame& frame, const TriangulateOptions& options);

}  // namespace sf
