// MVE scene: views/view_NNNN.mve/{meta.ini, <depth>.mvei, [<confidence>.mvei], [<image>.png|jpg|mvei]}.
// MVE depth maps hold the distance from the centre of projection along each pixel's ray, not z.
#include <algorithm>
#include <cmath>
#include <system_error>

#include "engine/error.h"
#include "engine/input/file_util.h"
#include "engine/input/image_io.h"
#include "engine/input/mve_io.h"
#include "engine/input/readers.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

struct MveView {
  fs::path dir, depth_path;
};

class MveSource final : public FrameSource {
 public:
  MveSource(std::vector<MveView> views, InputOptions options) : views_(std::move(views)), options_(std::move(options)) {}
  std::string format() const override { return "mve"; }
  std::size_t size() const override { return views_.size(); }
  std::string frame_name(std::size_t i) const override { return views_.at(i).depth_path.string(); }
  DepthFrame load(std::size_t i) const override;

 private:
  std::vector<MveView> views_;
  InputOptions options_;
};

// The colour embedding as RGB, or an empty image when the view has none.
Image8 read_colour(const fs::path& dir, const std::string& name) {
  std::error_code ec;
  for (const char* ext : {".png", ".jpg", ".jpeg"})
    if (fs::is_regular_file(dir / (name + ext), ec)) return read_image_rgb(dir / (name + ext));
  const fs::path mvei = dir / (name + ".mvei");
  if (!fs::is_regular_file(mvei, ec)) return {};
  MveImage im = read_mvei(mvei);
  if (im.type != 1 || (im.channels != 1 && im.channels != 3 && im.channels != 4))
    throw input_error(mvei.string(), "a colour image must be uint8 with 1, 3 or 4 channels, found type " +
                                         std::to_string(im.type) + " with " + std::to_string(im.channels) +
                                         " channels");
  return Image8{im.width, im.height, im.channels, std::move(im.bytes)};
}

DepthFrame load_view(const MveView& v, const InputOptions& options) {
  const fs::path meta = v.dir / "meta.ini";
  const MveCamera cam = mve_camera(read_mve_ini(meta), meta);
  const MveImage dm = read_mvei(v.depth_path);
  if (dm.type != 9 || dm.channels != 1)
    throw input_error(v.depth_path.string(), "a depth map must be a 1-channel float MVE image, found type " +
                                                 std::to_string(dm.type) + " with " + std::to_string(dm.channels) +
                                                 " channels");
  const std::vector<float> depth = mvei_channel0_as_float(dm, v.depth_path);
  input_detail::check_depths(v.depth_path, depth, dm.width);

  DepthFrame f;
  f.name = v.depth_path.string();
  f.width = dm.width;
  f.height = dm.height;
  // The camera is normalised, so K follows from the depth map's own size, whatever its level.
  f.sensor = mve_sensor(cam, f.width, f.height);
  fill_perspective_samples(f, depth, /*ray_distance=*/true);

  std::error_code ec;
  const fs::path conf_path = v.dir / (options.mve_confidence + ".mvei");
  if (fs::is_regular_file(conf_path, ec)) {
    const MveImage ci = read_mvei(conf_path);
    if (ci.width != f.width || ci.height != f.height || ci.channels != 1)
      throw input_error(conf_path.string(), "confidence is " + std::to_string(ci.width) + "x" +
                                                std::to_string(ci.height) + "x" + std::to_string(ci.channels) +
                                                ", the depth map is " + std::to_string(f.width) + "x" +
                                                std::to_string(f.height) + "x1");
    f.confidence = mvei_channel0_as_float(ci, conf_path);
    for (std::size_t i = 0; i < f.confidence.size(); ++i) {
      if (!std::isfinite(f.confidence[i]) || f.confidence[i] < 0)
        throw input_error(conf_path.string(), "confidence must be finite and >= 0, found " +
                                                  std::to_string(f.confidence[i]) + " at pixel " + std::to_string(i));
    }
  }

  const Image8 colour = read_colour(v.dir, options.mve_image);
  if (colour.width > 0) {
    // A depth map of a coarser level L is the colour image halved L times, MVE-style
    // (image_tools.h rescale_half_size: n -> (n + 1) / 2).
    bool same_view = false;
    for (int w = colour.width, h = colour.height; !same_view && w >= f.width && h >= f.height;
         w = (w + 1) / 2, h = (h + 1) / 2) {
      same_view = w == f.width && h == f.height;
      if (w == 1 && h == 1) break;
    }
    if (!same_view)
      throw input_error((v.dir / options.mve_image).string(),
                        "colour image is " + std::to_string(colour.width) + "x" + std::to_string(colour.height) +
                            ", not the depth map's " + std::to_string(f.width) + "x" + std::to_string(f.height) +
                            " or that size doubled (MVE levels)");
    f.colour = input_detail::sample_colour(colour, f.width, f.height);
  }
  return f;
}

DepthFrame MveSource::load(std::size_t i) const { return load_view(views_.at(i), options_); }

}  // namespace

std::unique_ptr<FrameSource> open_mve(const fs::path& scene, const InputOptions& options) {
  options.check();
  const fs::path views_dir = scene / "views";
  std::error_code ec;
  if (!fs::is_directory(views_dir, ec)) throw input_error(scene.string(), "MVE scene without a views/ folder");
  std::vector<fs::path> dirs;
  for (const auto& e : fs::directory_iterator(views_dir, ec)) {
    if (e.path().extension() != ".mve") continue;
    if (!e.is_directory(ec))
      throw input_error(e.path().string(), "single-file (zipped) MVE views are not supported; use view folders");
    dirs.push_back(e.path());
  }
  std::sort(dirs.begin(), dirs.end());  // view_0000.mve, view_0001.mve, ...: id order
  std::vector<MveView> views;
  for (const fs::path& d : dirs) {
    MveView v{d, d / (options.mve_depth + ".mvei")};
    // Views without the depth embedding are normal (dmrecon skips views it cannot reconstruct).
    if (!fs::is_regular_file(v.depth_path, ec)) continue;
    if (!options.skip_bad && !fs::is_regular_file(d / "meta.ini", ec))
      throw input_error((d / "meta.ini").string(), "missing file");
    views.push_back(std::move(v));
  }
  if (views.empty())
    throw input_error(views_dir.string(), "no view holds the depth embedding " + options.mve_depth + ".mvei (" +
                                              std::to_string(dirs.size()) + " views)");
  return std::make_unique<MveSource>(std::move(views), options);
}

}  // namespace sf
