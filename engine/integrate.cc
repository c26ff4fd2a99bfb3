#include "engine/integrate.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <mutex>

#include "engine/error.h"
#include "engine/hsdf_math.h"
#include "engine/integrate_kernel.h"

namespace sf {

void IntegrateOptions::check() const {
  if (!(lambda > 0)) throw InputError("integrate.lambda must be > 0, got " + std::to_string(lambda));
  if (!(gamma > 0)) throw InputError("integrate.gamma must be > 0, got " + std::to_string(gamma));
  if (coarser_levels < 0 || coarser_levels > kMaxLevel)
    throw InputError("integrate.coarser_levels must be in 0.." + std::to_string(kMaxLevel));
  if (!(coarse_reach >= 0)) throw InputError("integrate.coarse_reach must be >= 0 (0 = unlimited)");
  if (!(behind > 0 && behind <= 1)) throw InputError("integrate.behind must be in (0, 1]");
  if (!(min_cosine >= 0 && min_cosine < 1)) throw InputError("integrate.min_cosine must be in [0, 1)");
  if (max_level < 0 || max_level > kMaxLevel)
    throw InputError("integrate.max_level must be in 0.." + std::to_string(kMaxLevel));
  if (single_level < -1 || single_level > kMaxLevel)
    throw InputError("integrate.single_level must be -1 (off) or in 0.." + std::to_string(kMaxLevel));
}

void IntegrateStats::add(const IntegrateStats& o) {
  triangles += o.triangles;
  contributions += o.contributions;
  for (int l = 0; l <= kMaxLevel; ++l) triangles_per_level[l] += o.triangles_per_level[l];
}

namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;
using namespace integrate_detail;

// A triangle prepared for the prism enumeration.
struct PreparedTriangle {
  Vector3d P[3];
  std::uint32_t idx[3];
  Vector3d normal;        // unit, facing the sensor
  Vector3d dir[3];        // lines of sight through the vertices
  Vector3d side_normal[3];  // unit normals of the prism's side planes (plane e through edge e)
  double side_offset[3];
  Ownership own;
  bool ok = false;
};

PreparedTriangle prepare(const DepthFrame& f, const FrameTriangle& t) {
  PreparedTriangle p;
  Eigen::Vector2f q[3];  // sensor-plane positions
  for (int k = 0; k < 3; ++k) {
    p.idx[k] = t[k];
    p.P[k] = f.position[t[k]].cast<double>();
    q[k] = f.image_pos[t[k]];
  }
  if (!facing_normal(f.sensor, p.P, &p.normal)) return p;
  const Sensor& sensor = f.sensor;
  const bool perspective = sensor.kind == Sensor::Kind::Perspective;
  const Vector3d C = sensor.centre(), axis = sensor.axis();
  for (int k = 0; k < 3; ++k) p.dir[k] = sensor.ray_direction(p.P[k]);
  for (int e = 0; e < 3; ++e) {
    const Vector3d& A = p.P[(e + 1) % 3];
    const Vector3d& B = p.P[(e + 2) % 3];
    Vector3d m = perspective ? (A - C).cross(B - C) : (B - A).cross(axis);
    if (m.dot(p.P[e] - A) < 0) m = -m;
    const double mn = m.norm();
    if (!(mn > 0)) return p;
    p.side_normal[e] = m / mn;
    p.side_offset[e] = p.side_normal[e].dot(A);
  }
  p.ok = p.own.init(q, p.idx);
  return p;
}

// Half-space m . X >= k.
struct HalfSpace {
  Vector3d m;
  double k;
};

void contributions_at_level(const DepthFrame& frame, const PreparedTriangle& T, int level, int level_of_triangle,
                            const RootCube& root, const IntegrateOptions& options, std::vector<Contribution>& out) {
  const Sensor& sensor = frame.sensor;
  const bool perspective = sensor.kind == Sensor::Kind::Perspective;
  const Vector3d centre = sensor.centre(), axis = sensor.axis();
  const double h = root.cell_size(level);
  const double ramp = insertion_ramp(options, root, level, level_of_triangle);
  const double margin = 1e-3 * h;

  // The truncated prism swept by the lines of sight through the triangle, |distance| <= ramp,
  // as five half-spaces: three sides and two caps parallel to the triangle (below).
  HalfSpace planes[5];
  for (int e = 0; e < 3; ++e) planes[e] = {T.side_normal[e], T.side_offset[e] - margin};
  // A voxel at ray distance |d| <= ramp from the triangle lies within |n.(X - P0)| <= ramp * |n.dir|.
  double max_cos = 0;
  Vector3d corner[6];
  for (int k = 0; k < 3; ++k) {
    max_cos = std::max(max_cos, std::abs(T.normal.dot(T.dir[k])));
    corner[2 * k] = T.P[k] - ramp * T.dir[k];
    corner[2 * k + 1] = T.P[k] + ramp * T.dir[k];
  }
  const double slab = ramp * max_cos + margin;
  planes[3] = {T.normal, T.normal.dot(T.P[0]) - slab};
  planes[4] = {-T.normal, -T.normal.dot(T.P[0]) - slab};

  // March along the axis most aligned with the lines of sight: columns then run down the prism's
  // long side, and few columns miss it.
  int ax = 0;
  (T.dir[0] + T.dir[1] + T.dir[2]).cwiseAbs().maxCoeff(&ax);
  const int bx = (ax + 1) % 3, cx = (ax + 2) % 3;
  // The prism's shadow on the (b, c) plane: the convex hull of the six corners' projections,
  // grown by the margin (perspective caps bulge by far less than a cell).
  Eigen::Vector2d hull_pts[6];
  for (int k = 0; k < 6; ++k) hull_pts[k] = Eigen::Vector2d(corner[k][bx], corner[k][cx]);
  std::sort(hull_pts, hull_pts + 6, [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
  });
  Eigen::Vector2d hull[12];
  int nh = 0;
  for (int pass = 0; pass < 2; ++pass) {  // Andrew's monotone chain: lower then upper hull
    const int start = nh;
    for (int k = 0; k < 6; ++k) {
      const Eigen::Vector2d& p = hull_pts[pass == 0 ? k : 5 - k];
      while (nh >= start + 2 && cross2(hull[nh - 1] - hull[nh - 2], p - hull[nh - 2]) <= 0) --nh;
      hull[nh++] = p;
    }
    --nh;
  }
  Vector3d lo = corner[0], hi = corner[0];
  for (int k = 1; k < 6; ++k) {
    lo = lo.cwiseMin(corner[k]);
    hi = hi.cwiseMax(corner[k]);
  }
  const double pad = margin + 1e-6 * h;
  const std::int64_t n_cells = std::int64_t{1} << level;
  auto index_range = [&](int axis_id, double a, double b, std::int64_t* i0, std::int64_t* i1) {
    *i0 = std::max<std::int64_t>(0, std::int64_t(std::ceil((a - pad - root.min[axis_id]) / h)));
    *i1 = std::min<std::int64_t>(n_cells, std::int64_t(std::floor((b + pad - root.min[axis_id]) / h)));
  };
  std::int64_t b0, b1, a0, a1;
  index_range(bx, lo[bx], hi[bx], &b0, &b1);
  index_range(ax, lo[ax], hi[ax], &a0, &a1);
  if (b0 > b1 || a0 > a1) return;
  Vector3d X;
  for (std::int64_t ib = b0; ib <= b1; ++ib) {
    // The hull's extent in c along this row.
    const double yb = root.min[bx] + h * double(ib);
    double cmin = INFINITY, cmax = -INFINITY;
    for (int e = 0; e < nh; ++e) {
      const Eigen::Vector2d& p = hull[e];
      const Eigen::Vector2d& q = hull[(e + 1) % nh];
      const double lo_b = std::min(p.x(), q.x()) - pad, hi_b = std::max(p.x(), q.x()) + pad;
      if (yb < lo_b || yb > hi_b) continue;
      if (std::abs(q.x() - p.x()) <= pad) {
        cmin = std::min({cmin, p.y(), q.y()});
        cmax = std::max({cmax, p.y(), q.y()});
      } else {
        const double t = std::clamp((yb - p.x()) / (q.x() - p.x()), 0.0, 1.0);
        const double c = p.y() + t * (q.y() - p.y());
        cmin = std::min(cmin, c);
        cmax = std::max(cmax, c);
      }
    }
    if (!(cmin <= cmax)) continue;
    std::int64_t c0, c1;
    index_range(cx, cmin, cmax, &c0, &c1);
    for (std::int64_t ic = c0; ic <= c1; ++ic) {
      // Column X(t) = base + t * e_ax; clip t against the prism.
      Vector3d base;
      base[ax] = root.min[ax];
      base[bx] = root.min[bx] + h * double(ib);
      base[cx] = root.min[cx] + h * double(ic);
      // The column's bounds a0..a1 are applied in index space: a0 * h / h may round above a0.
      double tmin = -INFINITY, tmax = INFINITY;
      bool empty = false;
      for (const HalfSpace& hs : planes) {
        const double v = hs.m.dot(base) - hs.k, ma = hs.m[ax];
        if (ma == 0) {
          if (v < 0) { empty = true; break; }
        } else if (ma > 0) {
          tmin = std::max(tmin, -v / ma);
        } else {
          tmax = std::min(tmax, -v / ma);
        }
      }
      if (empty || tmin > tmax) continue;
      tmin = std::max(tmin, double(a0 - 1) * h);  // finite before the integer casts
      tmax = std::min(tmax, double(a1 + 1) * h);
      const std::int64_t i0 = std::max<std::int64_t>(a0, std::int64_t(std::ceil(tmin / h)));
      const std::int64_t i1 = std::min<std::int64_t>(a1, std::int64_t(std::floor(tmax / h)));
      for (std::int64_t ia = i0; ia <= i1; ++ia) {
        X = base;
        X[ax] += h * double(ia);
        Vector2d q;
        // Sensor::project and ray_direction, inlined with the centre hoisted out of the loop.
        const Vector3d xs = camera_point(sensor, X);
        if (perspective) {
          if (!(xs.z() > 0)) continue;
          q = pixel_of(sensor, xs);
        } else {
          q = xs.head<2>();
        }
        double E[3];
        if (!T.own.owns(q, E)) continue;
        const double plane = T.normal.dot(T.P[0] - X);
        if (beyond_ramp(plane, ramp, options)) continue;
        const double cosine = perspective ? sight_cosine(T.normal, X - centre) : T.normal.dot(axis);
        VoxelSample v;
        if (!voxel_sample(frame, T.idx, T.own, E, plane, cosine, ramp, options, &v)) continue;
        Contribution c;
        std::int64_t idx[3];
        idx[ax] = ia;
        idx[bx] = ib;
        idx[cx] = ic;
        c.key = VoxelKey::make(level, std::uint32_t(idx[0]), std::uint32_t(idx[1]), std::uint32_t(idx[2]));
        c.distance = v.distance;
        c.weight = v.weight;
        c.has_colour = v.has_colour;
        for (int k = 0; k < 3; ++k) c.colour[k] = v.colour[k];
        out.push_back(c);
      }
    }
  }
}

}  // namespace

void triangle_contributions(const DepthFrame& frame, const FrameTriangle& tri, int level, int level_of_triangle,
                            const RootCube& root, const IntegrateOptions& options, std::vector<Contribution>& out) {
  const PreparedTriangle T = prepare(frame, tri);
  if (T.ok) contributions_at_level(frame, T, level, level_of_triangle, root, options, out);
}

IntegrateStats integrate_frame_prisms(const DepthFrame& frame, const std::vector<FrameTriangle>& triangles,
                                      const RootCube& root, const IntegrateOptions& options, BrickMap& map,
                                      const BrickBox* region) {
  const int brick_level = map.brick_level();
  auto outside = [&](const Contribution& c) { return !region->contains(brick_of(c.key, brick_level)); };
  // The region in world coordinates, widened a little: a triangle reaches only voxels within a
  // ramp of it, so one whose box widened by its ramp misses this is skipped.
  Eigen::AlignedBox3d region_box;
  if (region) region_box = world_box(*region, root, brick_level);
  IntegrateStats total;
  std::mutex stats_mutex;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, triangles.size(), 2048), [&](const tbb::blocked_range<std::size_t>& r) {
    IntegrateStats local;
    std::vector<Contribution> batch;
    batch.reserve(r.size() * 16);
    for (std::size_t t = r.begin(); t != r.end(); ++t) {
      const FrameTriangle& tri = triangles[t];
      int lt = 0, coarsest = 0;
      if (!insertion_levels(frame, tri.data(), root, options, &lt, &coarsest)) continue;
      if (region) {
        Eigen::AlignedBox3d box;
        for (std::uint32_t i : tri) box.extend(frame.position[i].cast<double>());
        const double ramp = insertion_ramp(options, root, coarsest, lt);
        box.min().array() -= ramp;
        box.max().array() += ramp;
        if (!box.intersects(region_box)) continue;
      }
      const std::size_t before = batch.size();
      const PreparedTriangle T = prepare(frame, tri);
      if (T.ok)
        for (int l = lt; l >= coarsest; --l) contributions_at_level(frame, T, l, lt, root, options, batch);
      if (region) batch.erase(std::remove_if(batch.begin() + std::ptrdiff_t(before), batch.end(), outside), batch.end());
      ++local.triangles;
      ++local.triangles_per_level[lt];
      local.contributions += batch.size() - before;
      if (batch.size() > (1u << 18)) {
        map.apply(batch);
        batch.clear();
      }
    }
    map.apply(batch);
    std::lock_guard lock(stats_mutex);
    total.add(local);
  });
  return total;
}

IntegrateStats integrate_frame(const DepthFrame& frame, const std::vector<FrameTriangle>& triangles,
                               const RootCube& root, const IntegrateOptions& options, BrickMap& map,
                               const BrickBox* region, IntegrateScratch* scratch) {
  IntegrateStats stats;
  if (integrate_frame_projective(frame, triangles, root, options, map, &stats, region, scratch)) return stats;
  return integrate_frame_prisms(frame, triangles, root, options, map, region);
}

}  // namespace sf
