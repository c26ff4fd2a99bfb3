// Stanford range grids: a hand-made scan, and the real bunny scans against the zippered mesh.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <sstream>
#include <unordered_map>

#include "engine/error.h"
#include "engine/input/frame_source.h"
#include "engine/input/rangegrid_io.h"
#include "tests/test_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

using test::expect_input_error;
using test::write_text;

// A 3 x 2 grid (num_cols 3, num_rows 2), cells row by row; cell (row 1, col 0) is empty.
// Points in the scan frame: columns 1 mm apart in x, rows 2 mm apart in y.
std::string small_scan() {
  return "ply\nformat ascii 1.0\nobj_info is_cyberware_data 1\nobj_info num_cols 3\nobj_info num_rows 2\n"
         "element vertex 5\nproperty float x\nproperty float y\nproperty float z\nproperty float confidence\n"
         "element range_grid 6\nproperty list uchar int vertex_indices\nend_header\n"
         "0 0 0.01 1\n0.001 0 0.01 0.5\n0.002 0 0.012 1\n0.001 0.002 0.01 1\n0.002 0.002 0.01 1\n"
         "1 0\n1 1\n1 2\n0\n1 3\n1 4\n";
}

TEST(InputRangeGrid, HandWorkedScan) {
  const fs::path dir = test::scratch_dir("rangegrid_small");
  write_text(dir / "s.ply", small_scan());
  // Quaternion (x y z w) = (0, 0, sin 45, cos 45): R(q) = Rz(90). p_world = R(q)^T p_scan + t.
  const double s = std::sqrt(0.5);
  std::ostringstream conf;
  conf.precision(17);
  conf << "camera 0 0 1 0 0 0 1\nbmesh s.ply 1 2 3 0 0 " << s << " " << s << "\n";
  write_text(dir / "s.conf", conf.str());
  const auto src = open_input(dir, {});
  EXPECT_EQ(src->format(), "rangegrid");
  ASSERT_EQ(src->size(), 1u);
  const DepthFrame f = src->load(0);
  EXPECT_EQ(f.sensor.kind, Sensor::Kind::Orthographic);
  ASSERT_EQ(f.width, 3);
  ASSERT_EQ(f.height, 2);
  EXPECT_EQ(f.valid_count(), 5u);
  EXPECT_FALSE(f.valid[3]);
  // Cell (row 0, col 2) = point (0.002, 0, 0.012): R^T p = Rz(-90) p = (0, -0.002, 0.012), + t.
  EXPECT_NEAR(f.position[2].x(), 1.0, 1e-6);
  EXPECT_NEAR(f.position[2].y(), 2.0 - 0.002, 1e-6);
  EXPECT_NEAR(f.position[2].z(), 3.012, 1e-6);
  // Sensor looks along -z_scan, i.e. world R(q)^T (0,0,-1) = (0,0,-1); image_pos = (x, -y).
  EXPECT_TRUE(f.sensor.axis().isApprox(Eigen::Vector3d(0, 0, -1)));
  EXPECT_NEAR(std::abs(f.sensor.R.determinant() - 1), 0, 1e-12);
  EXPECT_FLOAT_EQ(f.image_pos[4].x(), 0.001f);
  EXPECT_FLOAT_EQ(f.image_pos[4].y(), -0.002f);
  Eigen::Vector2d uv;
  ASSERT_TRUE(f.sensor.project(f.position[4].cast<double>(), &uv));
  EXPECT_NEAR(uv.x(), 0.001, 1e-7);
  EXPECT_NEAR(uv.y(), -0.002, 1e-7);
  // Depths along the axis are positive.
  for (int i : {0, 1, 2, 4, 5}) EXPECT_GT((f.sensor.R * f.position[i].cast<double>() + f.sensor.t).z(), 0);
  // Footprints: sqrt(column spacing x row spacing) in the sensor plane.
  // Cell 1 (row 0, col 1): columns 1 mm both sides; row neighbour cell 4 at 2 mm -> sqrt(1 * 2) mm.
  EXPECT_NEAR(f.footprint[1], std::sqrt(0.001 * 0.002), 1e-7);
  // Cell 0: right neighbour 1 mm, no row neighbour (cell 3 empty) -> scan median row spacing 2 mm.
  EXPECT_NEAR(f.footprint[0], std::sqrt(0.001 * 0.002), 1e-7);
  ASSERT_EQ(f.confidence.size(), 6u);
  EXPECT_FLOAT_EQ(f.confidence[1], 0.5f);
}

void load_all(const fs::path& dir) {
  const auto src = open_input(dir, {});
  for (std::size_t i = 0; i < src->size(); ++i) src->load(i);
}
std::string replaced(std::string s, const std::string& a, const std::string& b) {
  s.replace(s.find(a), a.size(), b);
  return s;
}

TEST(InputRangeGrid, BadInput) {
  const fs::path dir = test::scratch_dir("rangegrid_bad");
  write_text(dir / "s.conf", "bmesh s.ply 0 0 0 0 0 0 1\n");
  write_text(dir / "s.ply", replaced(small_scan(), "element range_grid 6", "element range_grid 7"));
  expect_input_error([&] { load_all(dir); }, "s.ply", "num_cols x num_rows is 6");
  write_text(dir / "s.ply", replaced(small_scan(), "1 4\n", "1 9\n"));
  expect_input_error([&] { load_all(dir); }, "s.ply", "refers to vertex 9");
  write_text(dir / "s.ply", replaced(small_scan(), "1 4\n", "2 3 4\n"));
  expect_input_error([&] { load_all(dir); }, "s.ply", "0 or 1");
  write_text(dir / "s.ply", small_scan().substr(0, small_scan().size() - 8));
  expect_input_error([&] { load_all(dir); }, "s.ply", "file ends early");
  write_text(dir / "s.ply", replaced(small_scan(), "element vertex 5", "element vertex 500000000"));
  expect_input_error([&] { load_all(dir); }, "s.ply", "more than the file can hold");
  write_text(dir / "s.ply", replaced(small_scan(), "format ascii 1.0", "format binary_little_endian 1.0"));
  expect_input_error([&] { load_all(dir); }, "s.ply", "ASCII");
  write_text(dir / "s.ply", replaced(small_scan(), "obj_info num_cols 3\n", ""));
  expect_input_error([&] { load_all(dir); }, "s.ply", "num_cols");
  write_text(dir / "s.ply", replaced(small_scan(), "0.001 0 0.01 0.5", "0.001 nan 0.01 0.5"));
  expect_input_error([&] { load_all(dir); }, "s.ply", "vertex 1");
  write_text(dir / "s.ply", small_scan());
  write_text(dir / "s.conf", "bmesh s.ply 0 0 0 0 0 0 2\n");
  expect_input_error([&] { open_input(dir, {}); }, "s.conf", "unit length");
  write_text(dir / "s.conf", "bmesh s.ply 0 0 0 0 0 1\n");
  expect_input_error([&] { open_input(dir, {}); }, "s.conf", "expected bmesh");
  write_text(dir / "s.conf", "bmesh missing.ply 0 0 0 0 0 0 1\n");
  expect_input_error([&] { open_input(dir, {}); }, "s.conf", "missing.ply");
}

// --- the real bunny scans against bun_zipper.ply (same world frame).

struct RefMesh {
  std::vector<Eigen::Vector3d> vertices, normals;  // area-weighted vertex normals, outward
};

// Minimal ASCII PLY reader for bun_zipper.ply: x y z first among the vertex properties, faces as
// "3 a b c".
RefMesh read_zipper(const fs::path& path) {
  std::ifstream in(path);
  std::string line;
  std::size_t nv = 0, nf = 0, nprops = 0;
  bool in_vertex = false;
  while (std::getline(in, line) && line.rfind("end_header", 0) != 0) {
    std::istringstream ls(line);
    std::string a, b;
    ls >> a >> b;
    if (a == "element") {
      in_vertex = b == "vertex";
      (b == "vertex" ? nv : nf) = std::stoul(line.substr(line.rfind(' ') + 1));
    } else if (a == "property" && in_vertex) {
      ++nprops;
    }
  }
  RefMesh m;
  m.vertices.resize(nv);
  m.normals.assign(nv, Eigen::Vector3d::Zero());
  for (auto& v : m.vertices) {
    in >> v.x() >> v.y() >> v.z();
    double skip;
    for (std::size_t k = 3; k < nprops; ++k) in >> skip;
  }
  for (std::size_t i = 0; i < nf; ++i) {
    int n, a, b, c;
    in >> n >> a >> b >> c;
    const Eigen::Vector3d nrm = (m.vertices[b] - m.vertices[a]).cross(m.vertices[c] - m.vertices[a]);
    for (int k : {a, b, c}) m.normals[k] += nrm;
  }
  for (auto& n : m.normals) n.normalize();
  return m;
}

// Uniform hash grid for nearest-vertex queries within one cell's reach.
class NearestVertex {
 public:
  NearestVertex(const std::vector<Eigen::Vector3d>& pts, double cell) : pts_(pts), cell_(cell) {
    for (std::size_t i = 0; i < pts.size(); ++i) cells_[key(pts[i])].push_back(i);
  }
  // Index of the nearest vertex within `cell`, or -1.
  long find(const Eigen::Vector3d& p) const {
    long best = -1;
    double best_d = cell_ * cell_;
    const Eigen::Vector3i c = coords(p);
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto it = cells_.find(hash(c + Eigen::Vector3i(dx, dy, dz)));
          if (it == cells_.end()) continue;
          for (std::size_t i : it->second) {
            const double d = (pts_[i] - p).squaredNorm();
            if (d < best_d) best_d = d, best = long(i);
          }
        }
    return best;
  }

 private:
  Eigen::Vector3i coords(const Eigen::Vector3d& p) const { return (p / cell_).array().floor().cast<int>(); }
  static std::int64_t hash(const Eigen::Vector3i& c) {
    return (std::int64_t(c.x() + 100000) * 200000 + (c.y() + 100000)) * 200000 + (c.z() + 100000);
  }
  std::int64_t key(const Eigen::Vector3d& p) const { return hash(coords(p)); }
  const std::vector<Eigen::Vector3d>& pts_;
  double cell_;
  std::unordered_map<std::int64_t, std::vector<std::size_t>> cells_;
};

double median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

TEST(InputRangeGrid, BunnyScansMatchTheZipperedMesh) {
  const fs::path data = test::shared_data() / "stanford_bunny";
  const RefMesh ref = read_zipper(data / "reconstruction/bun_zipper.ply");
  ASSERT_EQ(ref.vertices.size(), 35947u);
  const NearestVertex nearest(ref.vertices, 0.005);
  const auto src = open_input(data / "scans", {});
  ASSERT_EQ(src->size(), 10u);
  for (std::size_t s = 0; s < src->size(); ++s) {
    const DepthFrame f = src->load(s);
    const std::string name = fs::path(src->frame_name(s)).filename().string();
    SCOPED_TRACE(name);
    EXPECT_EQ(f.width, 512);
    EXPECT_EQ(f.height, 400);
    ASSERT_GT(f.valid_count(), 30000u);
    const Eigen::Vector3d axis = f.sensor.axis();
    std::vector<double> dist, footprint;
    std::size_t facing = 0, near = 0;
    for (std::size_t i = 0; i < f.size(); ++i) {
      if (!f.valid[i]) continue;
      footprint.push_back(f.footprint[i]);
      const Eigen::Vector3d p = f.position[i].cast<double>();
      const long k = nearest.find(p);
      dist.push_back(k < 0 ? 1.0 : (ref.vertices[k] - p).norm());
      // Vertices in no face (bun_zipper has some) carry no orientation.
      if (k < 0 || (ref.vertices[k] - p).norm() > 0.002 || ref.normals[k].isZero()) continue;
      ++near;
      // The scanned side faces the sensor: outward normals point against the viewing direction.
      if (ref.normals[k].dot(axis) < 0) ++facing;
    }
    const double med = median(dist), med_fp = median(footprint);
    std::printf("%-13s %6zu samples: median distance %.2f mm, facing %.1f%%, median footprint %.3f mm\n",
                name.c_str(), footprint.size(), med * 1e3, 100.0 * facing / near, med_fp * 1e3);
    EXPECT_LE(med, 0.001);
    EXPECT_GT(double(facing) / near, 0.98);  // measured 99.9%; the opposite sign gives ~0.1%
    EXPECT_GT(med_fp, 0.0005);
    EXPECT_LT(med_fp, 0.0009);
    // Depths along the axis are positive (the sensor plane is in front of the scan).
    for (std::size_t i = 0; i < f.size(); ++i) {
      if (!f.valid[i]) continue;
      ASSERT_GT((f.sensor.R * f.position[i].cast<double>() + f.sensor.t).z(), 0);
    }
  }
}

}  // namespace
}  // namespace sf
