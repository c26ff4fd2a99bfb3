#pragma once
// The four readers behind open_input(), each in its own file, and the format detection rule.
// Each open_* parses the folder's metadata eagerly (so that bad metadata fails at open time) and
// reads the per-frame files in load().
#include <filesystem>
#include <memory>
#include <string>

#include "engine/input/frame_source.h"

namespace sf {

std::unique_ptr<FrameSource> open_colmap(const std::filesystem::path& workspace, const InputOptions& options);
std::unique_ptr<FrameSource> open_mve(const std::filesystem::path& scene, const InputOptions& options);
std::unique_ptr<FrameSource> open_rgbd(const std::filesystem::path& folder, const InputOptions& options);
std::unique_ptr<FrameSource> open_rangegrid(const std::filesystem::path& folder, const InputOptions& options);

// The format open_input picks for format "auto": "colmap" if the folder has sparse/ or
// stereo/depth_maps/; "mve" if views/ holds *.mve; "rgbd" if it has *.depth.png and
// camera-intrinsics.txt; "rangegrid" if a *.conf file has bmesh lines; "" otherwise.
std::string detect_input_format(const std::filesystem::path& input);

}  // namespace sf
