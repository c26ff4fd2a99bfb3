// COLMAP dense workspace (after image_undistorter + patch_match_stereo):
//   sparse/{cameras,images}.{bin,txt}   (also sparse/0/, or the files in the workspace root)
//   images/<name>                       undistorted colour images
//   stereo/depth_maps/<name>.<geometric|photometric>.bin
//
// Pixel convention. COLMAP's K puts pixel centres at +0.5, like ours, so a depth map W x H made
// from a camera of width x height uses K scaled by (W/width, H/height), principal point included
// (fusion.cc does the same), with no half-pixel shift. COLMAP's PatchMatch and fusion.cc
// back-project depth pixel (col,row) through K^-1 (col, row, 1), i.e. half a pixel off the camera
// model; we follow the camera model, which the sparse model and the images agree with. The
// difference is at most half a pixel footprint.
#include <Eigen/Geometry>
#include <algorithm>
#include <map>
#include <system_error>

#include "engine/error.h"
#include "engine/input/colmap_io.h"
#include "engine/input/file_util.h"
#include "engine/input/image_io.h"
#include "engine/input/readers.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

struct ColmapView {
  ColmapCamera camera;
  ColmapImage image;
  fs::path depth_path, image_path;
};

class ColmapSource final : public FrameSource {
 public:
  explicit ColmapSource(std::vector<ColmapView> views) : views_(std::move(views)) {}
  std::string format() const override { return "colmap"; }
  std::size_t size() const override { return views_.size(); }
  std::string frame_name(std::size_t i) const override { return views_.at(i).depth_path.string(); }
  DepthFrame load(std::size_t i) const override;

 private:
  std::vector<ColmapView> views_;
};

DepthFrame ColmapSource::load(std::size_t i) const {
  const ColmapView& v = views_.at(i);
  const ColmapArray map = read_colmap_array(v.depth_path);
  if (map.channels != 1)
    throw input_error(v.depth_path.string(), "a depth map has 1 channel, found " + std::to_string(map.channels));
  const ColmapCamera& cam = v.camera;
  if (std::uint64_t(map.width) > cam.width || std::uint64_t(map.height) > cam.height)
    throw input_error(v.depth_path.string(), "depth map is " + std::to_string(map.width) + "x" +
                                                 std::to_string(map.height) + ", larger than its camera's image (" +
                                                 std::to_string(cam.width) + "x" + std::to_string(cam.height) + ")");
  input_detail::check_depths(v.depth_path, map.data, map.width);

  DepthFrame f;
  f.name = v.depth_path.string();
  f.width = map.width;
  f.height = map.height;
  const double sx = double(map.width) / double(cam.width), sy = double(map.height) / double(cam.height);
  f.sensor.kind = Sensor::Kind::Perspective;
  f.sensor.fx = cam.fx * sx;
  f.sensor.fy = cam.fy * sy;
  f.sensor.cx = cam.cx * sx;
  f.sensor.cy = cam.cy * sy;
  const Eigen::Quaterniond q(v.image.qvec[0], v.image.qvec[1], v.image.qvec[2], v.image.qvec[3]);
  f.sensor.R = q.normalized().toRotationMatrix();
  f.sensor.t = v.image.tvec;
  fill_perspective_samples(f, map.data, /*ray_distance=*/false);

  std::error_code ec;
  if (fs::is_regular_file(v.image_path, ec)) {
    const Image8 img = read_image_rgb(v.image_path);
    if (std::uint64_t(img.width) != cam.width || std::uint64_t(img.height) != cam.height)
      throw input_error(v.image_path.string(), "image is " + std::to_string(img.width) + "x" +
                                                   std::to_string(img.height) + " but its camera says " +
                                                   std::to_string(cam.width) + "x" + std::to_string(cam.height));
    f.colour = input_detail::sample_colour(img, f.width, f.height);
  }
  return f;
}

// The folder holding cameras.* and images.*: sparse/, sparse/0/ or the workspace root.
fs::path find_model_folder(const fs::path& root) {
  std::error_code ec;
  auto has_model = [&](const fs::path& d) {
    return (fs::is_regular_file(d / "cameras.bin", ec) || fs::is_regular_file(d / "cameras.txt", ec)) &&
           (fs::is_regular_file(d / "images.bin", ec) || fs::is_regular_file(d / "images.txt", ec));
  };
  for (const fs::path& d : {root / "sparse", root / "sparse" / "0", root})
    if (has_model(d)) return d;
  throw input_error(root.string(), "COLMAP workspace without a model: no cameras.{bin,txt} + images.{bin,txt} in "
                                   "sparse/, sparse/0/ or the workspace folder");
}

fs::path pick(const fs::path& dir, const std::string& stem) {
  std::error_code ec;
  // COLMAP itself prefers the binary model when both exist.
  if (fs::is_regular_file(dir / (stem + ".bin"), ec)) return dir / (stem + ".bin");
  return dir / (stem + ".txt");
}

}  // namespace

std::unique_ptr<FrameSource> open_colmap(const fs::path& root, const InputOptions& options) {
  options.check();
  const fs::path model = find_model_folder(root);
  const fs::path cameras_path = pick(model, "cameras"), images_path = pick(model, "images");
  const auto cameras = read_colmap_cameras(cameras_path);
  const auto images = read_colmap_images(images_path);
  std::map<std::uint32_t, ColmapCamera> by_id;
  for (const auto& c : cameras) by_id[c.id] = c;

  const fs::path maps = root / "stereo" / "depth_maps";
  std::vector<ColmapView> views;
  std::error_code ec;
  for (const auto& im : images) {
    const auto cam = by_id.find(im.camera_id);
    if (cam == by_id.end())
      throw input_error(images_path.string(), "image " + std::to_string(im.id) + " (" + im.name +
                                                  ") refers to camera " + std::to_string(im.camera_id) +
                                                  ", which " + cameras_path.filename().string() + " does not list");
    ColmapView v{cam->second, im, maps / (im.name + "." + options.colmap_maps + ".bin"), root / "images" / im.name};
    // Images without a depth map are normal (e.g. filtered out by patch_match_stereo).
    if (fs::is_regular_file(v.depth_path, ec)) views.push_back(std::move(v));
  }
  if (views.empty())
    throw input_error(root.string(), "no " + options.colmap_maps + " depth maps in stereo/depth_maps for the " +
                                         std::to_string(images.size()) + " images of " + images_path.string());
  std::sort(views.begin(), views.end(),
            [](const ColmapView& a, const ColmapView& b) { return a.image.name < b.image.name; });
  return std::make_unique<ColmapSource>(std::move(views));
}

}  // namespace sf
