#pragma once
// Shared geometric vocabulary: the root cube of the primal octree.
#include <Eigen/Core>
#include <bit>
#include <cstdint>

#include "storage/voxel_key.h"

namespace sf {

// The octree's root node: an axis-aligned cube. Level l has cell size size / 2^l (the paper's
// F_box of that level).
struct RootCube {
  Eigen::Vector3d min = Eigen::Vector3d::Zero();
  double size = 1.0;

  // size x 2^-level, exact like ldexp but without its libm call: the integration asks for it per
  // triangle and work item.
  double cell_size(int level) const {
    return size * std::bit_cast<double>(std::uint64_t(1023 - level) << 52);
  }
  Eigen::Vector3d position(VoxelKey k) const {
    const double h = cell_size(k.level());
    return min + h * Eigen::Vector3d(double(k.x()), double(k.y()), double(k.z()));
  }
};

}  // namespace sf
