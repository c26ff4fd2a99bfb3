// PLY reading and writing: hand-written files in every encoding, the shared data meshes, and
// malformed input (which must raise InputError naming the file, never allocate from a header).
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cstring>
#include <fstream>
#include <string>

#include "engine/error.h"
#include "engine/meshio/ply_io.h"
#include "tests/test_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

fs::path write_text(const fs::path& dir, const std::string& name, const std::string& bytes) {
  const fs::path p = dir / name;
  std::ofstream(p, std::ios::binary) << bytes;
  return p;
}

template <typename T>
void put(std::string& s, T v, bool big_endian) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if (big_endian != (std::endian::native == std::endian::big)) std::reverse(b, b + sizeof(T));
  s.append(b, sizeof(T));
}

// Expects InputError whose message names the file.
void expect_input_error(const fs::path& p, const std::string& fragment = "") {
  try {
    read_ply_mesh(p);
    ADD_FAILURE() << "no error for " << p;
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(p.string()), std::string::npos) << what;
    if (!fragment.empty()) {
      EXPECT_NE(what.find(fragment), std::string::npos) << what;
    }
  }
}

TEST(MeshioPly, RoundTripAllAttributes) {
  const fs::path dir = test::scratch_dir("meshio_roundtrip");
  Mesh m;
  for (int i = 0; i < 5; ++i) {
    m.vertices.emplace_back(0.1f * i, -0.5f * i, 3.25f + i);
    m.colours.push_back({std::uint8_t(i), std::uint8_t(100 + i), std::uint8_t(250 - i)});
    m.confidence.push_back(0.5f * i);
    m.scale.push_back(0.001f * (i + 1));
  }
  m.faces = {{0, 1, 2}, {2, 3, 4}, {4, 0, 1}};
  write_ply_mesh(dir / "m.ply", m);
  // Nothing but the file remains (the temporary was renamed).
  EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator()), 1);
  const Mesh r = read_ply_mesh(dir / "m.ply");
  EXPECT_EQ(r.vertices, m.vertices);
  EXPECT_EQ(r.colours, m.colours);
  EXPECT_EQ(r.confidence, m.confidence);
  EXPECT_EQ(r.scale, m.scale);
  EXPECT_EQ(r.faces, m.faces);

  // Without optional attributes: the header holds only x y z and faces.
  Mesh plain;
  plain.vertices = m.vertices;
  plain.faces = m.faces;
  write_ply_mesh(dir / "plain.ply", plain);
  const Mesh p = read_ply_mesh(dir / "plain.ply");
  EXPECT_TRUE(p.colours.empty() && p.confidence.empty() && p.scale.empty());
  EXPECT_EQ(p.faces, m.faces);
  // Exact size: header + 5 * 12 + 3 * 13 bytes.
  std::ifstream in(dir / "plain.ply", std::ios::binary);
  std::string all((std::istreambuf_iterator<char>(in)), {});
  const auto body = all.find("end_header\n") + 11;
  EXPECT_EQ(all.size() - body, 5u * 12 + 3u * 13);
  EXPECT_NE(all.find("property list uchar int vertex_indices"), std::string::npos);
}

TEST(MeshioPly, WriteRejectsInconsistentMesh) {
  const fs::path dir = test::scratch_dir("meshio_bad_write");
  Mesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.faces = {{0, 1, 3}};
  EXPECT_THROW(write_ply_mesh(dir / "m.ply", m), std::invalid_argument);
  m.faces = {{0, 1, 2}};
  m.colours.resize(2);
  EXPECT_THROW(write_ply_mesh(dir / "m.ply", m), std::invalid_argument);
  EXPECT_FALSE(fs::exists(dir / "m.ply"));
  EXPECT_THROW(write_ply_mesh(dir / "missing_folder" / "m.ply", Mesh{}), InputError);
}

TEST(MeshioPly, AsciiWithExtraPropertiesQuadsAndUnknownElements) {
  const fs::path dir = test::scratch_dir("meshio_ascii");
  const fs::path p = write_text(dir, "a.ply",
                                "ply\r\n"
                                "format ascii 1.0\r\n"
                                "comment hand written, CRLF line ends\r\n"
                                "obj_info something 1\r\n"
                                "element material 2\r\n"
                                "property list uchar float values\r\n"
                                "property int id\r\n"
                                "element vertex 5\r\n"
                                "property double x\r\n"
                                "property float nx\r\n"
                                "property float y\r\n"
                                "property float z\r\n"
                                "property uchar red\r\n"
                                "property uchar green\r\n"
                                "property uchar blue\r\n"
                                "property float intensity\r\n"
                                "element face 2\r\n"
                                "property uchar flags\r\n"
                                "property list uchar uint vertex_index\r\n"
                                "element edge 1\r\n"
                                "property int vertex1\r\n"
                                "property int vertex2\r\n"
                                "end_header\r\n"
                                "3 1.5 2.5 3.5 7\r\n"
                                "0  -1\r\n"
                                "0 9 0 0 10 20 30 0.5\r\n"
                                "1 9 0 0 11 21 31 0.5\n"
                                "1 9 1 0 12 22 32 0.5\n"
                                "0 9 1 0 13 23 33 0.5\n"
                                "0.5 9 0.5 1 255 255 255 0.5\n"
                                "0 4 0 1 2 3\n"
                                "1 3 0 1 4\n"
                                "0 1");  // last value without a line break
  const Mesh m = read_ply_mesh(p);
  ASSERT_EQ(m.vertices.size(), 5u);
  EXPECT_EQ(m.vertices[1], Eigen::Vector3f(1, 0, 0));
  EXPECT_EQ(m.vertices[4], Eigen::Vector3f(0.5f, 0.5f, 1));
  ASSERT_EQ(m.colours.size(), 5u);
  EXPECT_EQ(m.colours[2], (Rgb8{12, 22, 32}));
  EXPECT_TRUE(m.confidence.empty());
  // The quad is fan-triangulated into (0,1,2), (0,2,3).
  const std::vector<std::array<std::uint32_t, 3>> faces = {{0, 1, 2}, {0, 2, 3}, {0, 1, 4}};
  EXPECT_EQ(m.faces, faces);
}

std::string binary_file(bool big_endian, int bad_index = -1) {
  std::string s = std::string("ply\nformat ") + (big_endian ? "binary_big_endian" : "binary_little_endian") +
                  " 1.0\n"
                  "element vertex 4\n"
                  "property float32 x\nproperty float32 y\nproperty float64 z\n"
                  "property int16 quality\n"
                  "element face 2\n"
                  "property list uint8 int32 vertex_indices\n"
                  "property list ushort short texcoord\n"
                  "end_header\n";
  const float xy[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  for (int i = 0; i < 4; ++i) {
    put(s, xy[i][0], big_endian);
    put(s, xy[i][1], big_endian);
    put(s, double(i) * 0.25, big_endian);
    put(s, std::int16_t(-i), big_endian);
  }
  put(s, std::uint8_t(3), big_endian);
  for (int v : {0, 1, 2}) put(s, std::int32_t(v), big_endian);
  put(s, std::uint16_t(2), big_endian);
  put(s, std::int16_t(5), big_endian);
  put(s, std::int16_t(6), big_endian);
  put(s, std::uint8_t(3), big_endian);
  for (int v : {0, 2, bad_index >= 0 ? bad_index : 3}) put(s, std::int32_t(v), big_endian);
  put(s, std::uint16_t(0), big_endian);
  return s;
}

TEST(MeshioPly, BinaryBothEndians) {
  const fs::path dir = test::scratch_dir("meshio_binary");
  for (bool be : {false, true}) {
    const Mesh m = read_ply_mesh(write_text(dir, be ? "be.ply" : "le.ply", binary_file(be)));
    ASSERT_EQ(m.vertices.size(), 4u) << be;
    EXPECT_EQ(m.vertices[2], Eigen::Vector3f(1, 1, 0.5f)) << be;
    EXPECT_EQ(m.vertices[3], Eigen::Vector3f(0, 1, 0.75f)) << be;
    const std::vector<std::array<std::uint32_t, 3>> faces = {{0, 1, 2}, {0, 2, 3}};
    EXPECT_EQ(m.faces, faces) << be;
  }
}

TEST(MeshioPly, TriangleStripsMatchTheExpandedIgea) {
  const fs::path data = test::shared_data() / "meshes";
  const Mesh strips = read_ply_mesh(data / "igea.ply");
  const Mesh tris = read_ply_mesh(data / "igea_triangles.ply");
  EXPECT_EQ(strips.vertices.size(), 134345u);
  EXPECT_EQ(tris.faces.size(), 268686u);
  EXPECT_EQ(strips.faces.size(), tris.faces.size());
  EXPECT_TRUE(strips.vertices == tris.vertices);
  EXPECT_TRUE(strips.faces == tris.faces);  // same triangles, same order, same winding
}

TEST(MeshioPly, HandWrittenStrips) {
  const fs::path dir = test::scratch_dir("meshio_strips");
  // Strip 0 1 2 3 4, then a strip with a repeated vertex (degenerate triangles dropped).
  const fs::path p = write_text(dir, "s.ply",
                                "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
                                "property float z\nelement tristrips 1\nproperty list int int vertex_indices\n"
                                "end_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n0 2 0\n1 2 0\n"
                                "11 0 1 2 3 4 -1 2 2 3 5 -1\n");
  const Mesh m = read_ply_mesh(p);
  // 0 1 2 | 2 1 3 | 2 3 4   then strip 2 2 3 5: (2,2,3) and (2,3,2)... only (2,3,5) at even i=3 -> swapped.
  const std::vector<std::array<std::uint32_t, 3>> faces = {{0, 1, 2}, {2, 1, 3}, {2, 3, 4}, {3, 2, 5}};
  EXPECT_EQ(m.faces, faces);
}

TEST(MeshioPly, FacesBeforeVertices) {
  // PLY does not fix the element order; indices are checked once everything is read.
  const fs::path dir = test::scratch_dir("meshio_order");
  const std::string head = "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n"
                           "element vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
  const Mesh m = read_ply_mesh(write_text(dir, "ok.ply", head + "3 2 1 0\n0 0 0\n1 0 0\n0 1 0\n"));
  EXPECT_EQ(m.faces, (std::vector<std::array<std::uint32_t, 3>>{{2, 1, 0}}));
  expect_input_error(write_text(dir, "bad.ply", head + "3 3 1 0\n0 0 0\n1 0 0\n0 1 0\n"), "vertex 3");
}

TEST(MeshioPly, StanfordBunnyFiles) {
  const fs::path data = test::shared_data() / "stanford_bunny";
  const Mesh z = read_ply_mesh(data / "reconstruction" / "bun_zipper.ply");
  EXPECT_EQ(z.vertices.size(), 35947u);
  EXPECT_EQ(z.faces.size(), 69451u);
  EXPECT_EQ(z.confidence.size(), 35947u);  // the file's confidence property
  const Mesh r4 = read_ply_mesh(data / "reconstruction" / "bun_zipper_res4.ply");
  EXPECT_EQ(r4.vertices.size(), 453u);
  const Mesh scan = read_ply_mesh(data / "scans" / "bun000.ply");  // range_grid lists are skipped
  EXPECT_GT(scan.vertices.size(), 30000u);
  EXPECT_TRUE(scan.faces.empty());
}

TEST(MeshioPly, MalformedInput) {
  const fs::path dir = test::scratch_dir("meshio_malformed");
  const std::string good = binary_file(false);
  expect_input_error(dir / "does_not_exist.ply", "missing");
  expect_input_error(write_text(dir, "empty.ply", ""));
  expect_input_error(write_text(dir, "notply.ply", "plx\nformat ascii 1.0\nend_header\n"), "not a PLY");
  expect_input_error(write_text(dir, "noend.ply", "ply\nformat ascii 1.0\nelement vertex 1\n"), "end_header");
  expect_input_error(write_text(dir, "badfmt.ply", "ply\nformat binary_middle_endian 1.0\nend_header\n"));
  expect_input_error(write_text(dir, "badtype.ply",
                                "ply\nformat ascii 1.0\nelement vertex 1\nproperty real x\nend_header\n0\n"));
  expect_input_error(write_text(dir, "noxyz.ply",
                                "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n"));
  // Truncated body, at several cut points.
  for (std::size_t cut : {good.size() - 1, good.size() - 20, good.find("end_header") + 20})
    expect_input_error(write_text(dir, "trunc" + std::to_string(cut) + ".ply", good.substr(0, cut)), "trunc");
  // Index out of range.
  expect_input_error(write_text(dir, "index.ply", binary_file(false, 4)), "vertex 4");
  // Absurd counts: a header asking for 2^60 vertices in a tiny file must fail without allocating.
  std::string absurd = good;
  absurd.replace(absurd.find("vertex 4"), 8, "vertex 1152921504606846976");
  expect_input_error(write_text(dir, "absurd.ply", absurd), "more than the file");
  // An absurd list length.
  expect_input_error(write_text(dir, "list.ply",
                                "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                                "property float z\nelement face 1\nproperty list uint int vertex_indices\n"
                                "end_header\n0 0 0\n4000000000 0 0 0\n"),
                     "list length");
  expect_input_error(write_text(dir, "negidx.ply",
                                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 -2 1\n"),
                     "-2");
  expect_input_error(write_text(dir, "garbage.ply",
                                "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                                "property float z\nend_header\n0 zero 0\n"),
                     "zero");
}

}  // namespace
}  // namespace sf
