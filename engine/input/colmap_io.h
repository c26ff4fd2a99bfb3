#pragma once
// COLMAP's model and dense-map files, as COLMAP writes them (src/colmap/scene/reconstruction_io_*.cc,
// src/colmap/mvs/mat.cc). Only what fusion needs is kept: undistorted pinhole cameras, image poses
// and names, and depth maps.
#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace sf {

struct ColmapCamera {
  std::uint32_t id = 0;
  int model_id = -1;            // 0 SIMPLE_PINHOLE (f, cx, cy), 1 PINHOLE (fx, fy, cx, cy)
  std::uint64_t width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;  // COLMAP image coordinates: pixel centres at +0.5
};

struct ColmapImage {
  std::uint32_t id = 0;
  Eigen::Vector4d qvec{1, 0, 0, 0};  // (w, x, y, z), world -> camera
  Eigen::Vector3d tvec = Eigen::Vector3d::Zero();
  std::uint32_t camera_id = 0;
  std::string name;
};

// cameras.txt or cameras.bin (by extension). Rejects models other than SIMPLE_PINHOLE/PINHOLE
// ("the workspace must be undistorted"), non-positive focal lengths and duplicate ids.
std::vector<ColmapCamera> read_colmap_cameras(const std::filesystem::path& path);
// images.txt or images.bin (by extension); the 2D points are skipped. Rejects duplicate ids/names.
std::vector<ColmapImage> read_colmap_images(const std::filesystem::path& path);

// A stereo/*_maps/*.bin array: "W&H&C&" then W*H*C little-endian float32, index c*W*H + row*W + col.
struct ColmapArray {
  int width = 0, height = 0, channels = 0;
  std::vector<float> data;
};
ColmapArray read_colmap_array(const std::filesystem::path& path);

}  // namespace sf
