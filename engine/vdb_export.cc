#include "engine/vdb_export.h"

#include <openvdb/openvdb.h>
#include <unistd.h>

#include <array>
#include <cstdio>

#include "engine/error.h"

namespace sf {

void initialize_vdb() { openvdb::initialize(); }

void export_vdb(const std::filesystem::path& path, const std::vector<SurfaceVoxel>& voxels, const RootCube& root) {
  std::array<openvdb::FloatGrid::Ptr, kMaxLevel + 1> distance{}, weight{};
  std::array<openvdb::FloatGrid::Accessor*, kMaxLevel + 1> dacc{}, wacc{};
  std::vector<std::unique_ptr<openvdb::FloatGrid::Accessor>> accessors;
  for (const SurfaceVoxel& v : voxels) {
    {
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
  }
  openvdb::GridPtrVec grids;
  for (int l = 0; l <= kMaxLevel; ++l)
    if (distance[l]) {
      grids.push_back(distance[l]);
      grids.push_back(weight[l]);
    }
  accessors.clear();
  const std::filesystem::path tmp = path.string() + ".tmp-" + std::to_string(::getpid());
  try {
    openvdb::io::File file(tmp.string());
    file.write(grids);
    file.close();
  } catch (const openvdb::Exception& e) {
    std::filesystem::remove(tmp);
    throw std::runtime_error(path.string() + ": cannot write VDB: " + e.what());
  }
  std::filesystem::rename(tmp, path);
}

}  // namespace sf
