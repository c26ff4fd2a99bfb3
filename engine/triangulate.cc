#include "engine/triangulate.h"

#include <cmath>

#include "engine/error.h"

namespace sf {

void TriangulateOptions::check() const {
  if (!(rho > 0)) throw InputError("triangulate.rho must be > 0, got " + std::to_string(rho));
}

std::vector<float> sensor_depths(const DepthFrame& frame) {
  std::vector<float> z(frame.size(), 0.f);
  const Eigen::Matrix3d& R = frame.sensor.R;
  for (std::size_t i = 0; i < z.size(); ++i) {
    if (!frame.valid[i]) continue;
    z[i] = float(R.row(2).dot(frame.position[i].cast<double>()) + frame.sensor.t.z());
  }
  return z;
}

std::vector<FrameTriangle> triangulate(const DepthFrame& frame, const TriangulateOptions& options) {
  std::vector<FrameTriangle> out;
  if (frame.width < 2 || frame.height < 2) return out;
  const std::vector<float> z = sensor_depths(frame);
  const double rho = options.rho;
  auto ok = [&](std::uint32_t a, std::uint32_t b) {
    return !is_discontinuity(z[a], z[b], frame.footprint[a], frame.footprint[b], rho);
  };
  auto emit = [&](std::uint32_t a, std::uint32_t b, std::uint32_t c) {
    if (ok(a, b) && ok(b, c) && ok(c, a)) out.push_back({a, b, c});
  };
  out.reserve(frame.valid_count() * 2);
  const std::uint32_t w = std::uint32_t(frame.width);
  for (int row = 0; row + 1 < frame.height; ++row) {
    for (int col = 0; col + 1 < frame.width; ++col) {
      // i00 --- i10
      //  |       |
      // i01 --- i11    (rows go down the image)
      const std::uint32_t i00 = std::uint32_t(row) * w + std::uint32_t(col), i10 = i00 + 1, i01 = i00 + w, i11 = i01 + 1;
      const int mask = (frame.valid[i00] ? 1 : 0) | (frame.valid[i10] ? 2 : 0) | (frame.valid[i01] ? 4 : 0) |
                       (frame.valid[i11] ? 8 : 0);
      switch (mask) {
        case 15:
          if (std::abs(z[i00] - z[i11]) <= std::abs(z[i10] - z[i01])) {
            emit(i00, i01, i11);
            emit(i00, i11, i10);
          } else {
            emit(i00, i01, i10);
            emit(i10, i01, i11);
          }
          break;
        case 14: emit(i10, i01, i11); break;
        case 13: emit(i00, i01, i11); break;
        case 11: emit(i00, i11, i10); break;
        case 7: emit(i00, i01, i10); break;
        default: break;
      }
    }
  }
  return out;
}

}  // namespace sf
