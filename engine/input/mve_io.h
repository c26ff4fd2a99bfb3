#pragma once
// MVE scene files, as MVE writes them (libs/mve/image_io.cc, view.cc, camera.cc, util/ini_parser.cc).
#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "engine/depth_frame.h"

namespace sf {

// An .mvei image: "\x89MVE_IMAGE\n", int32 width, height, channels, type, then interleaved
// pixels. Types are MVE's ImageType: 1 uint8, 2 uint16, 3 uint32, 4 uint64, 5-8 int8..int64,
// 9 float, 10 double.
struct MveImage {
  int width = 0, height = 0, channels = 0, type = 0;
  std::vector<std::uint8_t> bytes;  // width * height * channels * sizeof(type), host order
};
MveImage read_mvei(const std::filesystem::path& path);
// Channel 0 of a float/double/uint8 image as float (uint8 scaled to [0,1]); InputError otherwise.
std::vector<float> mvei_channel0_as_float(const MveImage& image, const std::filesystem::path& path);

// meta.ini as "section.key" -> value, whitespace-trimmed (MVE's parse_ini).
std::map<std::string, std::string> read_mve_ini(const std::filesystem::path& path);

// The [camera] section. flen is normalised by the image's larger side (for paspect 1), ppoint by
// the image size; rotation/translation map world to camera.
struct MveCamera {
  double flen = 0, paspect = 1;
  double ppoint[2] = {0.5, 0.5};
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
};
// Throws InputError naming `path` when focal_length is missing or not positive, or values are bad.
MveCamera mve_camera(const std::map<std::string, std::string>& ini, const std::filesystem::path& path);
// Pinhole sensor for an image of width x height, as CameraInfo::fill_calibration computes K.
Sensor mve_sensor(const MveCamera& camera, int width, int height);

}  // namespace sf
