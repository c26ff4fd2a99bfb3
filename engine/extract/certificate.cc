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

PointGrid::PointGrid(const std::vector<LatticePoint>& points, int shift) : shift_(shift), cell_at_(points.size()) {
  std::vector<std::pair<std::uint64_t, std::uint32_t>> by_cell(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    const LatticePoint& p = points[i];
    by_cell[i] = {Occupancy::pack(p[0] >> shift, p[1] >> shift, p[2] >> shift), std::uint32_t(i)};
  }
  std::sort(by_cell.begin(), by_cell.end());
  points_.reserve(points.size());
  for (std::size_t i = 0; i < by_cell.size(); ++i) {
    if (i == 0 || by_cell[i].first != by_cell[i - 1].first) {
      cell_at_.insert(by_cell[i].first, std::uint32_t(starts_.size()));
      starts_.push_back(std::uint32_t(i));
    }
    points_.push_back(points[by_cell[i].second]);
  }
  starts_.push_back(std::uint32_t(points_.size()));
}

bool PointGrid::any_in_ball(const Ball& ball, const LatticePoint* cell_points[4]) const {
  if (points_.empty()) return false;
  const long double r = ball.radius + kBallMargin, r2 = r * r;
  const auto inside = [&](const LatticePoint& p) {
    long double d2 = 0;
    for (int k = 0; k < 3; ++k) d2 += (ball.centre[k] - p[k]) * (ball.centre[k] - p[k]);
    return d2 <= r2 && lattice_side_of_sphere(cell_points, p) > 0;
  };
  const long double cell = static_cast<long double>(std::int64_t{1} << shift_);
  std::int64_t c0[3], c1[3], mid[3];
  bool small = true;
  for (int k = 0; k < 3; ++k) {
    const long double a = std::floor((ball.centre[k] - r) / cell), b = std::floor((ball.centre[k] + r) / cell);
    small = small && a > -1e6L && b < 1e6L;
    c0[k] = small ? std::max<std::int64_t>(0, std::int64_t(a)) : 0;
    c1[k] = small ? std::int64_t(b) : 0;
    mid[k] = small ? std::clamp(std::int64_t(std::floor(ball.centre[k] / cell)), c0[k], c1[k]) : 0;
  }
  // A sliver's huge ball: look at every point rather than at its many empty cells.
  if (!small || std::uint64_t((c1[0] - c0[0] + 1) * (c1[1] - c0[1] + 1) * (c1[2] - c0[2] + 1)) > starts_.size()) {
    for (const LatticePoint& p : points_)
      if (inside(p)) return true;
    return false;
  }
  const auto any_in_cell = [&](std::int64_t x, std::int64_t y, std::int64_t z) {
    const std::int64_t run = cell_at_.find(Occupancy::pack(x, y, z));
    if (run < 0) return false;
    for (std::uint32_t i = starts_[std::size_t(run)]; i < starts_[std::size_t(run) + 1]; ++i)
      if (inside(points_[i])) return true;
    return false;
  };
  // The centre's cell first: where a ball reaches into the interior, it is mostly there.
  if (any_in_cell(mid[0], mid[1], mid[2])) return true;
  for (std::int64_t z = c0[2]; z <= c1[2]; ++z)
    for (std::int64_t y = c0[1]; y <= c1[1]; ++y)
      for (std::int64_t x = c0[0]; x <= c1[0]; ++x)
        if (!(x == mid[0] && y == mid[1] && z == mid[2]) && any_in_cell(x, y, z)) return true;
  return false;
}

}  // namespace sf::extract_detail
