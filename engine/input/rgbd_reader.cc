// RGB-D folder (7-Scenes / tsdf-fusion layout):
//   camera-intrinsics.txt      3x3 K of the depth camera, OpenCV convention (pixel centres at integers)
//   <stem>.depth.png           16-bit depth, rgbd_depth_scale metres per unit; 0 and 65535 = no depth
//   <stem>.pose.txt            4x4 camera-to-world, metres
//   <stem>.color.png|jpg       optional colour
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <system_error>

#include "engine/error.h"
#include "engine/input/file_util.h"
#include "engine/input/image_io.h"
#include "engine/input/readers.h"

namespace sf {
namespace {

namespace fs = std::filesystem;
using namespace input_detail;

constexpr const char* kDepthSuffix = ".depth.png";

std::vector<double> read_numbers(const fs::path& path, std::size_t count) {
  const std::string text = read_file_text(path);
  const auto tok = split_ws(text);
  if (tok.size() != count)
    throw input_error(path.string(), "expected " + std::to_string(count) + " numbers, found " +
                                         std::to_string(tok.size()) + " tokens");
  std::vector<double> v(count);
  for (std::size_t i = 0; i < count; ++i)
    if (!parse_number(tok[i], &v[i]) || !std::isfinite(v[i]))
      throw input_error(path.string(), "bad number \"" + std::string(tok[i]) + "\"");
  return v;
}

struct Intrinsics {
  double fx, fy, cx, cy;
};

Intrinsics read_intrinsics(const fs::path& path) {
  const auto k = read_numbers(path, 9);
  if (k[1] != 0 || k[3] != 0 || k[6] != 0 || k[7] != 0 || k[8] != 1)
    throw input_error(path.string(), "expected a pinhole K [fx 0 cx; 0 fy cy; 0 0 1] without skew");
  if (!(k[0] > 0) || !(k[4] > 0))
    throw input_error(path.string(), "focal length must be positive, got fx=" + std::to_string(k[0]) +
                                         " fy=" + std::to_string(k[4]));
  // OpenCV/7-Scenes put pixel centres at integer coordinates; ours (COLMAP's) at +0.5.
  return {k[0], k[4], k[2] + 0.5, k[5] + 0.5};
}

struct RgbdFrame {
  fs::path depth, pose, colour;  // colour empty when absent or not wanted
};

class RgbdSource final : public FrameSource {
 public:
  RgbdSource(std::vector<RgbdFrame> frames, Intrinsics k, double scale)
      : frames_(std::move(frames)), k_(k), scale_(scale) {}
  std::string format() const override { return "rgbd"; }
  std::size_t size() const override { return frames_.size(); }
  std::string frame_name(std::size_t i) const override { return frames_.at(i).depth.string(); }
  DepthFrame load(std::size_t i) const override;

 private:
  std::vector<RgbdFrame> frames_;
  Intrinsics k_;
  double scale_;
};

// World -> camera from a camera-to-world 4x4. The stored rotation (printed with ~7 digits) is
// snapped to the nearest rotation, since Sensor inverts R by transposing it.
void set_pose(const fs::path& path, Sensor* s) {
  const auto m = read_numbers(path, 16);
  Eigen::Matrix4d T;
  for (int i = 0; i < 16; ++i) T(i / 4, i % 4) = m[i];
  if (T(3, 0) != 0 || T(3, 1) != 0 || T(3, 2) != 0 || T(3, 3) != 1)
    throw input_error(path.string(), "last row of the pose must be 0 0 0 1");
  const Eigen::Matrix3d A = T.topLeftCorner<3, 3>();
  if ((A * A.transpose() - Eigen::Matrix3d::Identity()).norm() > 1e-2 || A.determinant() < 0)
    throw input_error(path.string(), "pose rotation is not a rotation matrix");
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(A, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix3d R_wc = svd.matrixU() * svd.matrixV().transpose();
  s->R = R_wc.transpose();
  s->t = -s->R * T.topRightCorner<3, 1>();
}

DepthFrame RgbdSource::load(std::size_t i) const {
  const RgbdFrame& fr = frames_.at(i);
  const Image16 png = read_png16(fr.depth);
  input_detail::check_depth_size(fr.depth, png.width, png.height);
  DepthFrame f;
  f.name = fr.depth.string();
  f.width = png.width;
  f.height = png.height;
  f.sensor.kind = Sensor::Kind::Perspective;
  f.sensor.fx = k_.fx;
  f.sensor.fy = k_.fy;
  f.sensor.cx = k_.cx;
  f.sensor.cy = k_.cy;
  set_pose(fr.pose, &f.sensor);
  std::vector<float> depth(png.data.size());
  for (std::size_t p = 0; p < depth.size(); ++p) {
    const std::uint16_t d = png.data[p];
    depth[p] = (d == 0 || d == 65535) ? 0.f : float(d * scale_);  // 65535: 7-Scenes' other "no depth"
  }
  fill_perspective_samples(f, depth, /*ray_distance=*/false);
  if (!fr.colour.empty()) {
    // 7-Scenes colour is not registered to depth (different camera, offset of a few pixels): it is
    // good enough for display colours, not for anything geometric.
    const Image8 c = read_image_rgb(fr.colour);
    if (c.width == f.width && c.height == f.height) f.colour = sample_colour(c, f.width, f.height);
  }
  return f;
}

}  // namespace

std::unique_ptr<FrameSource> open_rgbd(const fs::path& folder, const InputOptions& options) {
  options.check();
  const Intrinsics k = read_intrinsics(folder / "camera-intrinsics.txt");
  std::vector<fs::path> depths;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(folder, ec)) {
    const std::string name = e.path().filename().string();
    if (name.size() > std::strlen(kDepthSuffix) && name.ends_with(kDepthSuffix)) depths.push_back(e.path());
  }
  if (depths.empty()) throw input_error(folder.string(), "RGB-D folder without *.depth.png files");
  std::sort(depths.begin(), depths.end());
  std::vector<RgbdFrame> frames;
  for (const fs::path& d : depths) {
    const std::string name = d.filename().string();
    const std::string stem = name.substr(0, name.size() - std::strlen(kDepthSuffix));
    RgbdFrame fr{d, folder / (stem + ".pose.txt"), {}};
    if (!options.skip_bad && !fs::is_regular_file(fr.pose, ec))
      throw input_error(fr.pose.string(), "missing file (every depth map needs its camera-to-world pose)");
    if (options.rgbd_use_colour) {
      for (const char* ext : {".color.png", ".color.jpg"})
        if (fr.colour.empty() && fs::is_regular_file(folder / (stem + ext), ec)) fr.colour = folder / (stem + ext);
    }
    frames.push_back(std::move(fr));
  }
  return std::make_unique<RgbdSource>(std::move(frames), k, options.rgbd_depth_scale);
}

}  // namespace sf
