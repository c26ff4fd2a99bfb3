#pragma once
// Exports the fused field as OpenVDB grids for Houdini/Blender users: per octree level l, a float
// grid "distance_Lnn" (signed distance, metres, positive in front of the surface) and a float grid
// "weight_Lnn" (confidence), with a linear transform so that index (i,j,k) of level l sits at
// root.min + cell_size(l) * (i,j,k) in world metres.
#include <filesystem>
#include <vector>

#include "engine/geometry.h"
#include "engine/extract/extract.h"

namespace sf {

// Call once per process before any OpenVDB use (cli/ does).
void initialize_vdb();

// Writes to a temporary file beside `path`, then renames it into place.
void export_vdb(const std::filesystem::path& path, const std::vector<SurfaceVoxel>& voxels, const RootCube& root);

}  // namespace sf
