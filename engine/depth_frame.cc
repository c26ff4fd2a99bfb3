#include "engine/depth_frame.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include "engine/error.h"
#include "engine/hash.h"

namespace sf {

std::size_t DepthFrame::memory_bytes() const {
  return valid.capacity() + position.capacity() * sizeof(position[0]) + image_pos.capacity() * sizeof(image_pos[0]) +
         footprint.capacity() * sizeof(float) + confidence.capacity() * sizeof(float) + colour.capacity() * sizeof(Rgb8);
}

std::size_t DepthFrame::valid_count() const {
  std::size_t n = 0;
  for (auto v : valid) n += v ? 1 : 0;
  return n;
}

std::uint64_t DepthFrame::content_hash() const {
  std::uint64_t h = fnv1a64(&width, sizeof width);
  h = fnv1a64(&height, sizeof height, h);
  const int kind = sensor.kind == Sensor::Kind::Perspective ? 0 : 1;
  h = fnv1a64(&kind, sizeof kind, h);
  h = fnv1a64(sensor.R.data(), 9 * sizeof(double), h);
  h = fnv1a64(sensor.t.data(), 3 * sizeof(double), h);
  const double k[4] = {sensor.fx, sensor.fy, sensor.cx, sensor.cy};
  h = fnv1a64(k, sizeof k, h);
  h = fnv1a64(valid.data(), valid.size(), h);
  for (std::size_t i = 0; i < valid.size(); ++i) {
    if (!valid[i]) continue;
    h = fnv1a64(position[i].data(), 3 * sizeof(float), h);
    h = fnv1a64(&footprint[i], sizeof(float), h);
    if (!confidence.empty()) h = fnv1a64(&confidence[i], sizeof(float), h);
    if (!colour.empty()) h = fnv1a64(colour[i].data(), 3, h);
  }
  return h;
}

void fill_perspective_samples(DepthFrame& frame, const std::vector<float>& depth, bool ray_distance) {
  const std::size_t n = frame.size();
  // A caller bug, not bad input: readers check map sizes against their headers before this.
  if (depth.size() != n)
    throw std::invalid_argument(frame.name + ": fill_perspective_samples given " + std::to_string(depth.size()) +
                                " depths for a " + std::to_string(frame.width) + "x" + std::to_string(frame.height) +
                                " frame");
  frame.valid.assign(n, 0);
  frame.position.assign(n, Eigen::Vector3f::Zero());
  frame.image_pos.assign(n, Eigen::Vector2f::Zero());
  frame.footprint.assign(n, 0.f);
  const Sensor& s = frame.sensor;
  const Eigen::Matrix3d Rt = s.R.transpose();
  const double f_mean = std::sqrt(s.fx * s.fy);
  for (int row = 0; row < frame.height; ++row) {
    for (int col = 0; col < frame.width; ++col) {
      const std::size_t i = std::size_t(row) * frame.width + col;
      const double d = depth[i];
      if (!(d > 0) || !std::isfinite(d)) continue;
      const double u = col + 0.5, v = row + 0.5;
      const Eigen::Vector3d ray((u - s.cx) / s.fx, (v - s.cy) / s.fy, 1.0);
      const double z = ray_distance ? d / ray.norm() : d;
      const Eigen::Vector3d Xc = z * ray;
      frame.valid[i] = 1;
      frame.position[i] = (Rt * (Xc - s.t)).cast<float>();
      frame.image_pos[i] = Eigen::Vector2f(float(u), float(v));
      frame.footprint[i] = float(z / f_mean);
      // Finite depths and poses can still overflow float positions (a translation of 1e300 m):
      // the file is bad, not the sample.
      if (!frame.position[i].allFinite() || !(frame.footprint[i] > 0) || !std::isfinite(frame.footprint[i]))
        throw InputError(frame.name + ": the sample at (col " + std::to_string(col) + ", row " + std::to_string(row) +
                         ") lands outside any sensible space (position or footprint not a finite float); the camera "
                         "pose or the depth is out of range");
    }
  }
}

}  // namespace sf
