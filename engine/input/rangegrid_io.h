#pragma once
// Stanford range grids (Cyberware scans, as in the Stanford 3D Scanning Repository): an ASCII PLY
// per scan with `obj_info num_cols/num_rows`, `element vertex` (x y z [confidence ...]) and
// `element range_grid` (per cell a list of 0 or 1 vertex indices, row by row), plus a .conf file
// registering the scans (`bmesh <file> tx ty tz qx qy qz qw`).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <filesystem>
#include <vector>

#include "engine/depth_frame.h"

namespace sf {

struct RangeScan {
  int num_cols = 0, num_rows = 0;
  std::vector<Eigen::Vector3f> points;  // scanner frame, metres
  std::vector<float> confidence;        // per point; empty when the PLY has none
  std::vector<std::int32_t> grid;       // per cell (row * num_cols + col): point index or -1
};
RangeScan read_range_grid_ply(const std::filesystem::path& path);

struct RangeScanPose {
  std::filesystem::path file;  // the scan, resolved against the .conf's folder
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();  // as written (x y z w), normalised
  // p_world = R(q)^T * p_scan + t: the convention that registers the Stanford scans (data README).
  Eigen::Vector3d to_world(const Eigen::Vector3d& p_scan) const { return q.toRotationMatrix().transpose() * p_scan + t; }
};
// The bmesh lines of a .conf file (other lines, e.g. `camera`, are viewer settings and ignored).
std::vector<RangeScanPose> read_range_grid_conf(const std::filesystem::path& path);

// An orthographic DepthFrame for one registered scan (see rangegrid_reader.cc for the sensor
// frame and the footprint definition). `name` is used for messages.
DepthFrame range_scan_frame(const RangeScan& scan, const RangeScanPose& pose, const std::string& name);

}  // namespace sf
