// Stanford range grids as orthographic DepthFrames.
//
// Sensor frame. A Cyberware scan's lines of sight are parallel to the scan frame's z axis, and the
// scanner sits on the +z side: for every one of the ten bunny scans, 99.8-100% of the samples'
// nearest bun_zipper.ply vertices have outward normals pointing to +z of the scan frame, i.e.
// against the viewing direction chosen below (tests/input_rangegrid_test.cc checks this). The sensor therefore looks along -z_scan. To keep R a proper
// rotation we turn the scan frame by 180 degrees about x:
//     x_s = x_scan,  y_s = -y_scan,  z_s = -z_scan + offset,
// so sensor +z is the viewing direction and image_pos = (x_scan, -y_scan). Note that rows of the
// grid run along -y_s (the grid is mirrored with respect to a camera image); consumers orient
// triangles from positions and image_pos, not from the grid order. `offset` puts the sensor plane
// one scan extent in front of the nearest sample, so that depths along the axis are positive.
//
// Footprint. The paper's footprint is the width of a fronto-parallel square covering one sample.
// For a range grid we take, per sample, the spacing to its valid grid neighbours measured in the
// sensor plane (i.e. perpendicular to the line of sight): s_col = mean distance to the left/right
// neighbours, s_row = the same for the neighbours above/below, footprint = sqrt(s_col * s_row).
// Neighbours further than 3x the scan's median spacing in that direction (grid gaps, jumps across
// silhouettes) do not count; a direction without a usable neighbour falls back to the scan median.
// The rows of these scans are not evenly spaced in y, so nothing assumes a regular lattice.
#include <algorithm>
#include <cmath>
#include <system_error>

#include "engine/error.h"
#include "engine/input/file_util.h"
#include "engine/input/rangegrid_io.h"
#include "engine/input/readers.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

constexpr double kNeighbourOutlier = 3.0;  // x median spacing

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  const auto mid = v.begin() + v.size() / 2;
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

class RangeGridSource final : public FrameSource {
 public:
  explicit RangeGridSource(std::vector<RangeScanPose> scans) : scans_(std::move(scans)) {}
  std::string format() const override { return "rangegrid"; }
  std::size_t size() const override { return scans_.size(); }
  std::string frame_name(std::size_t i) const override { return scans_.at(i).file.string(); }
  DepthFrame load(std::size_t i) const override {
    const RangeScanPose& p = scans_.at(i);
    return range_scan_frame(read_range_grid_ply(p.file), p, p.file.string());
  }

 private:
  std::vector<RangeScanPose> scans_;
};

}  // namespace

DepthFrame range_scan_frame(const RangeScan& scan, const RangeScanPose& pose, const std::string& name) {
  const int W = scan.num_cols, H = scan.num_rows;
  auto point_at = [&](int row, int col) -> const Eigen::Vector3f* {
    if (row < 0 || row >= H || col < 0 || col >= W) return nullptr;
    const std::int32_t k = scan.grid[std::size_t(row) * W + col];
    return k < 0 ? nullptr : &scan.points[std::size_t(k)];
  };
  auto plane_dist = [](const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
    return double((a.head<2>() - b.head<2>()).norm());
  };

  // Scan-wide medians and extent.
  std::vector<double> col_gaps, row_gaps;
  Eigen::AlignedBox3d box;
  for (int row = 0; row < H; ++row)
    for (int col = 0; col < W; ++col) {
      const Eigen::Vector3f* p = point_at(row, col);
      if (!p) continue;
      box.extend(p->cast<double>());
      if (const auto* q = point_at(row, col + 1)) col_gaps.push_back(plane_dist(*p, *q));
      if (const auto* q = point_at(row + 1, col)) row_gaps.push_back(plane_dist(*p, *q));
    }
  if (box.isEmpty()) throw input_error(name, "range grid has no samples");
  double med_col = median(col_gaps), med_row = median(row_gaps);
  if (!(med_col > 0)) med_col = med_row;
  if (!(med_row > 0)) med_row = med_col;
  if (!(med_col > 0))
    throw input_error(name, "cannot estimate the sample spacing: no two grid neighbours are both valid");

  // Sensor pose: p_s = F * p_scan + (0, 0, offset), p_scan = Q * (p_world - t).
  const Eigen::Matrix3d Q = pose.q.toRotationMatrix();
  const Eigen::Matrix3d F = Eigen::Vector3d(1, -1, -1).asDiagonal();
  const double offset = box.max().z() + box.sizes().maxCoeff();
  DepthFrame f;
  f.name = name;
  f.width = W;
  f.height = H;
  f.sensor.kind = Sensor::Kind::Orthographic;
  f.sensor.R = F * Q;
  f.sensor.t = -F * Q * pose.t + Eigen::Vector3d(0, 0, offset);

  const std::size_t n = f.size();
  f.valid.assign(n, 0);
  f.position.assign(n, Eigen::Vector3f::Zero());
  f.image_pos.assign(n, Eigen::Vector2f::Zero());
  f.footprint.assign(n, 0.f);
  if (!scan.confidence.empty()) f.confidence.assign(n, 0.f);
  auto spacing = [&](const Eigen::Vector3f& p, const Eigen::Vector3f* a, const Eigen::Vector3f* b, double med) {
    double sum = 0;
    int count = 0;
    for (const Eigen::Vector3f* q : {a, b}) {
      if (!q) continue;
      const double d = plane_dist(p, *q);
      if (d > 0 && d <= kNeighbourOutlier * med) {
        sum += d;
        ++count;
      }
    }
    return count ? sum / count : med;
  };
  for (int row = 0; row < H; ++row)
    for (int col = 0; col < W; ++col) {
      const Eigen::Vector3f* p = point_at(row, col);
      if (!p) continue;
      const std::size_t i = std::size_t(row) * W + col;
      const double s_col = spacing(*p, point_at(row, col - 1), point_at(row, col + 1), med_col);
      const double s_row = spacing(*p, point_at(row - 1, col), point_at(row + 1, col), med_row);
      f.valid[i] = 1;
      f.position[i] = pose.to_world(p->cast<double>()).cast<float>();
      f.image_pos[i] = Eigen::Vector2f(p->x(), -p->y());
      f.footprint[i] = float(std::sqrt(s_col * s_row));
      if (!f.position[i].allFinite() || !std::isfinite(f.footprint[i]))
        throw input_error(name, "the sample at (col " + std::to_string(col) + ", row " + std::to_string(row) +
                                    ") lands outside any sensible space (not a finite float); the scan's "
                                    "registration or its points are out of range");
      if (!scan.confidence.empty()) f.confidence[i] = scan.confidence[std::size_t(scan.grid[i])];
    }
  return f;
}

std::unique_ptr<FrameSource> open_rangegrid(const fs::path& folder, const InputOptions& options) {
  options.check();
  std::vector<fs::path> confs;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(folder, ec))
    if (e.path().extension() == ".conf" && e.is_regular_file(ec)) confs.push_back(e.path());
  std::sort(confs.begin(), confs.end());
  std::vector<RangeScanPose> scans;
  for (const fs::path& c : confs) {
    auto poses = read_range_grid_conf(c);
    for (auto& p : poses) {
      if (!fs::is_regular_file(p.file, ec))
        throw input_error(c.string(), "bmesh refers to " + p.file.filename().string() + ", which is missing");
      scans.push_back(std::move(p));
    }
  }
  if (scans.empty()) throw input_error(folder.string(), "no .conf file with bmesh lines: not a range-grid folder");
  return std::make_unique<RangeGridSource>(std::move(scans));
}

}  // namespace sf
