#pragma once
// Readers turn a folder of registered depth maps into DepthFrames, one at a time, so that a job
// never holds more than the frames in flight. Formats: see docs/formats.md.
#include <cstddef>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "engine/depth_frame.h"

namespace sf {

struct InputOptions {
  std::string format = "auto";           // auto | colmap | mve | rgbd | rangegrid
  std::string colmap_maps = "geometric"; // geometric | photometric
  std::string mve_depth = "depth-L0";    // MVE embedding holding depth (distance along the ray)
  std::string mve_image = "undistorted"; // MVE colour embedding; missing per view is fine
  std::string mve_confidence = "conf-L0";// MVE confidence embedding; missing per view is fine
  double rgbd_depth_scale = 0.001;       // metres per depth-PNG unit (7-Scenes: millimetres)
  bool rgbd_use_colour = true;           // use *.color.(png|jpg) when its size matches the depth
  int frame_step = 1;                    // fuse every frame_step-th depth map (redundant sequences)
  // job.skip_bad: a depth map that fails to read is skipped (SkippingSource), so per-frame
  // problems the readers would find at open time (a view's missing meta.ini or pose) wait for load().
  bool skip_bad = false;
  bool check() const;                    // throws InputError on a bad value
};

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  virtual std::string format() const = 0;           // "colmap", "mve", "rgbd", "rangegrid"
  virtual std::size_t size() const = 0;             // number of depth maps
  virtual std::string frame_name(std::size_t i) const = 0;  // file the frame comes from
  // Reads frame i. Thread-safe (const, no shared mutable state). Throws InputError naming the
  // file and the problem on bad data.
  virtual DepthFrame load(std::size_t i) const = 0;
};

// A source that grows while the fusion runs (fuse --follow): fuse() asks for more once it has
// integrated everything the source holds.
class FrameFeed {
 public:
  virtual ~FrameFeed() = default;
  // Blocks until the source holds more than `known` depth maps (true), or the feed has ended
  // (false: a stop file, a signal, or nothing more to take).
  virtual bool wait_for_more(std::size_t known) = 0;
};

// Detects the format of `input` (unless options.format says it) and opens it. Throws InputError if
// the folder is missing, unrecognised or holds no depth maps.
std::unique_ptr<FrameSource> open_input(const std::filesystem::path& input, const InputOptions& options);

// The depth maps of several inputs, one after the other (a job that grew with `scalefuse add`).
std::unique_ptr<FrameSource> concatenate_inputs(std::vector<std::unique_ptr<FrameSource>> parts);

}  // namespace sf
