#include "engine/input/frame_source.h"

#include <stdexcept>

#include <cmath>
#include <fstream>
#include <string>
#include <system_error>

#include "engine/error.h"
#include "engine/input/file_util.h"
#include "engine/input/readers.h"

namespace sf {

namespace fs = std::filesystem;

bool InputOptions::check() const {
  auto bad = [](const std::string& what) { return InputError("input options: " + what); };
  if (format != "auto" && format != "colmap" && format != "mve" && format != "rgbd" && format != "rangegrid")
    throw bad("format must be auto, colmap, mve, rgbd or rangegrid, got \"" + format + "\"");
  if (colmap_maps != "geometric" && colmap_maps != "photometric")
    throw bad("colmap_maps must be geometric or photometric, got \"" + colmap_maps + "\"");
  // Embedding names become file names inside the view folder.
  for (const auto* name : {&mve_depth, &mve_image, &mve_confidence}) {
    if (name->empty() || name->find('/') != std::string::npos || *name == "." || *name == "..")
      throw bad("MVE embedding names must be plain file names, got \"" + *name + "\"");
  }
  if (!(rgbd_depth_scale > 0) || !std::isfinite(rgbd_depth_scale))
    throw bad("rgbd_depth_scale must be a positive number of metres per unit, got " + std::to_string(rgbd_depth_scale));
  if (frame_step < 1) throw bad("frame_step must be >= 1, got " + std::to_string(frame_step));
  return true;
}

namespace {

bool has_bmesh_line(const fs::path& conf) {
  std::ifstream in(conf);
  std::string line;
  while (std::getline(in, line)) {
    const auto tokens = input_detail::split_ws(line);
    if (!tokens.empty() && tokens[0] == "bmesh") return true;
  }
  return false;
}

}  // namespace

std::string detect_input_format(const fs::path& input) {
  std::error_code ec;
  if (fs::is_directory(input / "sparse", ec) || fs::is_directory(input / "stereo" / "depth_maps", ec)) return "colmap";
  if (fs::is_directory(input / "views", ec)) {
    for (const auto& entry : fs::directory_iterator(input / "views", ec))
      if (entry.path().extension() == ".mve") return "mve";
  }
  bool depth_png = false, conf_with_bmesh = false;
  for (const auto& entry : fs::directory_iterator(input, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.size() > 10 && name.ends_with(".depth.png")) depth_png = true;
    if (entry.path().extension() == ".conf" && entry.is_regular_file(ec) && has_bmesh_line(entry.path()))
      conf_with_bmesh = true;
  }
  if (depth_png && fs::is_regular_file(input / "camera-intrinsics.txt", ec)) return "rgbd";
  if (conf_with_bmesh) return "rangegrid";
  return "";
}

std::unique_ptr<FrameSource> open_input(const fs::path& input, const InputOptions& options) {
  options.check();
  std::error_code ec;
  if (!fs::exists(input, ec)) throw input_error(input.string(), "input folder does not exist");
  if (!fs::is_directory(input, ec)) throw input_error(input.string(), "input is not a folder");
  std::string format = options.format;
  if (format == "auto") {
    format = detect_input_format(input);
    if (format.empty())
      throw input_error(input.string(), "not a COLMAP workspace, MVE scene, RGB-D folder or range-grid folder");
  }
  if (format == "colmap") return open_colmap(input, options);
  if (format == "mve") return open_mve(input, options);
  if (format == "rgbd") return open_rgbd(input, options);
  return open_rangegrid(input, options);
}

namespace {

class ConcatenatedSource : public FrameSource {
 public:
  explicit ConcatenatedSource(std::vector<std::unique_ptr<FrameSource>> parts) : parts_(std::move(parts)) {
    for (const auto& p : parts_) {
      starts_.push_back(total_);
      total_ += p->size();
    }
  }
  std::string format() const override {
    std::string f = parts_.front()->format();
    for (const auto& p : parts_)
      if (p->format() != f) return "mixed";
    return f;
  }
  std::size_t size() const override { return total_; }
  std::string frame_name(std::size_t i) const override {
    const std::size_t k = part_of(i);
    return parts_[k]->frame_name(i - starts_[k]);
  }
  DepthFrame load(std::size_t i) const override {
    const std::size_t k = part_of(i);
    return parts_[k]->load(i - starts_[k]);
  }

 private:
  std::size_t part_of(std::size_t i) const {
    std::size_t k = 0;
    while (k + 1 < starts_.size() && starts_[k + 1] <= i) ++k;
    return k;
  }
  std::vector<std::unique_ptr<FrameSource>> parts_;
  std::vector<std::size_t> starts_;
  std::size_t total_ = 0;
};

}  // namespace

std::unique_ptr<FrameSource> concatenate_inputs(std::vector<std::unique_ptr<FrameSource>> parts) {
  if (parts.empty()) throw std::invalid_argument("concatenate_inputs: no inputs");
  if (parts.size() == 1) return std::move(parts.front());
  return std::make_unique<ConcatenatedSource>(std::move(parts));
}

}  // namespace sf
