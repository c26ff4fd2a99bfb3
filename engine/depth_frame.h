#pragma once
// A registered depth map, in the one form every reader produces and the fusion consumes.
//
// Two sensor models cover our inputs:
//  - Perspective (COLMAP, MVE, RGB-D, synthetic): rays start at the centre of projection.
//    Image coordinates follow COLMAP: the centre of pixel (col,row) is (col + 0.5, row + 0.5), and
//    u = fx * x_c / z_c + cx, v = fy * y_c / z_c + cy with x_c = R * x_w + t (world -> camera).
//  - Orthographic (Stanford range grids): all lines of sight are parallel to the sensor's +z axis;
//    the sensor-plane coordinates of a point are its (x_s, y_s) in the sensor frame, in metres.
//
// Every sample stores its world position and its position in the sensor plane ("image_pos"), so
// the image-space triangulation and the voxel-to-triangle lookup need not know which model made it.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace sf {

struct Sensor {
  enum class Kind { Perspective, Orthographic };
  Kind kind = Kind::Perspective;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // world -> sensor rotation
  Eigen::Vector3d t = Eigen::Vector3d::Zero();      // world -> sensor translation
  double fx = 1, fy = 1, cx = 0, cy = 0;            // perspective intrinsics, pixels

  // Centre of projection in world coordinates (perspective only).
  Eigen::Vector3d centre() const { return -R.transpose() * t; }
  // Viewing direction (sensor +z) in world coordinates.
  Eigen::Vector3d axis() const { return R.row(2).transpose(); }

  // Unit direction of the line of sight through world point X, pointing away from the sensor.
  Eigen::Vector3d ray_direction(const Eigen::Vector3d& X) const {
    if (kind == Kind::Orthographic) return axis();
    return (X - centre()).normalized();
  }
  // Sensor-plane coordinates of X; false if X is behind a perspective camera.
  bool project(const Eigen::Vector3d& X, Eigen::Vector2d* uv) const {
    const Eigen::Vector3d p = R * X + t;
    if (kind == Kind::Orthographic) {
      *uv = p.head<2>();
      return true;
    }
    if (p.z() <= 0) return false;
    *uv = Eigen::Vector2d(fx * p.x() / p.z() + cx, fy * p.y() / p.z() + cy);
    return true;
  }
};

using Rgb8 = std::array<std::uint8_t, 3>;

struct DepthFrame {
  std::string name;   // source file, for messages
  int width = 0, height = 0;
  Sensor sensor;
  // Per sample, row-major (index = row * width + col). Invalid samples have valid[i] == 0 and
  // unspecified other fields.
  std::vector<std::uint8_t> valid;
  std::vector<Eigen::Vector3f> position;   // world coordinates, metres
  std::vector<Eigen::Vector2f> image_pos;  // sensor-plane coordinates (see above)
  std::vector<float> footprint;            // pixel footprint F, metres (section 5)
  std::vector<float> confidence;           // empty: all 1
  std::vector<Rgb8> colour;                // empty: no colour

  std::size_t size() const { return std::size_t(width) * std::size_t(height); }
  std::size_t valid_count() const;
  std::size_t memory_bytes() const;  // heap bytes of the per-sample arrays
  // A hash of everything the fusion reads: size, sensor, and every sample's validity, position,
  // footprint, confidence and colour. A job compares it to notice changed inputs.
  std::uint64_t content_hash() const;
};

// Fills valid/position/image_pos/footprint of a perspective frame from a depth image.
// depth[i] is z-depth (distance along the optical axis) unless ray_distance is true, in which case
// it is the distance from the centre of projection along the pixel's ray (MVE convention).
// Depths that are <= 0 or not finite are invalid. The footprint is z / sqrt(fx * fy): the width of
// a fronto-parallel square that projects onto one pixel.
void fill_perspective_samples(DepthFrame& frame, const std::vector<float>& depth, bool ray_distance);

}  // namespace sf
