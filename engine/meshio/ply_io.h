#pragma once
// PLY meshes: reading any common PLY (ascii / binary either endian; faces as lists or triangle
// strips) and writing binary little-endian PLY with scalefuse's vertex attributes.
#include <filesystem>
#include <memory>
#include <vector>

#include "engine/mesh.h"

namespace sf {

class AtomicFile;

// Reads vertices (x y z; red green blue if present) and faces (element face with vertex_indices or
// vertex_index, polygons fan-triangulated; or element tristrips with -1 separators). Throws
// InputError naming the file on malformed input.
Mesh read_ply_mesh(const std::filesystem::path& path);

// Writes binary little-endian PLY: x y z float; red green blue uchar, confidence float and scale
// float when present. Writes to a temporary file in the same folder, then renames it into place.
void write_ply_mesh(const std::filesystem::path& path, const Mesh& mesh);

// The same file, streamed: begin() writes the header, vertices and faces follow, end() renames the
// finished file into place (destroyed before end(): the temporary file is removed).
class PlyStreamWriter : public MeshStream {
 public:
  explicit PlyStreamWriter(std::filesystem::path path, bool colour = true, bool confidence = true, bool scale = true);
  ~PlyStreamWriter() override;
  void begin(std::size_t vertices, std::size_t faces) override;
  void vertex(const Eigen::Vector3f& position, const Rgb8& colour, float confidence, float scale) override;
  void face(const std::array<std::uint32_t, 3>& face) override;
  void end() override;

 private:
  void put(const void* data, std::size_t bytes);
  void drain();
  std::filesystem::path path_;
  bool colour_, confidence_, scale_;
  std::unique_ptr<AtomicFile> file_;
  std::vector<char> buffer_;
  std::size_t vertices_ = 0, faces_ = 0, vertices_seen_ = 0, faces_seen_ = 0;
};

}  // namespace sf
