// COLMAP dense workspaces: fixtures written the way COLMAP writes them
// (src/colmap/scene/reconstruction_io_{text,binary}.cc, src/colmap/mvs/mat.cc).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>

#include "engine/error.h"
#include "engine/input/colmap_io.h"
#include "engine/input/frame_source.h"
#include "engine/input/image_io.h"
#include "tests/test_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

struct Cam {
  std::uint32_t id;
  std::string model;
  int model_id;
  std::uint64_t width, height;
  std::vector<double> params;
};
struct Img {
  std::uint32_t id;
  double q[4];  // w x y z
  double t[3];
  std::uint32_t camera_id;
  std::string name;
  int num_points2d = 0;
};

using test::expect_input_error;
using test::write_text;
std::string read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}
template <typename T>
void put(std::string& s, T v) {
  s.append(reinterpret_cast<const char*>(&v), sizeof(T));
}

// As WriteCamerasText / WriteImagesText: comment header, precision 17, second line per image
// with the 2D points (empty when there are none).
void write_model_text(const fs::path& dir, const std::vector<Cam>& cams, const std::vector<Img>& imgs) {
  std::ostringstream c;
  c.precision(17);
  c << "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
    << "# Number of cameras: " << cams.size() << "\n";
  for (const auto& cam : cams) {
    c << cam.id << " " << cam.model << " " << cam.width << " " << cam.height;
    for (double p : cam.params) c << " " << p;
    c << "\n";
  }
  write_text(dir / "cameras.txt", c.str());
  std::ostringstream m;
  m.precision(17);
  m << "# Image list with two lines of data per image:\n"
    << "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
    << "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
    << "# Number of images: " << imgs.size() << ", mean observations per image: 1\n";
  for (const auto& im : imgs) {
    m << im.id << " " << im.q[0] << " " << im.q[1] << " " << im.q[2] << " " << im.q[3] << " " << im.t[0] << " "
      << im.t[1] << " " << im.t[2] << " " << im.camera_id << " " << im.name << "\n";
    for (int k = 0; k < im.num_points2d; ++k) m << (k ? " " : "") << 10.5 + k << " " << 20.25 << " " << (k % 2 ? -1 : 7);
    m << "\n";
  }
  write_text(dir / "images.txt", m.str());
}

// As WriteCamerasBinary / WriteImagesBinary.
void write_model_binary(const fs::path& dir, const std::vector<Cam>& cams, const std::vector<Img>& imgs) {
  std::string c;
  put<std::uint64_t>(c, cams.size());
  for (const auto& cam : cams) {
    put<std::uint32_t>(c, cam.id);
    put<std::int32_t>(c, cam.model_id);
    put<std::uint64_t>(c, cam.width);
    put<std::uint64_t>(c, cam.height);
    for (double p : cam.params) put<double>(c, p);
  }
  write_text(dir / "cameras.bin", c);
  std::string m;
  put<std::uint64_t>(m, imgs.size());
  for (const auto& im : imgs) {
    put<std::uint32_t>(m, im.id);
    for (double q : im.q) put<double>(m, q);
    for (double t : im.t) put<double>(m, t);
    put<std::uint32_t>(m, im.camera_id);
    m += im.name;
    m += '\0';
    put<std::uint64_t>(m, std::uint64_t(im.num_points2d));
    for (int k = 0; k < im.num_points2d; ++k) {
      put<double>(m, 10.5 + k);
      put<double>(m, 20.25);
      put<std::uint64_t>(m, k % 2 ? std::numeric_limits<std::uint64_t>::max() : 7);
    }
  }
  write_text(dir / "images.bin", m);
}

// As Mat<float>::Write.
void write_map(const fs::path& p, int w, int h, int c, const std::vector<float>& data) {
  std::string s = std::to_string(w) + "&" + std::to_string(h) + "&" + std::to_string(c) + "&";
  s.append(reinterpret_cast<const char*>(data.data()), data.size() * sizeof(float));
  write_text(p, s);
}

// The scene used by most tests: camera 1 is PINHOLE 8x6 (fx 10, fy 12, cx 4, cy 3); image
// "b.png" (id 5) looks through it rotated 90 degrees about z, t = (1, 2, 3), and has a 4x3
// (half-size) geometric depth map. Image "a.png" (id 2) has a full-size map, "c.png" (id 9) none.
const double kS = std::sqrt(0.5);
std::vector<Cam> cams() {
  return {{1, "PINHOLE", 1, 8, 6, {10, 12, 4, 3}}, {3, "SIMPLE_PINHOLE", 0, 8, 6, {9, 4, 3}}};
}
std::vector<Img> imgs() {
  return {{5, {kS, 0, 0, kS}, {1, 2, 3}, 1, "b.png", 3},
          {2, {1, 0, 0, 0}, {0, 0, 0}, 3, "a.png", 0},
          {9, {1, 0, 0, 0}, {0, 0, 0}, 1, "c.png", 2}};
}
std::vector<float> b_depth() {
  std::vector<float> d(12, 0.f);
  d[2 * 4 + 1] = 2.f;  // (col 1, row 2)
  d[0] = 1.f;
  return d;
}

fs::path make_workspace(const std::string& name, bool binary, const fs::path& model_sub = "sparse") {
  const fs::path ws = test::scratch_dir(name);
  if (binary)
    write_model_binary(ws / model_sub, cams(), imgs());
  else
    write_model_text(ws / model_sub, cams(), imgs());
  write_map(ws / "stereo/depth_maps/b.png.geometric.bin", 4, 3, 1, b_depth());
  write_map(ws / "stereo/depth_maps/b.png.photometric.bin", 4, 3, 1, std::vector<float>(12, 5.f));
  write_map(ws / "stereo/depth_maps/a.png.geometric.bin", 8, 6, 1, std::vector<float>(48, 1.5f));
  write_map(ws / "stereo/normal_maps/b.png.geometric.bin", 4, 3, 3, std::vector<float>(36, 0.f));
  return ws;
}

void expect_near(const Eigen::Vector3f& a, const Eigen::Vector3d& b, double tol = 1e-5) {
  EXPECT_NEAR(a.x(), b.x(), tol);
  EXPECT_NEAR(a.y(), b.y(), tol);
  EXPECT_NEAR(a.z(), b.z(), tol);
}

void check_b_frame(const DepthFrame& f) {
  ASSERT_EQ(f.width, 4);
  ASSERT_EQ(f.height, 3);
  // K scaled by the map size: 4/8 and 3/6. Principal point scaled the same way (corner origin).
  EXPECT_DOUBLE_EQ(f.sensor.fx, 5);
  EXPECT_DOUBLE_EQ(f.sensor.fy, 6);
  EXPECT_DOUBLE_EQ(f.sensor.cx, 2);
  EXPECT_DOUBLE_EQ(f.sensor.cy, 1.5);
  EXPECT_EQ(f.valid_count(), 2u);
  const std::size_t i = 2 * 4 + 1;
  ASSERT_TRUE(f.valid[i]);
  // Pixel centre (1.5, 2.5), z = 2: camera point ((1.5-2)/5*2, (2.5-1.5)/6*2, 2) = (-0.2, 1/3, 2).
  // R = Rz(90) = [0 -1 0; 1 0 0; 0 0 1], world = R^T (Xc - t) = R^T (-1.2, -5/3, -1) = (-5/3, 1.2, -1).
  expect_near(f.position[i], Eigen::Vector3d(-5.0 / 3.0, 1.2, -1.0));
  EXPECT_NEAR(f.footprint[i], 2.0 / std::sqrt(30.0), 1e-6);
  EXPECT_FLOAT_EQ(f.image_pos[i].x(), 1.5f);
  EXPECT_FLOAT_EQ(f.image_pos[i].y(), 2.5f);
  // And the sensor projects it back to that pixel centre.
  Eigen::Vector2d uv;
  ASSERT_TRUE(f.sensor.project(f.position[i].cast<double>(), &uv));
  EXPECT_NEAR(uv.x(), 1.5, 1e-5);
  EXPECT_NEAR(uv.y(), 2.5, 1e-5);
}

TEST(InputColmap, TextModelHandWorkedPixel) {
  const fs::path ws = make_workspace("colmap_text", false);
  const auto src = open_input(ws, InputOptions{});
  EXPECT_EQ(src->format(), "colmap");
  // c.png has no depth map; frames sorted by image name.
  ASSERT_EQ(src->size(), 2u);
  EXPECT_EQ(fs::path(src->frame_name(0)).filename(), "a.png.geometric.bin");
  EXPECT_EQ(fs::path(src->frame_name(1)).filename(), "b.png.geometric.bin");
  check_b_frame(src->load(1));
  const DepthFrame a = src->load(0);
  EXPECT_DOUBLE_EQ(a.sensor.fx, 9);  // SIMPLE_PINHOLE, full-size map: unscaled
  EXPECT_DOUBLE_EQ(a.sensor.fy, 9);
  EXPECT_DOUBLE_EQ(a.sensor.cx, 4);
  EXPECT_EQ(a.valid_count(), 48u);
  EXPECT_TRUE(a.colour.empty());  // no images/ folder: no colour, no error
}

TEST(InputColmap, BinaryModelMatchesText) {
  const fs::path ws_txt = make_workspace("colmap_t2", false), ws_bin = make_workspace("colmap_b2", true);
  const auto a = open_input(ws_txt, {}), b = open_input(ws_bin, {});
  ASSERT_EQ(b->size(), 2u);
  check_b_frame(b->load(1));
  const DepthFrame ft = a->load(1), fb = b->load(1);
  EXPECT_TRUE(ft.sensor.R.isApprox(fb.sensor.R, 1e-15));
  EXPECT_EQ(ft.position, fb.position);
}

TEST(InputColmap, ModelInSparse0OrRoot) {
  for (const fs::path& sub : {fs::path("sparse/0"), fs::path(".")}) {
    const fs::path ws = make_workspace("colmap_sub", true, sub);
    const auto src = open_input(ws, InputOptions{});
    ASSERT_EQ(src->size(), 2u);
    check_b_frame(src->load(1));
  }
}

TEST(InputColmap, PhotometricMapsOption) {
  const fs::path ws = make_workspace("colmap_photo", false);
  InputOptions o;
  o.colmap_maps = "photometric";
  const auto src = open_input(ws, o);
  ASSERT_EQ(src->size(), 1u);  // only b.png has a photometric map
  const DepthFrame f = src->load(0);
  EXPECT_EQ(f.valid_count(), 12u);
  EXPECT_NEAR(f.footprint[0], 5.0 / std::sqrt(30.0), 1e-6);
}

TEST(InputColmap, ColourIsSampledNearestWhenTheMapIsSmaller) {
  const fs::path ws = make_workspace("colmap_colour", false);
  Image8 img{8, 6, 3, {}};
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 8; ++c) img.data.insert(img.data.end(), {std::uint8_t(c), std::uint8_t(r), 77});
  fs::create_directories(ws / "images");
  write_png8(ws / "images/b.png", img);
  const DepthFrame f = open_input(ws, {})->load(1);
  ASSERT_EQ(f.colour.size(), 12u);
  // Depth pixel (1,2) has its centre at (1.5,2.5) x 2 = (3,5) in the image: pixel (3,5).
  EXPECT_EQ(f.colour[2 * 4 + 1], (Rgb8{3, 5, 77}));
  EXPECT_EQ(f.colour[0], (Rgb8{1, 1, 77}));
}

// --- bad input: every case is one InputError naming the file.


void load_all(const fs::path& ws) {
  const auto src = open_input(ws, {});
  for (std::size_t i = 0; i < src->size(); ++i) src->load(i);
}

TEST(InputColmap, UnknownOrDistortedCameraModel) {
  {
    const fs::path ws = make_workspace("colmap_bad_model_t", false);
    auto c = cams();
    c[0] = {1, "OPENCV", 4, 8, 6, {10, 12, 4, 3, 0.1, 0, 0, 0}};
    write_model_text(ws / "sparse", c, imgs());
    expect_input_error([&] { load_all(ws); }, "cameras.txt", "undistorted");
    c[0].model = "NOT_A_MODEL";
    write_model_text(ws / "sparse", c, imgs());
    expect_input_error([&] { load_all(ws); }, "cameras.txt", "unknown camera model");
  }
  {
    const fs::path ws = make_workspace("colmap_bad_model_b", true);
    auto c = cams();
    c[1] = {3, "SIMPLE_RADIAL", 2, 8, 6, {9, 4, 3, 0.01}};
    write_model_binary(ws / "sparse", c, imgs());
    expect_input_error([&] { load_all(ws); }, "cameras.bin", "SIMPLE_RADIAL");
  }
}

TEST(InputColmap, NonPositiveFocalLength) {
  const fs::path ws = make_workspace("colmap_focal", true);
  auto c = cams();
  c[0].params[1] = 0;
  write_model_binary(ws / "sparse", c, imgs());
  expect_input_error([&] { load_all(ws); }, "cameras.bin", "focal length");
  c[0].params[1] = -3;
  write_model_text(ws / "sparse", c, imgs());
  fs::remove(ws / "sparse/cameras.bin");
  expect_input_error([&] { load_all(ws); }, "cameras.txt", "focal length");
}

TEST(InputColmap, DuplicateIds) {
  const fs::path ws = make_workspace("colmap_dup", false);
  auto im = imgs();
  im[1].id = 5;
  write_model_text(ws / "sparse", cams(), im);
  expect_input_error([&] { load_all(ws); }, "images.txt", "duplicate image id 5");
  write_model_binary(ws / "sparse", cams(), im);
  expect_input_error([&] { load_all(ws); }, "images.bin", "duplicate image id 5");
  auto c = cams();
  c[1].id = 1;
  write_model_binary(ws / "sparse", c, imgs());
  expect_input_error([&] { load_all(ws); }, "cameras.bin", "duplicate camera id 1");
}

TEST(InputColmap, ImageWithUnknownCamera) {
  const fs::path ws = make_workspace("colmap_nocam", false);
  auto im = imgs();
  im[0].camera_id = 42;
  write_model_text(ws / "sparse", cams(), im);
  expect_input_error([&] { load_all(ws); }, "images.txt", "camera 42");
}

TEST(InputColmap, TruncatedOrOversizedBinaryModel) {
  const fs::path ws = make_workspace("colmap_trunc", true);
  const std::string images = read_all(ws / "sparse/images.bin");
  write_text(ws / "sparse/images.bin", images.substr(0, images.size() - 5));
  expect_input_error([&] { load_all(ws); }, "images.bin", "truncated");
  // A count of 2^60 images must fail on the size check, not by allocating.
  std::string huge = images;
  const std::uint64_t n = std::uint64_t(1) << 60;
  std::memcpy(huge.data(), &n, 8);
  write_text(ws / "sparse/images.bin", huge);
  expect_input_error([&] { load_all(ws); }, "images.bin", "more than the file can hold");
  write_text(ws / "sparse/images.bin", images);
  const std::string cameras = read_all(ws / "sparse/cameras.bin");
  write_text(ws / "sparse/cameras.bin", cameras.substr(0, cameras.size() - 8));
  expect_input_error([&] { load_all(ws); }, "cameras.bin", "truncated");
}

TEST(InputColmap, BadDepthMaps) {
  const fs::path ws = make_workspace("colmap_bad_depth", false);
  const fs::path map = ws / "stereo/depth_maps/b.png.geometric.bin";
  const std::string good = read_all(map);
  write_text(map, good.substr(0, good.size() - 3));
  expect_input_error([&] { load_all(ws); }, "b.png.geometric.bin", "truncated");
  write_text(map, "PK\x03\x04garbage");
  expect_input_error([&] { load_all(ws); }, "b.png.geometric.bin", "header");
  write_text(map, "100000&100000&1&" + good.substr(6));
  expect_input_error([&] { load_all(ws); }, "b.png.geometric.bin", "holds");
  for (float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(), -1.f}) {
    auto d = b_depth();
    d[5] = bad;
    write_map(map, 4, 3, 1, d);
    expect_input_error([&] { load_all(ws); }, "b.png.geometric.bin", "row 1");
  }
  // A map larger than the camera's image.
  write_map(map, 16, 12, 1, std::vector<float>(16 * 12, 1.f));
  expect_input_error([&] { load_all(ws); }, "b.png.geometric.bin", "larger than");
  // A colour image of the wrong size.
  write_map(map, 4, 3, 1, b_depth());
  fs::create_directories(ws / "images");
  write_png8(ws / "images/b.png", Image8{5, 5, 3, std::vector<std::uint8_t>(75, 1)});
  expect_input_error([&] { load_all(ws); }, "images/b.png", "camera says 8x6");
}

TEST(InputColmap, NoDepthMapsIsAnError) {
  const fs::path ws = make_workspace("colmap_empty", false);
  fs::remove_all(ws / "stereo/depth_maps");
  fs::create_directories(ws / "stereo/depth_maps");
  expect_input_error([&] { open_input(ws, {}); }, ws.string(), "no geometric depth maps");
  fs::remove_all(ws / "sparse");
  fs::remove(ws / "cameras.txt");
  expect_input_error([&] { open_input(ws, {}); }, ws.string(), "without a model");
}

}  // namespace
}  // namespace sf
