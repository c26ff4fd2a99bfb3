#pragma once
// Exports the fused field as OpenVDB grids for Houdini/Blender users: per octree level l, a float
// grid "distance_Lnn" (signed distance, metres, positive in front of the surface) and a float grid
// "weight_Lnn" (confidence), with a linear transform so that index (i,j,k) of level l sits at
// root.min + cell_size(l) * (i,j,k) in world metres.
//
// The OpenVDB code is a plugin, libscalefuse_vdb.so (engine/vdb_plugin.cc), loaded only by a run
// that exports. Linked into the program, OpenVDB's 69,000 symbol relocations, all resolved at load
// (the library is linked with BIND_NOW), cost every start of the program ~70 ms on this project's
// machines, twice with the huge-page re-execution (scheduler/huge_pages.h): more than the work of
// many commands, and of most tests (bench/README.md, session 34).
#include <filesystem>
#include <string>
#include <vector>

#include "engine/extract/extract.h"
#include "engine/geometry.h"

namespace sf {

// The plugin's one entry point (extern "C", so that dlsym finds it by this name). Writes the
// grids to `path` as it is (VdbExporter::write gives it a temporary sibling and renames); returns
// 0, or non-zero with OpenVDB's one-line message in `error` (no exception crosses the boundary).
using VdbExportFn = int (*)(const char* path, const SurfaceVoxel* voxels, std::size_t count, const RootCube* root,
                            char* error, std::size_t error_size);
inline constexpr const char* kVdbExportSymbol = "scalefuse_export_vdb_v1";

class VdbExporter {
 public:
  // Loads the plugin: the file named by $SCALEFUSE_VDB_PLUGIN if set, else
  // lib/scalefuse/libscalefuse_vdb.so beside the folder of the running program (build/bin/ ->
  // build/lib/scalefuse/). Throws std::runtime_error naming the file if it cannot be loaded.
  static VdbExporter load();
  // The plugin file load() tries.
  static std::filesystem::path plugin_path();

  // Writes the grids through a temporary sibling of `path`, renamed into place; throws
  // std::runtime_error "path: cannot write VDB: why" if that fails (no file is left behind).
  void write(const std::filesystem::path& path, const std::vector<SurfaceVoxel>& voxels, const RootCube& root) const;

 private:
  // The plugin stays loaded until the process exits (never dlclose()d: OpenVDB's statics and
  // its TBB use are not made to be unloaded mid-run), so copies share nothing to manage.
  VdbExportFn export_ = nullptr;
};

}  // namespace sf
