// VoxelKey is header-only; this unit keeps the static library non-empty and checks the layout.
#include "storage/voxel_key.h"

namespace sf {
static_assert(VoxelKey::kLevelShift + 5 <= 64, "key layout overflows 64 bits");
static_assert((std::uint64_t{1} << kMaxLevel) <= kCoordMask, "deepest level's coordinates must fit");
static_assert(VoxelKey::make(18, 262144, 5, 7).x() == 262144);
static_assert(VoxelKey::make(18, 262144, 5, 7).level() == 18);
}  // namespace sf
