#pragma once
// Writing a SyntheticScene as a COLMAP workspace, an MVE scene or an RGB-D sequence, each in that
// format's own conventions (so that engine/input reads it back like real data), plus
//   reference.ply  the normalized mesh (binary PLY), the ground truth for `scalefuse eval`;
//   synth.json     every camera, the focus, the close-up radius and the footprints (schema below).
//
// Layouts (NAME = view name, e.g. far_000; all files written to a temporary name, then renamed):
//   colmap  images/NAME.png                                8-bit RGB
//           sparse/cameras.txt images.txt points3D.txt     (or .bin with colmap_binary) one PINHOLE
//                                                          camera per image, CAMERA_ID = IMAGE_ID
//           stereo/depth_maps/NAME.png.{geometric,photometric}.bin   "W&H&1&" + float32 LE z-depth
//           stereo/normal_maps/NAME.png.{geometric,photometric}.bin  "W&H&3&" + float32 LE, camera
//                                                          frame, towards the camera, slice-major
//           stereo/fusion.cfg                              image names, one per line
//   mve     views/view_%04d.mve/meta.ini                   [camera] + [view] (MVE's own writer's keys)
//           views/view_%04d.mve/depth-L0.mvei              float, distance along the ray (not z)
//           views/view_%04d.mve/undistorted.png            8-bit RGB
//   rgbd    frame-%06d.depth.png                           16-bit, depth_scale metres per unit, 0 invalid
//           frame-%06d.color.png, frame-%06d.pose.txt      4x4 camera-to-world, "%.18e"
//           camera-intrinsics.txt                          3x3 K, pixel centres at integers
//                                                          (cx_file = cx - 0.5); needs one K for all
//                                                          views: render with uniform_resolution
//
// synth.json (version 1):
//   { "generator": "scalefuse synth", "version": 1, "format": "colmap"|"mve"|"rgbd",
//     "source": string, "reference": "reference.ply",
//     "normalization": {"size", "measure": "extent"|"diagonal", "scale", "source_centre": [3]},
//     "options": {far_views, far_width, far_height, far_fill, close_views, close_width,
//                 close_height, footprint_ratio, close_tilt_deg, focal, uniform_resolution,
//                 noise, seed},
//     "focus": [3], "focus_normal": [3], "close_radius": m,
//     "coarse_footprint": m, "fine_footprint": m, "footprint_ratio": coarse / fine,
//     "cameras": [ {"name", "kind": "far"|"close", "width", "height",
//                   "K": [[3],[3],[3]] (pixel centres at +0.5), "R": [[3],[3],[3]] and "t": [3]
//                   (world -> camera), "centre": [3], "median_footprint": m, "valid_pixels",
//                   "depth": path, "image": path (relative to the scene folder)} ] }
#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "engine/depth_frame.h"
#include "engine/synth/synth.h"

namespace sf {

enum class SceneFormat { Colmap, Mve, Rgbd };
std::optional<SceneFormat> parse_scene_format(std::string_view name);  // "colmap" | "mve" | "rgbd"
const char* format_name(SceneFormat format);

struct SceneWriteOptions {
  SceneFormat format = SceneFormat::Colmap;
  bool colmap_binary = false;       // sparse/*.bin (COLMAP's binary model) instead of *.txt
  double rgbd_depth_scale = 0.001;  // metres per unit of the 16-bit depth PNG (millimetres)
  std::string source;               // recorded in synth.json, e.g. the mesh path
  void check() const;               // throws InputError
};

struct WrittenScene {
  std::size_t frames = 0;
  std::vector<std::filesystem::path> files;  // every file written, synth.json last
  std::size_t rgbd_clipped = 0;  // RGB-D depths beyond 65535 units, written as 0 (invalid)
};

// Writes the scene into `dir` (created if missing; existing files of the same names are replaced).
// Throws InputError if a file cannot be written, std::invalid_argument if the scene does not fit
// the format (RGB-D with views of different sizes or intrinsics).
WrittenScene write_scene(const SyntheticScene& scene, const std::filesystem::path& dir,
                         const SceneWriteOptions& options);

// Removes what write_scene may have written into `dir` in any format (for --overwrite); leaves
// every other file alone.
void clear_scene_outputs(const std::filesystem::path& dir);

// The parts of synth.json that evaluation needs.
struct SceneCamera {
  std::string name;
  bool close = false;
  int width = 0, height = 0;
  Sensor sensor;
};
struct SceneInfo {
  std::string format;
  std::filesystem::path reference;  // resolved against the json's folder
  Eigen::Vector3d focus = Eigen::Vector3d::Zero();
  double close_radius = 0;
  double coarse_footprint = 0, fine_footprint = 0;
  std::vector<SceneCamera> cameras;
};
// Throws InputError naming the file if it is missing or malformed.
SceneInfo read_scene_info(const std::filesystem::path& synth_json);

}  // namespace sf
