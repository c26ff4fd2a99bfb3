#pragma once
// Shared geometric vocabulary: the root cube of the primal octree.
#include <Eigen/Core>
#include <cmath>

#include "storage/voxel_key.h"

namespace sf {

// The octree's root node: an axis-aligned cube. Level l has cell size size / 2^l (the paper's
// F_box of that level).
struct RootCube {
  Eigen::Vector3d min = Eigen::Vector3d::Zero();
  double size = 1.0;

  double cell_size(int level) const { return std::ldexp(size, -level); }
  Eigen::Vector3d position(VoxelKey k) const {
    const double h = cell_size(k.level());
    return min + h * Eigen::Vector3d(double(k.x()), double(k.y()), double(k.z()));
  }
};

}  // namespace sf
