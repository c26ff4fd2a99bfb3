#include "engine/extract/certificate.h"

#include <algorithm>
#include <cmath>

namespace sf::extract_detail {

bool circumball(const LatticePoint* p[4], Ball* out) {
  std::int64_t a[3], b[3], c[3];
  for (int k = 0; k < 3; ++k) {
    a[k] = std::int64_t((*p[1])[k]) - (*p[0])[k];
    b[k] = std::int64_t((*p[2])[k]) - (*p[0])[k];
    c[k] = std::int64_t((*p[3])[k]) - (*p[0])[k];
  }
  using I = __int128;
  const auto cross = [](const std::int64_t* u, const std::int64_t* w, I* o) {
    o[0] = I(u[1]) * w[2] - I(u[2]) * w[1];
    o[1] = I(u[2]) * w[0] - I(u[0]) * w[2];
    o[2] = I(u[0]) * w[1] - I(u[1]) * w[0];
  };
  I bc[3], ca[3], ab[3];
  cross(b, c, bc);
  cross(c, a, ca);
  cross(a, b, ab);
  const I det = I(a[0]) * bc[0] + I(a[1]) * bc[1] + I(a[2]) * bc[2];
  if (det <= 0) return false;
  const auto sq = [](const std::int64_t* u) { return I(u[0]) * u[0] + I(u[1]) * u[1] + I(u[2]) * u[2]; };
  const I la = sq(a), lb = sq(b), lc = sq(c);
  const long double D = 2.0L * static_cast<long double>(det);
  long double r2 = 0;
  for (int k = 0; k < 3; ++k) {
    const long double n = static_cast<long double>(la * bc[k] + lb * ca[k] + lc * ab[k]) / D;
    out->centre[k] = static_cast<long double>((*p[0])[k]) + n;
    r2 += n * n;
  }
  out->radius = std::sqrt(r2);
  return true;
}
namespace {
constexpr long double kBallMargin = 1e-3L;  // lattice units, far above the long double rounding
}  // namespace

Certificate certify(const Ball& ball, const LatticePoint* cell_points[4], const std::int64_t lo[3],
                    const std::int64_t hi[3], const OutsidePoints& outside, const Occupancy& occ) {
  bool inside = true;
  for (int k = 0; k < 3; ++k)
    inside = inside && ball.centre[k] - ball.radius > static_cast<long double>(lo[k] - 1) + kBallMargin &&
             ball.centre[k] + ball.radius < static_cast<long double>(hi[k] + 1) - kBallMargin;
  if (inside) return Certificate::kGlobal;
  std::int64_t c0[3], c1[3];
  for (int k = 0; k < 3; ++k) {
    const long double a = (ball.centre[k] - ball.radius - kBallMargin) / occ.side;
    const long double b = (ball.centre[k] + ball.radius + kBallMargin) / occ.side;
    if (!(a > -1e6L && b < 1e6L)) return Certificate::kUnknown;  // a sliver's huge ball
    c0[k] = std::max<std::int64_t>(0, std::int64_t(std::floor(a)));
    c1[k] = std::int64_t(std::floor(b));
  }
  if ((c1[2] - c0[2] + 1) * (c1[1] - c0[1] + 1) > 65536) return Certificate::kUnknown;
  const long double r2 = (ball.radius + kBallMargin) * (ball.radius + kBallMargin);
  // The occupied cells of the ball's box, row by row (a big ball over empty space costs its rows).
  for (std::int64_t z = c0[2]; z <= c1[2]; ++z)
    for (std::int64_t y = c0[1]; y <= c1[1]; ++y) {
      const std::uint64_t row_end = Occupancy::pack(c1[0], y, z);
      for (auto cell_it = std::lower_bound(occ.cells.begin(), occ.cells.end(), Occupancy::pack(c0[0], y, z));
           cell_it != occ.cells.end() && *cell_it <= row_end; ++cell_it) {
        const std::int64_t cell[3] = {std::int64_t(*cell_it & 0x1FFFFF), y, z};
        bool in_window = true;
        long double d2 = 0;  // squared distance from the centre to the cell's closed box
        for (int k = 0; k < 3; ++k) {
          const std::int64_t first = cell[k] * occ.side, last = first + occ.side - 1;
          in_window = in_window && first >= lo[k] && last <= hi[k];
          const long double q = std::clamp(ball.centre[k], static_cast<long double>(first), static_cast<long double>(last));
          d2 += (ball.centre[k] - q) * (ball.centre[k] - q);
        }
        if (in_window || d2 > r2) continue;
        for (const LatticePoint& p : outside(*cell_it))
          if (lattice_side_of_sphere(cell_points, p) > 0) return Certificate::kNotGlobal;
      }
    }
  return Certificate::kGlobal;
}

}  // namespace sf::extract_detail
