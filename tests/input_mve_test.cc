// MVE scenes: fixtures written the way MVE writes them (util::write_ini for meta.ini,
// mve::image::save_mvei_file for .mvei).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <sstream>

#include "engine/error.h"
#include "engine/input/frame_source.h"
#include "engine/input/image_io.h"
#include "engine/input/mve_io.h"
#include "tests/test_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

using test::expect_input_error;
using test::write_text;
std::string read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// As util::write_ini: keys sorted, a blank line and "[section]" before each section, "key = value".
void write_meta(const fs::path& view, const std::map<std::string, std::string>& kv) {
  std::ostringstream out;
  std::string last;
  for (const auto& [key, value] : kv) {
    const std::string section = key.substr(0, key.find('.')), name = key.substr(key.find('.') + 1);
    if (section != last) out << "\n[" << section << "]\n";
    last = section;
    out << name << " = " << value << "\n";
  }
  write_text(view / "meta.ini", out.str());
}

// As save_mvei_file: signature, int32 width height channels type, raw interleaved pixels.
template <typename T>
void write_mvei(const fs::path& p, int w, int h, int c, int type, const std::vector<T>& data) {
  std::string s("\x89MVE_IMAGE\n", 11);
  for (std::int32_t v : {std::int32_t(w), std::int32_t(h), std::int32_t(c), std::int32_t(type)})
    s.append(reinterpret_cast<const char*>(&v), 4);
  s.append(reinterpret_cast<const char*>(data.data()), data.size() * sizeof(T));
  write_text(p, s);
}

std::map<std::string, std::string> meta(const std::string& flen, const std::string& paspect = "1") {
  // Camera rotated 90 degrees about z (world -> camera), translation (1, 2, 3).
  return {{"camera.focal_length", flen},
          {"camera.pixel_aspect", paspect},
          {"camera.principal_point", "0.5 0.5"},
          {"camera.radial_distortion", "0 0"},
          {"camera.rotation", "0 -1 0 1 0 0 0 0 1"},
          {"camera.translation", "1 2 3"},
          {"view.id", "0"},
          {"view.name", "IMG_0001"}};
}

// view 0: 8x6 depth, flen 1.25 (fx = fy = 10, cx = 4, cy = 3); one valid sample at (col 5, row 1).
// view 1: no depth. view 2: 8x6 depth, all 2.0.
fs::path make_scene(const std::string& name) {
  const fs::path scene = test::scratch_dir(name);
  const fs::path v0 = scene / "views/view_0000.mve", v1 = scene / "views/view_0001.mve",
                 v2 = scene / "views/view_0002.mve";
  write_meta(v0, meta("1.25"));
  std::vector<float> d(48, 0.f);
  d[1 * 8 + 5] = 3.f;
  write_mvei(v0 / "depth-L0.mvei", 8, 6, 1, 9, d);
  write_meta(v1, meta("1.25"));
  write_meta(v2, meta("1.25"));
  write_mvei(v2 / "depth-L0.mvei", 8, 6, 1, 9, std::vector<float>(48, 2.f));
  return scene;
}

TEST(InputMve, RayDistanceIsConvertedToZ) {
  const fs::path scene = make_scene("mve_basic");
  const auto src = open_input(scene, {});
  EXPECT_EQ(src->format(), "mve");
  ASSERT_EQ(src->size(), 2u);  // view_0001 has no depth
  EXPECT_NE(src->frame_name(1).find("view_0002.mve"), std::string::npos);
  const DepthFrame f = src->load(0);
  EXPECT_DOUBLE_EQ(f.sensor.fx, 10);
  EXPECT_DOUBLE_EQ(f.sensor.fy, 10);
  EXPECT_DOUBLE_EQ(f.sensor.cx, 4);
  EXPECT_DOUBLE_EQ(f.sensor.cy, 3);
  ASSERT_EQ(f.valid_count(), 1u);
  const std::size_t i = 1 * 8 + 5;
  // Pixel centre (5.5, 1.5): ray (0.15, -0.15, 1), |ray| = sqrt(1.045); distance 3 -> z = 3/|ray|.
  const double z = 3.0 / std::sqrt(1.045);
  const Eigen::Vector3d Xc(0.15 * z, -0.15 * z, z);
  // world = R^T (Xc - t) with R = [0 -1 0; 1 0 0; 0 0 1].
  const Eigen::Vector3d d = Xc - Eigen::Vector3d(1, 2, 3);
  const Eigen::Vector3d Xw(d.y(), -d.x(), d.z());
  EXPECT_NEAR(f.position[i].x(), Xw.x(), 1e-5);
  EXPECT_NEAR(f.position[i].y(), Xw.y(), 1e-5);
  EXPECT_NEAR(f.position[i].z(), Xw.z(), 1e-5);
  EXPECT_NEAR(f.footprint[i], z / 10, 1e-6);
  // The distance from the camera centre is the stored value.
  EXPECT_NEAR((f.position[i].cast<double>() - f.sensor.centre()).norm(), 3.0, 1e-5);
  EXPECT_TRUE(f.confidence.empty());
  EXPECT_TRUE(f.colour.empty());
}

TEST(InputMve, CalibrationFollowsFillCalibration) {
  const fs::path p = "meta.ini";
  // Landscape with pixel aspect 2: fx = flen * w, fy = flen * w * paspect.
  Sensor s = mve_sensor(mve_camera(meta("0.5", "2"), p), 40, 10);
  EXPECT_DOUBLE_EQ(s.fx, 20);
  EXPECT_DOUBLE_EQ(s.fy, 40);
  // Portrait: normalised by the height. fx = flen * h / paspect, fy = flen * h.
  s = mve_sensor(mve_camera(meta("0.5"), p), 6, 8);
  EXPECT_DOUBLE_EQ(s.fx, 4);
  EXPECT_DOUBLE_EQ(s.fy, 4);
  EXPECT_DOUBLE_EQ(s.cx, 3);
  EXPECT_DOUBLE_EQ(s.cy, 4);
  auto m = meta("0.5");
  m["camera.principal_point"] = "0.25 0.75";
  s = mve_sensor(mve_camera(m, p), 8, 4);
  EXPECT_DOUBLE_EQ(s.cx, 2);
  EXPECT_DOUBLE_EQ(s.cy, 3);
}

TEST(InputMve, ConfidenceAndColour) {
  const fs::path scene = make_scene("mve_extras");
  const fs::path v0 = scene / "views/view_0000.mve", v2 = scene / "views/view_0002.mve";
  std::vector<float> conf(48, 0.5f);
  conf[13] = 0.25f;
  write_mvei(v0 / "conf-L0.mvei", 8, 6, 1, 9, conf);
  // Colour at twice the depth resolution as PNG for view 0, same size as uint8 .mvei for view 2.
  Image8 big{16, 12, 3, {}};
  for (int r = 0; r < 12; ++r)
    for (int c = 0; c < 16; ++c) big.data.insert(big.data.end(), {std::uint8_t(c), std::uint8_t(r), 9});
  write_png8(v0 / "undistorted.png", big);
  std::vector<std::uint8_t> rgb;
  for (int k = 0; k < 48; ++k) rgb.insert(rgb.end(), {std::uint8_t(k), 1, 2});
  write_mvei(v2 / "undistorted.mvei", 8, 6, 3, 1, rgb);
  const auto src = open_input(scene, {});
  const DepthFrame f0 = src->load(0), f2 = src->load(1);
  ASSERT_EQ(f0.confidence.size(), 48u);
  EXPECT_FLOAT_EQ(f0.confidence[13], 0.25f);
  ASSERT_EQ(f0.colour.size(), 48u);
  EXPECT_EQ(f0.colour[1 * 8 + 5], (Rgb8{11, 3, 9}));  // centre (5.5,1.5) x 2 = (11,3)
  ASSERT_EQ(f2.colour.size(), 48u);
  EXPECT_EQ(f2.colour[20], (Rgb8{20, 1, 2}));
  EXPECT_TRUE(f2.confidence.empty());
}

void load_all(const fs::path& scene) {
  const auto src = open_input(scene, {});
  for (std::size_t i = 0; i < src->size(); ++i) src->load(i);
}

TEST(InputMve, BadDepthFiles) {
  const fs::path scene = make_scene("mve_bad");
  const fs::path depth = scene / "views/view_0002.mve/depth-L0.mvei";
  const std::string good = read_all(depth);
  write_text(depth, good.substr(0, good.size() - 1));
  expect_input_error([&] { load_all(scene); }, "depth-L0.mvei", "truncated");
  write_text(depth, good.substr(0, 15));
  expect_input_error([&] { load_all(scene); }, "depth-L0.mvei", "truncated");
  std::string magic = good;
  magic[1] = 'X';
  write_text(depth, magic);
  expect_input_error([&] { load_all(scene); }, "depth-L0.mvei", "wrong magic");
  write_mvei(depth, 1 << 14, 1 << 14, 1, 9, std::vector<float>(4, 1.f));  // header claims 1 GiB
  expect_input_error([&] { load_all(scene); }, "depth-L0.mvei", "holds");
  write_mvei(depth, 8, 6, 1, 1, std::vector<std::uint8_t>(48, 1));
  expect_input_error([&] { load_all(scene); }, "depth-L0.mvei", "float");
  for (float bad : {std::numeric_limits<float>::quiet_NaN(), -std::numeric_limits<float>::infinity(), -2.f}) {
    std::vector<float> d(48, 1.f);
    d[47] = bad;
    write_mvei(depth, 8, 6, 1, 9, d);
    expect_input_error([&] { load_all(scene); }, "depth-L0.mvei", "col 7, row 5");
  }
}

TEST(InputMve, BadCameraAndSizes) {
  const fs::path scene = make_scene("mve_bad_cam");
  const fs::path v2 = scene / "views/view_0002.mve";
  write_meta(v2, meta("0"));
  expect_input_error([&] { load_all(scene); }, "view_0002.mve/meta.ini", "focal_length must be positive");
  auto m = meta("1");
  m.erase("camera.focal_length");
  write_meta(v2, m);
  expect_input_error([&] { load_all(scene); }, "meta.ini", "no camera");
  m = meta("1");
  m["camera.rotation"] = "1 0 0 0 1 0 0 0 2";
  write_meta(v2, m);
  expect_input_error([&] { load_all(scene); }, "meta.ini", "rotation");
  write_meta(v2, meta("1"));
  write_mvei(v2 / "conf-L0.mvei", 4, 3, 1, 9, std::vector<float>(12, 1.f));
  expect_input_error([&] { load_all(scene); }, "conf-L0.mvei", "the depth map is 8x6");
  fs::remove(v2 / "conf-L0.mvei");
  write_png8(v2 / "undistorted.png", Image8{8, 8, 3, std::vector<std::uint8_t>(192, 1)});
  expect_input_error([&] { load_all(scene); }, "undistorted", "8x8");
  fs::remove(v2 / "undistorted.png");
  fs::remove(v2 / "meta.ini");
  expect_input_error([&] { open_input(scene, {}); }, "view_0002.mve/meta.ini", "missing file");
}

TEST(InputMve, SceneWithoutDepthIsAnError) {
  const fs::path scene = make_scene("mve_empty");
  fs::remove(scene / "views/view_0000.mve/depth-L0.mvei");
  fs::remove(scene / "views/view_0002.mve/depth-L0.mvei");
  expect_input_error([&] { open_input(scene, {}); }, "views", "depth-L0.mvei");
  InputOptions o;
  o.mve_depth = "depth-L1";
  expect_input_error([&] { open_input(make_scene("mve_empty2"), o); }, "views", "depth-L1.mvei");
}

}  // namespace
}  // namespace sf
