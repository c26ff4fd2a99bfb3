// The OpenVDB export plugin, libscalefuse_vdb.so (engine/vdb_export.h): the only code that links
// OpenVDB. Built as a module of its own, never into sf_fusion.
#include <openvdb/openvdb.h>

#include <array>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <memory>
#include <string>

#include "engine/vdb_export.h"

namespace sf {
namespace {

void write_grids(const std::filesystem::path& path, const SurfaceVoxel* voxels, std::size_t count, const RootCube& root) {
  openvdb::initialize();  // idempotent and thread-safe
  std::array<openvdb::FloatGrid::Ptr, kMaxLevel + 1> distance{}, weight{};
  std::array<openvdb::FloatGrid::Accessor*, kMaxLevel + 1> dacc{}, wacc{};
  std::vector<std::unique_ptr<openvdb::FloatGrid::Accessor>> accessors;
  for (std::size_t i = 0; i < count; ++i) {
    const SurfaceVoxel& v = voxels[i];
    const VoxelKey k = v.key;
    const int l = k.level();
    if (!distance[l]) {
      char name[32];
      const double h = root.cell_size(l);
      auto transform = openvdb::math::Transform::createLinearTransform(h);
      transform->postTranslate(openvdb::Vec3d(root.min.x(), root.min.y(), root.min.z()));
      distance[l] = openvdb::FloatGrid::create(0.f);
      weight[l] = openvdb::FloatGrid::create(0.f);
      for (auto* g : {&distance[l], &weight[l]}) {
        (*g)->setTransform(transform->copy());
        (*g)->insertMeta("octree_level", openvdb::Int32Metadata(l));
        (*g)->insertMeta("cell_size_m", openvdb::DoubleMetadata(h));
      }
      std::snprintf(name, sizeof name, "distance_L%02d", l);
      distance[l]->setName(name);
      std::snprintf(name, sizeof name, "weight_L%02d", l);
      weight[l]->setName(name);
      accessors.push_back(std::make_unique<openvdb::FloatGrid::Accessor>(distance[l]->getAccessor()));
      dacc[l] = accessors.back().get();
      accessors.push_back(std::make_unique<openvdb::FloatGrid::Accessor>(weight[l]->getAccessor()));
      wacc[l] = accessors.back().get();
    }
    const openvdb::Coord c(int(k.x()), int(k.y()), int(k.z()));
    dacc[l]->setValue(c, v.distance);
    wacc[l]->setValue(c, v.weight);
  }
  openvdb::GridPtrVec grids;
  for (int l = 0; l <= kMaxLevel; ++l)
    if (distance[l]) {
      grids.push_back(distance[l]);
      grids.push_back(weight[l]);
    }
  accessors.clear();
  openvdb::io::File file(path.string());
  file.write(grids);
  file.close();
}

}  // namespace
}  // namespace sf

extern "C" int scalefuse_export_vdb_v1(const char* path, const sf::SurfaceVoxel* voxels, std::size_t count,
                                       const sf::RootCube* root, char* error, std::size_t error_size) {
  // Matches sf::VdbExportFn; checked here so that a change of one without the other fails to build.
  [[maybe_unused]] constexpr sf::VdbExportFn kSignature = &scalefuse_export_vdb_v1;
  try {
    sf::write_grids(path, voxels, count, *root);
    return 0;
  } catch (const std::exception& e) {
    std::snprintf(error, error_size, "%s", e.what());
  } catch (...) {
    std::snprintf(error, error_size, "unknown error");
  }
  return 1;
}
