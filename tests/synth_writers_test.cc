// The scene writers: every format's files parsed back by hand (exact headers and sizes), then read
// with engine/input's readers, whose points must lie on the reference surface.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "engine/error.h"
#include "engine/input/frame_source.h"
#include "engine/input/image_io.h"
#include "engine/meshio/ply_io.h"
#include "engine/synth/mesh_query.h"
#include "engine/synth/scene_writer.h"
#include "engine/synth/shapes.h"
#include "engine/synth/synth.h"
#include "tests/test_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  EXPECT_TRUE(in.good()) << p;
  return std::string((std::istreambuf_iterator<char>(in)), {});
}

template <typename T>
T at(const std::string& s, std::size_t offset) {
  T v;
  std::memcpy(&v, s.data() + offset, sizeof(T));
  return v;
}

std::vector<std::string> lines(const std::string& s) {
  std::vector<std::string> out;
  std::istringstream in(s);
  std::string l;
  while (std::getline(in, l)) out.push_back(l);
  return out;
}

// A small scene on a sphere: 3 far views 40x30, 2 close views 64x48 (or all 64x48 for RGB-D).
SyntheticScene small_scene(bool uniform) {
  SynthOptions o;
  o.far_views = 3;
  o.far_width = 40;
  o.far_height = 30;
  o.close_views = 2;
  o.close_width = 64;
  o.close_height = 48;
  o.footprint_ratio = 4;
  o.uniform_resolution = uniform;
  return render_scene(make_sphere(Eigen::Vector3d(1, 2, 3), 0.5, 4), o);
}

// Reads the scene back with open_input and checks every valid sample against the reference.
void check_with_reader(const fs::path& dir, const SyntheticScene& scene, const std::string& format, double tol) {
  InputOptions io;
  const auto source = open_input(dir, io);
  ASSERT_EQ(source->format(), format);
  ASSERT_EQ(source->size(), scene.views.size());
  const MeshQuery ref(scene.reference);
  for (std::size_t i = 0; i < source->size(); ++i) {
    const DepthFrame f = source->load(i);
    const SynthView* view = nullptr;  // readers may sort frames by file name
    for (const auto& v : scene.views)
      if (f.width == v.width && f.height == v.height && (f.sensor.centre() - v.sensor.centre()).norm() < 1e-5) view = &v;
    ASSERT_NE(view, nullptr) << f.name;
    EXPECT_EQ(f.valid_count(), view->valid_pixels) << f.name;
    EXPECT_NEAR(f.sensor.fx, view->sensor.fx, 1e-9);
    EXPECT_NEAR(f.sensor.cx, view->sensor.cx, 1e-9);
    EXPECT_NEAR(f.sensor.cy, view->sensor.cy, 1e-9);
    double worst = 0;
    for (std::size_t k = 0; k < f.size(); ++k)
      if (f.valid[k]) worst = std::max(worst, std::sqrt(ref.squared_distance(f.position[k].cast<double>())));
    EXPECT_LT(worst, tol) << f.name;
  }
}

TEST(SynthWriters, ColmapText) {
  const SyntheticScene scene = small_scene(false);
  const fs::path dir = test::scratch_dir("synth_colmap_text");
  SceneWriteOptions o;
  o.format = SceneFormat::Colmap;
  const WrittenScene w = write_scene(scene, dir, o);
  EXPECT_EQ(w.frames, 5u);
  EXPECT_EQ(w.files.back(), dir / "synth.json");

  const auto cams = lines(slurp(dir / "sparse" / "cameras.txt"));
  const auto imgs = lines(slurp(dir / "sparse" / "images.txt"));
  ASSERT_EQ(cams.size(), 3u + 5u);
  ASSERT_EQ(imgs.size(), 4u + 2 * 5u);
  for (std::size_t i = 0; i < 5; ++i) {
    const SynthView& v = scene.views[i];
    std::istringstream c(cams[3 + i]);
    int id, w_, h_;
    std::string model;
    double fx, fy, cx, cy;
    c >> id >> model >> w_ >> h_ >> fx >> fy >> cx >> cy;
    EXPECT_EQ(id, int(i + 1));
    EXPECT_EQ(model, "PINHOLE");
    EXPECT_EQ(w_, v.width);
    EXPECT_EQ(h_, v.height);
    EXPECT_DOUBLE_EQ(fx, v.sensor.fx);
    EXPECT_DOUBLE_EQ(cx, v.sensor.cx);  // COLMAP also centres pixels at +0.5
    EXPECT_DOUBLE_EQ(cy, v.sensor.cy);
    std::istringstream im(imgs[4 + 2 * i]);
    double qw, qx, qy, qz, tx, ty, tz;
    int cam;
    std::string name;
    im >> id >> qw >> qx >> qy >> qz >> tx >> ty >> tz >> cam >> name;
    EXPECT_EQ(cam, int(i + 1));
    EXPECT_EQ(name, v.name + ".png");
    EXPECT_TRUE(imgs[5 + 2 * i].empty());  // no 2D points
    const Eigen::Matrix3d R = Eigen::Quaterniond(qw, qx, qy, qz).toRotationMatrix();
    EXPECT_TRUE(R.isApprox(v.sensor.R, 1e-12));
    EXPECT_TRUE(Eigen::Vector3d(tx, ty, tz).isApprox(v.sensor.t, 1e-12));

    // Depth map: "W&H&1&" then W*H float32, row-major z-depth.
    const std::string dm = slurp(dir / "stereo" / "depth_maps" / (v.name + ".png.geometric.bin"));
    const std::string header = std::to_string(v.width) + "&" + std::to_string(v.height) + "&1&";
    ASSERT_EQ(dm.substr(0, header.size()), header);
    ASSERT_EQ(dm.size(), header.size() + 4 * v.size());
    for (std::size_t k = 0; k < v.size(); k += 7) ASSERT_EQ(at<float>(dm, header.size() + 4 * k), v.depth[k]);
    EXPECT_EQ(dm, slurp(dir / "stereo" / "depth_maps" / (v.name + ".png.photometric.bin")));
    // Normal map: 3 slices, unit normals facing the camera (negative z in the camera frame).
    const std::string nm = slurp(dir / "stereo" / "normal_maps" / (v.name + ".png.geometric.bin"));
    const std::string nh = std::to_string(v.width) + "&" + std::to_string(v.height) + "&3&";
    ASSERT_EQ(nm.size(), nh.size() + 12 * v.size());
    for (std::size_t k = 0; k < v.size(); ++k) {
      if (!(v.depth[k] > 0)) continue;
      const Eigen::Vector3f n(at<float>(nm, nh.size() + 4 * k), at<float>(nm, nh.size() + 4 * (v.size() + k)),
                              at<float>(nm, nh.size() + 4 * (2 * v.size() + k)));
      ASSERT_NEAR(n.norm(), 1.0, 1e-4);
      ASSERT_LE(n.z(), 0);
    }
    const Image8 png = read_image_rgb(dir / "images" / (v.name + ".png"));
    EXPECT_EQ(png.width, v.width);
    EXPECT_EQ(png.data[3 * 100 + 1], v.colour[100][1]);
  }
  EXPECT_EQ(lines(slurp(dir / "sparse" / "points3D.txt")).size(), 3u);
  EXPECT_EQ(lines(slurp(dir / "stereo" / "fusion.cfg")).size(), 5u);
  check_with_reader(dir, scene, "colmap", 1e-4);
}

TEST(SynthWriters, ColmapBinary) {
  const SyntheticScene scene = small_scene(false);
  const fs::path dir = test::scratch_dir("synth_colmap_bin");
  SceneWriteOptions o;
  o.colmap_binary = true;
  write_scene(scene, dir, o);
  EXPECT_FALSE(fs::exists(dir / "sparse" / "cameras.txt"));
  const std::string cams = slurp(dir / "sparse" / "cameras.bin"), imgs = slurp(dir / "sparse" / "images.bin");
  // cameras.bin: u64 n, then per camera u32 id, i32 model, u64 w, u64 h, 4 doubles.
  ASSERT_EQ(cams.size(), 8u + 5 * (4 + 4 + 8 + 8 + 32));
  ASSERT_EQ(at<std::uint64_t>(cams, 0), 5u);
  std::size_t off = 8, ioff = 8;
  ASSERT_EQ(at<std::uint64_t>(imgs, 0), 5u);
  for (std::size_t i = 0; i < 5; ++i) {
    const SynthView& v = scene.views[i];
    EXPECT_EQ(at<std::uint32_t>(cams, off), i + 1);
    EXPECT_EQ(at<std::int32_t>(cams, off + 4), 1);  // PINHOLE
    EXPECT_EQ(at<std::uint64_t>(cams, off + 8), std::uint64_t(v.width));
    EXPECT_EQ(at<std::uint64_t>(cams, off + 16), std::uint64_t(v.height));
    EXPECT_EQ(at<double>(cams, off + 24), v.sensor.fx);
    EXPECT_EQ(at<double>(cams, off + 48), v.sensor.cy);
    off += 56;
    // images.bin: u32 id, qw qx qy qz tx ty tz doubles, u32 camera id, name\0, u64 #points2D.
    EXPECT_EQ(at<std::uint32_t>(imgs, ioff), i + 1);
    const Eigen::Quaterniond q(at<double>(imgs, ioff + 4), at<double>(imgs, ioff + 12), at<double>(imgs, ioff + 20),
                               at<double>(imgs, ioff + 28));
    EXPECT_TRUE(q.toRotationMatrix().isApprox(v.sensor.R, 1e-12));
    EXPECT_EQ(at<double>(imgs, ioff + 52), v.sensor.t.z());
    EXPECT_EQ(at<std::uint32_t>(imgs, ioff + 60), i + 1);
    const std::string name(imgs.c_str() + ioff + 64);
    EXPECT_EQ(name, v.name + ".png");
    ioff += 64 + name.size() + 1;
    EXPECT_EQ(at<std::uint64_t>(imgs, ioff), 0u);
    ioff += 8;
  }
  EXPECT_EQ(ioff, imgs.size());
  EXPECT_EQ(slurp(dir / "sparse" / "points3D.bin"), std::string(8, '\0'));
  check_with_reader(dir, scene, "colmap", 1e-4);
}

TEST(SynthWriters, MveDepthIsTheRayDistance) {
  const SyntheticScene scene = small_scene(false);
  const fs::path dir = test::scratch_dir("synth_mve");
  SceneWriteOptions o;
  o.format = SceneFormat::Mve;
  write_scene(scene, dir, o);
  for (std::size_t i = 0; i < scene.views.size(); ++i) {
    const SynthView& v = scene.views[i];
    char name[32];
    std::snprintf(name, sizeof name, "view_%04zu.mve", i);
    const fs::path vd = dir / "views" / name;
    // meta.ini: MVE's keys; landscape, so fx = focal_length * width, cx = principal_point.x * width.
    std::map<std::string, std::string> ini;
    std::string section;
    for (const auto& l : lines(slurp(vd / "meta.ini"))) {
      if (l.empty() || l[0] == '#') continue;
      if (l[0] == '[') {
        section = l.substr(1, l.size() - 2);
        continue;
      }
      const auto eq = l.find(" = ");
      ini[section + "." + l.substr(0, eq)] = l.substr(eq + 3);
    }
    EXPECT_NEAR(std::stod(ini.at("camera.focal_length")) * v.width, v.sensor.fx, 1e-9);
    EXPECT_EQ(ini.at("camera.pixel_aspect"), "1");
    std::istringstream pp(ini.at("camera.principal_point"));
    double px, py;
    pp >> px >> py;
    EXPECT_DOUBLE_EQ(px * v.width, v.sensor.cx);
    EXPECT_DOUBLE_EQ(py * v.height, v.sensor.cy);
    std::istringstream rot(ini.at("camera.rotation")), tr(ini.at("camera.translation"));
    Eigen::Matrix3d R;
    for (int k = 0; k < 9; ++k) rot >> R(k / 3, k % 3);
    Eigen::Vector3d t;
    tr >> t[0] >> t[1] >> t[2];
    EXPECT_TRUE(R.isApprox(v.sensor.R, 1e-15));
    EXPECT_TRUE(t.isApprox(v.sensor.t, 1e-15));
    EXPECT_EQ(ini.at("view.id"), std::to_string(i));
    EXPECT_EQ(ini.at("view.name"), v.name);
    EXPECT_EQ(ini.at("camera.radial_distortion"), "0 0");

    // depth-L0.mvei: signature, int32 w h channels type(9 = float), then the floats.
    const std::string d = slurp(vd / "depth-L0.mvei");
    ASSERT_EQ(d.size(), 11u + 16u + 4 * v.size());
    EXPECT_EQ(d.substr(0, 11), std::string("\x89MVE_IMAGE\n", 11));
    EXPECT_EQ(at<std::int32_t>(d, 11), v.width);
    EXPECT_EQ(at<std::int32_t>(d, 15), v.height);
    EXPECT_EQ(at<std::int32_t>(d, 19), 1);
    EXPECT_EQ(at<std::int32_t>(d, 23), 9);
    std::size_t off_axis = 0;
    for (int row = 0; row < v.height; ++row)
      for (int col = 0; col < v.width; ++col) {
        const std::size_t k = std::size_t(row) * v.width + col;
        const float dist = at<float>(d, 27 + 4 * k);
        if (!(v.depth[k] > 0)) {
          ASSERT_EQ(dist, 0.f);
          continue;
        }
        const double x = (col + 0.5 - v.sensor.cx) / v.sensor.fx, y = (row + 0.5 - v.sensor.cy) / v.sensor.fy;
        ASSERT_NEAR(dist, v.depth[k] * std::sqrt(1 + x * x + y * y), 1e-5);
        if (dist > v.depth[k] * 1.01f) ++off_axis;  // larger than z away from the centre
      }
    EXPECT_GT(off_axis, 0u);
    EXPECT_EQ(read_image_rgb(vd / "undistorted.png").height, v.height);
  }
  check_with_reader(dir, scene, "mve", 1e-4);
}

TEST(SynthWriters, Rgbd) {
  const SyntheticScene scene = small_scene(true);
  for (const auto& v : scene.views) EXPECT_EQ(v.width, 64);
  const fs::path dir = test::scratch_dir("synth_rgbd");
  SceneWriteOptions o;
  o.format = SceneFormat::Rgbd;
  const WrittenScene w = write_scene(scene, dir, o);
  EXPECT_EQ(w.rgbd_clipped, 0u);
  // K with integer pixel centres: cx_file = cx - 0.5.
  std::istringstream k(slurp(dir / "camera-intrinsics.txt"));
  double K[9];
  for (double& x : K) k >> x;
  const Sensor& s0 = scene.views[0].sensor;
  EXPECT_DOUBLE_EQ(K[0], s0.fx);
  EXPECT_DOUBLE_EQ(K[2], s0.cx - 0.5);
  EXPECT_DOUBLE_EQ(K[5], s0.cy - 0.5);
  EXPECT_EQ(K[8], 1.0);
  for (std::size_t i = 0; i < scene.views.size(); ++i) {
    const SynthView& v = scene.views[i];
    char stem[32];
    std::snprintf(stem, sizeof stem, "frame-%06zu", i);
    std::istringstream p(slurp(dir / (std::string(stem) + ".pose.txt")));
    Eigen::Matrix4d pose;
    for (int e = 0; e < 16; ++e) p >> pose(e / 4, e % 4);
    // camera-to-world: the inverse of (R, t).
    const Eigen::Matrix3d Rwc = pose.topLeftCorner<3, 3>();
    const Eigen::Vector3d C = pose.topRightCorner<3, 1>();
    EXPECT_TRUE(Rwc.isApprox(v.sensor.R.transpose(), 1e-15));
    EXPECT_TRUE(C.isApprox(v.sensor.centre(), 1e-15));
    EXPECT_EQ(pose.row(3), Eigen::RowVector4d(0, 0, 0, 1));
    const Image16 depth = read_png16(dir / (std::string(stem) + ".depth.png"));
    ASSERT_EQ(depth.width, 64);
    for (std::size_t j = 0; j < v.size(); ++j)
      ASSERT_EQ(depth.data[j], v.depth[j] > 0 ? std::uint16_t(std::lround(double(v.depth[j]) / 0.001)) : 0);
    EXPECT_TRUE(fs::exists(dir / (std::string(stem) + ".color.png")));
  }
  check_with_reader(dir, scene, "rgbd", 1.5e-3);  // millimetre quantization

  // RGB-D needs one K: a scene with two resolutions is refused.
  EXPECT_THROW(write_scene(small_scene(false), test::scratch_dir("synth_rgbd_bad"), o), std::invalid_argument);
}

TEST(SynthWriters, SynthJsonAndReference) {
  const SyntheticScene scene = small_scene(false);
  const fs::path dir = test::scratch_dir("synth_json");
  SceneWriteOptions o;
  o.source = "sphere";
  write_scene(scene, dir, o);
  const auto j = nlohmann::json::parse(slurp(dir / "synth.json"));
  EXPECT_EQ(j.at("format"), "colmap");
  EXPECT_EQ(j.at("version"), 1);
  EXPECT_EQ(j.at("source"), "sphere");
  EXPECT_EQ(j.at("cameras").size(), 5u);
  EXPECT_EQ(j.at("cameras")[3].at("kind"), "close");
  EXPECT_EQ(j.at("cameras")[0].at("depth"), "stereo/depth_maps/far_000.png.geometric.bin");
  EXPECT_DOUBLE_EQ(j.at("coarse_footprint").get<double>(), scene.coarse_footprint);
  EXPECT_DOUBLE_EQ(j.at("footprint_ratio").get<double>(), scene.coarse_footprint / scene.fine_footprint);
  EXPECT_DOUBLE_EQ(j.at("normalization").at("scale").get<double>(), scene.scale);
  const SceneInfo info = read_scene_info(dir / "synth.json");
  EXPECT_EQ(info.reference, dir / "reference.ply");
  EXPECT_TRUE(info.focus.isApprox(scene.focus));
  EXPECT_EQ(info.close_radius, scene.close_radius);
  ASSERT_EQ(info.cameras.size(), 5u);
  EXPECT_TRUE(info.cameras[4].sensor.R.isApprox(scene.views[4].sensor.R));
  EXPECT_EQ(info.cameras[4].sensor.cx, scene.views[4].sensor.cx);
  EXPECT_TRUE(info.cameras[4].close);
  const Mesh ref = read_ply_mesh(info.reference);
  EXPECT_EQ(ref.vertices, scene.reference.vertices);
  EXPECT_EQ(ref.faces, scene.reference.faces);

  std::ofstream(dir / "broken.json") << "{\"format\": 1";
  EXPECT_THROW(read_scene_info(dir / "broken.json"), InputError);
  EXPECT_THROW(read_scene_info(dir / "missing.json"), InputError);
}

TEST(SynthWriters, ClearRemovesOnlySceneFiles) {
  const SyntheticScene scene = small_scene(true);
  const fs::path dir = test::scratch_dir("synth_clear");
  std::ofstream(dir / "notes.txt") << "keep me";
  for (SceneFormat f : {SceneFormat::Colmap, SceneFormat::Mve, SceneFormat::Rgbd}) {
    SceneWriteOptions o;
    o.format = f;
    write_scene(scene, dir, o);
  }
  clear_scene_outputs(dir);
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(dir)) left.push_back(e.path().filename().string());
  EXPECT_EQ(left, std::vector<std::string>{"notes.txt"});
}

}  // namespace
}  // namespace sf
