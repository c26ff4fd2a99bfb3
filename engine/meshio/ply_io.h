#pragma once
// PLY meshes: reading any common PLY (ascii / binary either endian; faces as lists or triangle
// strips) and writing binary little-endian PLY with scalefuse's vertex attributes.
#include <filesystem>

#include "engine/mesh.h"

namespace sf {

// Reads vertices (x y z; red green blue if present) and faces (element face with vertex_indices or
// vertex_index, polygons fan-triangulated; or element tristrips with -1 separators). Throws
// InputError naming the file on malformed input.
Mesh read_ply_mesh(const std::filesystem::path& path);

// Writes binary little-endian PLY: x y z float; red green blue uchar, confidence float and scale
// float when present. Writes to a temporary file in the same folder, then renames it into place.
void write_ply_mesh(const std::filesystem::path& path, const Mesh& mesh);

}  // namespace sf
