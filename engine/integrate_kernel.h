#pragma once
// The per-voxel arithmetic of section 5 shared by both ways of finding a triangle's voxels
// (prisms per triangle, engine/integrate.cc; voxel-centric per image tile,
// engine/integrate_projective.cc). Both must decide ownership and compute distances with the very
// same operations, so that the two enumerations give bit-identical fields.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#if defined(__SSE2__) && defined(__x86_64__)
#include <immintrin.h>
#endif

#include "engine/depth_frame.h"
#include "engine/hsdf_math.h"
#include "engine/integrate.h"

namespace sf::integrate_detail {

inline double cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() * b.y() - a.y() * b.x(); }

// Camera coordinates R X + t of a world point whose terms R(i, a) X[a] are `terms[a][i]`, summed
// in the order Eigen 3.4's SSE2 product sums them (rows 0 and 1 left to right, row 2 its last two
// terms first), so that fields are those of `R * X + t`. Both enumerations project with this, so
// they agree to the bit; the projective one computes the terms of a column's fixed axes once.
inline Eigen::Vector3d camera_point(const double terms[3][3], const Eigen::Vector3d& t) {
  return {((terms[0][0] + terms[1][0]) + terms[2][0]) + t.x(), ((terms[0][1] + terms[1][1]) + terms[2][1]) + t.y(),
          (terms[0][2] + (terms[1][2] + terms[2][2])) + t.z()};
}
inline void camera_terms(const Eigen::Matrix3d& R, const Eigen::Vector3d& X, int a, double terms[3][3]) {
  for (int i = 0; i < 3; ++i) terms[a][i] = R(i, a) * X[a];
}
inline Eigen::Vector3d camera_point(const Sensor& s, const Eigen::Vector3d& X) {
  double terms[3][3];
  for (int a = 0; a < 3; ++a) camera_terms(s.R, X, a, terms);
  return camera_point(terms, s.t);
}

// Pixel coordinates of camera-frame point xs (z > 0), one division for both axes. Both
// enumerations project with this, so their ownership decisions agree bit for bit.
inline Eigen::Vector2d pixel_of(const Sensor& s, const Eigen::Vector3d& xs) {
  const double iz = 1.0 / xs.z();
  return {s.fx * xs.x() * iz + s.cx, s.fy * xs.y() * iz + s.cy};
}

// Ownership of lines of sight by a triangle in the sensor plane. Edge e joins local vertices
// lo, hi, ordered by sample index, so the triangle on the other side of the edge evaluates a
// bit-identical edge function and exactly one of the two owns each point of the edge. The vertices
// come as the frame stores them (float) and are widened, which is exact; each edge keeps its start
// and its direction in double, computed once rather than at every point tested (the owner test
// runs for every voxel of an enumeration, and again where the first guess fails).
struct Ownership {
  double ax[3], ay[3];  // edge e's start (vertex lo)
  double dx[3], dy[3];  // edge e's direction: vertex hi - vertex lo
  double inv_opp[3];    // 1 / edge function of edge e at the opposite vertex e (never 0)
  bool positive[3];     // the triangle lies on the positive side of edge e

  // The edge function of edge e at p: cross2(direction, p - start).
  double edge(int e, const Eigen::Vector2d& p) const { return dx[e] * (p.y() - ay[e]) - dy[e] * (p.x() - ax[e]); }
  // The same for a triangle of pixel centres set up in the quad at (0, 0) (starts 0.5 or 1.5,
  // directions -1, 0 or 1) and moved by whole pixels (col, row), at p given in the moved quad's
  // coordinates U = p.x - col, V = p.y - row. For p at least half a pixel right of and below
  // (col, row) and less than 2.5 beyond, U, V, V - ay and p.y - (row + ay) are all exact
  // (multiples of p's ulp, below 2 in size), so this gives the bits of the moved triangle's own
  // edge(), and one Ownership serves every quad of its shape.
  double edge_local(int e, double U, double V) const { return dx[e] * (V - ay[e]) - dy[e] * (U - ax[e]); }
  // All three edge_local() values; edges 0 and 1 in two lanes where there are SSE2 lanes (the same
  // products and differences, so the same bits).
  void edges_local(double U, double V, double E[3]) const {
#if defined(__SSE2__) && defined(__x86_64__)
    const __m128d dv = _mm_sub_pd(_mm_set1_pd(V), _mm_loadu_pd(ay));
    const __m128d du = _mm_sub_pd(_mm_set1_pd(U), _mm_loadu_pd(ax));
    _mm_storeu_pd(E, _mm_sub_pd(_mm_mul_pd(_mm_loadu_pd(dx), dv), _mm_mul_pd(_mm_loadu_pd(dy), du)));
    E[2] = edge_local(2, U, V);
#else
    for (int e = 0; e < 3; ++e) E[e] = edge_local(e, U, V);
#endif
  }
  // Sets the fields; false if the triangle is degenerate in the sensor plane.
  bool init(const Eigen::Vector2f q[3], const std::uint32_t idx[3]) {
    for (int e = 0; e < 3; ++e) {  // edge e is opposite vertex e
      int a = (e + 1) % 3, b = (e + 2) % 3;
      if (idx[a] > idx[b]) std::swap(a, b);
      const Eigen::Vector2d start = q[a].cast<double>(), direction = q[b].cast<double>() - start;
      ax[e] = start.x(), ay[e] = start.y();
      dx[e] = direction.x(), dy[e] = direction.y();
      const double v = edge(e, q[e].cast<double>());
      if (v == 0 || !std::isfinite(v)) return false;
      positive[e] = v > 0;
      inv_opp[e] = 1.0 / v;
    }
    return true;
  }
  // True if the triangle owns the line of sight through p; `E` receives the edge functions at p,
  // from which bary() gives the barycentric coordinates (apart, as most owned voxels of an
  // enumeration lie off the ramp and never need them).
  bool owns(const Eigen::Vector2d& p, double E[3]) const {
    return owns_by([&](int e) { return edge(e, p); }, E);
  }
  // owns() for the triangle moved by whole pixels, in the moved quad's coordinates (edge_local()).
  bool owns_local(double U, double V, double E[3]) const {
    return owns_by([&](int e) { return edge_local(e, U, V); }, E);
  }
  void bary(const double E[3], double out[3]) const {
    for (int e = 0; e < 3; ++e) out[e] = E[e] * inv_opp[e];
  }

 private:
  template <typename EdgeAt>
  bool owns_by(EdgeAt edge_at, double E[3]) const {
    bool inside = true;
    for (int e = 0; e < 3; ++e) {
      E[e] = edge_at(e);
      // positive ? E >= 0 : E < 0, without a branch: the side is a coin toss for the many
      // points near an edge, and a mispredicted branch costs more than both comparisons.
      inside &= (positive[e] & (E[e] >= 0)) | (!positive[e] & (E[e] < 0));
    }
    return inside;
  }
};

// The unit normal of triangle (P0, P1, P2), turned to face the sensor; false if degenerate.
// `centre` is the sensor's centre (perspective; ignored for orthographic sensors), passed in so
// that a frame's triangles do not each recompute it. The side is the sign of the normal's dot
// product with the line of sight to the centroid, which needs no unit line of sight.
inline bool facing_normal(const Sensor& sensor, const Eigen::Vector3d& centre, const Eigen::Vector3d P[3],
                          Eigen::Vector3d* normal) {
  Eigen::Vector3d n = (P[1] - P[0]).cross(P[2] - P[0]);
  const double len = n.norm();
  if (!(len > 0)) return false;
  n /= len;
  const Eigen::Vector3d centroid = (P[0] + P[1] + P[2]) / 3.0;
  const Eigen::Vector3d sight =
      sensor.kind == Sensor::Kind::Orthographic ? sensor.axis() : Eigen::Vector3d(centroid - centre);
  if (n.dot(sight) > 0) n = -n;
  *normal = n;
  return true;
}
inline bool facing_normal(const Sensor& sensor, const Eigen::Vector3d P[3], Eigen::Vector3d* normal) {
  return facing_normal(sensor, sensor.centre(), P, normal);
}

// The region's bricks in world coordinates, widened a little (for culling triangles that cannot
// reach it: a triangle writes only within a ramp of itself).
inline Eigen::AlignedBox3d world_box(const BrickBox& region, const RootCube& root, int brick_level) {
  const double bs = root.cell_size(brick_level), pad = 1e-6 * bs;
  const Eigen::Vector3d lo(region.lo.x, region.lo.y, region.lo.z), hi(region.hi.x, region.hi.y, region.hi.z);
  return {root.min + lo * bs - Eigen::Vector3d::Constant(pad), root.min + hi * bs + Eigen::Vector3d::Constant(pad)};
}

// The ramp of a triangle of level `level_of_triangle` inserted at `level` (<= it).
inline double insertion_ramp(const IntegrateOptions& o, const RootCube& root, int level, int level_of_triangle) {
  double ramp = ramp_length(o.gamma, root.cell_size(level));
  if (level < level_of_triangle && o.coarse_reach > 0)
    ramp = std::min(ramp, o.coarse_reach * ramp_length(o.gamma, root.cell_size(level_of_triangle)));
  return ramp;
}

// Level of equation 1 and the coarsest insertion level of a triangle; false if it is not inserted.
inline bool insertion_levels(const DepthFrame& f, const std::uint32_t idx[3], const RootCube& root,
                             const IntegrateOptions& o, int* level, int* coarsest) {
  const float footprint = std::min({f.footprint[idx[0]], f.footprint[idx[1]], f.footprint[idx[2]]});
  if (!(footprint > 0)) return false;
  if (o.single_level >= 0) {
    *level = *coarsest = o.single_level;
    return true;
  }
  *level = triangle_level(root.size, o.lambda, footprint, o.max_level);
  *coarsest = std::max(0, *level - o.coarser_levels);
  return true;
}

// True if voxel_sample() is sure to reject the voxel at X for lying beyond the ramp, decided
// without its line of sight: |distance along the ray| = |plane distance| / |cosine| >= |plane
// distance|, and the floating-point division keeps that order. Saves the square root for the many
// voxels of an enumeration's bounding slab that lie off the ramp.
// `plane` = normal . (P0 - X): the ray distance times the cosine, which is < 0 for any voxel accepted.
inline bool beyond_ramp(double plane, double ramp, const IntegrateOptions& options) {
  const bool in_front = plane > 0;  // both sides compared, no branch: the side is unpredictable
  return (in_front & (plane > ramp * options.behind)) | (!in_front & (-plane > ramp));
}

// The cosine between the triangle's normal and the line of sight D (from the sensor to the voxel,
// any length): one square root and one division instead of normalizing D.
inline double sight_cosine(const Eigen::Vector3d& normal, const Eigen::Vector3d& D) {
  return normal.dot(D) / std::sqrt(D.squaredNorm());
}

// std::clamp(std::lround(v), 0, 255) bit for bit, without lround's libm call (baseline x86-64 has
// no rounding instruction), which was a visible share of the per-voxel cost. v - trunc(v) is exact.
inline std::uint8_t colour_byte(double v) {
  if (!(v > 0)) return 0;
  if (v >= 255) return 255;
  const int i = int(v);
  return std::uint8_t(i + (v - double(i) >= 0.5 ? 1 : 0));
}

// A vertex colour as one word, c0 | c1 << 8 | c2 << 16: the voxel-centric path packs a frame's
// colours once, so that a contribution loads each vertex's colour once rather than byte by byte.
inline std::uint32_t packed_colour(const Rgb8& c) {
  return std::uint32_t(c[0]) | (std::uint32_t(c[1]) << 8) | (std::uint32_t(c[2]) << 16);
}

// The colour at barycentric coordinates `bary` of vertex colours c[0..2] (packed_colour), each
// channel colour_byte((bary0 c0 + bary1 c1) + bary2 c2): the reference for interpolate_colour.
inline void interpolate_colour_scalar(const double bary[3], const std::uint32_t c[3], std::uint8_t out[3]) {
  for (int k = 0; k < 3; ++k) {
    const auto channel = [&](int j) { return double((c[j] >> (8 * k)) & 255); };
    out[k] = colour_byte(bary[0] * channel(0) + bary[1] * channel(1) + bary[2] * channel(2));
  }
}

#if defined(__SSE2__) && defined(__x86_64__)
// colour_byte per lane, as 32-bit integers in lanes 0 and 1: max/min clamp (a NaN or -0 becomes
// 0, as !(v > 0) does), truncate, and add one where the fraction is at least 0.5.
inline __m128i colour_bytes_lanes(__m128d v) {
  v = _mm_min_pd(_mm_max_pd(v, _mm_setzero_pd()), _mm_set1_pd(255.0));
  const __m128i i = _mm_cvttpd_epi32(v);
  const __m128d up = _mm_cmpge_pd(_mm_sub_pd(v, _mm_cvtepi32_pd(i)), _mm_set1_pd(0.5));
  return _mm_sub_epi32(i, _mm_shuffle_epi32(_mm_castpd_si128(up), _MM_SHUFFLE(3, 3, 2, 0)));
}

// Channels 0 and 1 in one register, 2 in another: the same products and sums, lane by lane, as
// interpolate_colour_scalar (so the same bits), without the scalar code's six branches per
// contribution (the run's branches 0.878x, bench/README.md session 32).
inline void interpolate_colour(const double bary[3], const std::uint32_t c[3], std::uint8_t out[3]) {
  const __m128i zero = _mm_setzero_si128();
  __m128d lo = _mm_setzero_pd(), hi = _mm_setzero_pd();
  for (int j = 0; j < 3; ++j) {
    const __m128i i32 = _mm_unpacklo_epi16(_mm_unpacklo_epi8(_mm_cvtsi32_si128(int(c[j])), zero), zero);
    const __m128d b = _mm_set1_pd(bary[j]);
    const __m128d plo = _mm_mul_pd(b, _mm_cvtepi32_pd(i32)), phi = _mm_mul_pd(b, _mm_cvtepi32_pd(_mm_srli_si128(i32, 8)));
    lo = j == 0 ? plo : _mm_add_pd(lo, plo);
    hi = j == 0 ? phi : _mm_add_pd(hi, phi);
  }
  const __m128i a = colour_bytes_lanes(lo), b = colour_bytes_lanes(hi);
  out[0] = std::uint8_t(_mm_cvtsi128_si32(a));
  out[1] = std::uint8_t(_mm_cvtsi128_si32(_mm_srli_si128(a, 4)));
  out[2] = std::uint8_t(_mm_cvtsi128_si32(b));
}

// interpolate_colour for two contributions at once (the sample phase's two lanes), their six
// channels in three registers rather than four: (first 0, first 1), (first 2, second 0),
// (second 1, second 2), each lane with interpolate_colour_scalar's products and sums in its order.
inline void interpolate_colour_pair(const double bary0[3], const double bary1[3], const std::uint32_t c0[3],
                                    const std::uint32_t c1[3], std::uint8_t out0[3], std::uint8_t out1[3]) {
  const __m128i zero = _mm_setzero_si128();
  __m128d a = _mm_setzero_pd(), b = _mm_setzero_pd(), c = _mm_setzero_pd();
  for (int j = 0; j < 3; ++j) {
    // Six bytes: the first's channels 0-2, the second's 0-2 (packed_colour leaves byte 3 zero).
    const std::uint64_t both = std::uint64_t(c0[j]) | (std::uint64_t(c1[j]) << 24);
    const __m128i u16 = _mm_unpacklo_epi8(_mm_cvtsi64_si128(std::int64_t(both)), zero);
    const __m128i first = _mm_unpacklo_epi16(u16, zero), second = _mm_unpackhi_epi16(u16, zero);
    const __m128d pa = _mm_mul_pd(_mm_set1_pd(bary0[j]), _mm_cvtepi32_pd(first));
    const __m128d pb = _mm_mul_pd(_mm_set_pd(bary1[j], bary0[j]), _mm_cvtepi32_pd(_mm_srli_si128(first, 8)));
    const __m128d pc = _mm_mul_pd(_mm_set1_pd(bary1[j]), _mm_cvtepi32_pd(second));
    a = j == 0 ? pa : _mm_add_pd(a, pa);
    b = j == 0 ? pb : _mm_add_pd(b, pb);
    c = j == 0 ? pc : _mm_add_pd(c, pc);
  }
  const __m128i ia = colour_bytes_lanes(a), ib = colour_bytes_lanes(b), ic = colour_bytes_lanes(c);
  out0[0] = std::uint8_t(_mm_cvtsi128_si32(ia));
  out0[1] = std::uint8_t(_mm_cvtsi128_si32(_mm_srli_si128(ia, 4)));
  out0[2] = std::uint8_t(_mm_cvtsi128_si32(ib));
  out1[0] = std::uint8_t(_mm_cvtsi128_si32(_mm_srli_si128(ib, 4)));
  out1[1] = std::uint8_t(_mm_cvtsi128_si32(ic));
  out1[2] = std::uint8_t(_mm_cvtsi128_si32(_mm_srli_si128(ic, 4)));
}

#if defined(__GNUC__)
// interpolate_colour_scalar for four contributions, one per AVX2 lane (integrate_projective.cc's
// sample phase, where the CPU has AVX2): bary[j] holds vertex j's barycentric coordinate in each
// lane and c[j] its packed colour; returns each lane's channels as a packed_colour word. Each
// channel is the scalar reference's products and sums in its order, and colour_byte's clamp,
// truncation and rounding up, so the same bytes.
__attribute__((target("avx2"))) inline __m128i colour_bytes_quad(__m256d v) {
  v = _mm256_min_pd(_mm256_max_pd(v, _mm256_setzero_pd()), _mm256_set1_pd(255.0));
  const __m128i i = _mm256_cvttpd_epi32(v);
  const __m256d up = _mm256_cmp_pd(_mm256_sub_pd(v, _mm256_cvtepi32_pd(i)), _mm256_set1_pd(0.5), _CMP_GE_OQ);
  // Each lane's 64-bit mask as a 32-bit one (-1 where it rounds up).
  const __m256i low_halves = _mm256_setr_epi32(0, 2, 4, 6, 0, 2, 4, 6);
  return _mm_sub_epi32(i, _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(_mm256_castpd_si256(up), low_halves)));
}
__attribute__((target("avx2"))) inline __m128i interpolate_colour_quad(const __m256d bary[3], const __m128i c[3]) {
  const __m128i byte = _mm_set1_epi32(255);
  __m256d channel[3];
  for (int j = 0; j < 3; ++j)
    for (int k = 0; k < 3; ++k) {
      const __m256d term = _mm256_mul_pd(bary[j], _mm256_cvtepi32_pd(_mm_and_si128(_mm_srli_epi32(c[j], 8 * k), byte)));
      channel[k] = j == 0 ? term : _mm256_add_pd(channel[k], term);
    }
  return _mm_or_si128(colour_bytes_quad(channel[0]), _mm_or_si128(_mm_slli_epi32(colour_bytes_quad(channel[1]), 8),
                                                                  _mm_slli_epi32(colour_bytes_quad(channel[2]), 16)));
}
// The same on arrays (for tests): bary[j][lane], c[j][lane], out[lane].
__attribute__((target("avx2"))) inline void interpolate_colour_quad(const double bary[3][4], const std::uint32_t c[3][4],
                                                                    std::uint32_t out[4]) {
  __m256d b[3];
  __m128i w[3];
  for (int j = 0; j < 3; ++j) {
    b[j] = _mm256_loadu_pd(bary[j]);
    w[j] = _mm_loadu_si128(reinterpret_cast<const __m128i*>(c[j]));
  }
  _mm_storeu_si128(reinterpret_cast<__m128i*>(out), interpolate_colour_quad(b, w));
}
#endif
#else
inline void interpolate_colour(const double bary[3], const std::uint32_t c[3], std::uint8_t out[3]) {
  interpolate_colour_scalar(bary, c, out);
}
inline void interpolate_colour_pair(const double bary0[3], const double bary1[3], const std::uint32_t c0[3],
                                    const std::uint32_t c1[3], std::uint8_t out0[3], std::uint8_t out1[3]) {
  interpolate_colour_scalar(bary0, c0, out0);
  interpolate_colour_scalar(bary1, c1, out1);
}
#endif

// Signed distance and weight of a voxel whose line of sight the triangle `own` owns with edge
// functions E; `plane` = normal . (P0 - X), `cosine` = sight_cosine(normal, line of sight). False
// if the voxel gets nothing.
struct VoxelSample {
  float distance, weight;
  std::uint8_t colour[3];
  bool has_colour;
};
// A contribution's colour: the vertex colours interpolated at barycentric coordinates `bary`
// (none if the frame has no colour). `packed`, if given, holds them as packed_colour words.
inline void sample_colour(const DepthFrame& frame, const std::uint32_t idx[3], const double bary[3],
                          const std::uint32_t* packed, VoxelSample* out) {
  out->has_colour = !frame.colour.empty();
  if (out->has_colour) {
    const auto colour_of = [&](std::uint32_t i) { return packed ? packed[i] : packed_colour(frame.colour[i]); };
    const std::uint32_t c[3] = {colour_of(idx[0]), colour_of(idx[1]), colour_of(idx[2])};
    interpolate_colour(bary, c, out->colour);
  } else {
    out->colour[0] = out->colour[1] = out->colour[2] = 0;
  }
}
// sample_colour for two contributions at once (the voxel-centric sample phase's two lanes, which
// may be one contribution twice); `packed` holds the frame's colours as packed_colour words, null
// if it has none.
inline void sample_colour_pair(const std::uint32_t idx0[3], const std::uint32_t idx1[3], const double bary0[3],
                               const double bary1[3], const std::uint32_t* packed, VoxelSample* s0,
                               VoxelSample* s1) {
  s0->has_colour = s1->has_colour = packed != nullptr;
  if (packed) {
    const std::uint32_t c0[3] = {packed[idx0[0]], packed[idx0[1]], packed[idx0[2]]};
    const std::uint32_t c1[3] = {packed[idx1[0]], packed[idx1[1]], packed[idx1[2]]};
    interpolate_colour_pair(bary0, bary1, c0, c1, s0->colour, s1->colour);  // s0 == s1: the same bytes twice
  } else {
    for (int k = 0; k < 3; ++k) s0->colour[k] = s1->colour[k] = 0;
  }
}
// `packed`, if given, holds the frame's colours as packed_colour words.
inline bool voxel_sample(const DepthFrame& frame, const std::uint32_t idx[3], const Ownership& own, const double E[3],
                         double plane, double cosine, double ramp, const IntegrateOptions& options, VoxelSample* out,
                         const std::uint32_t* packed = nullptr) {
  if (!(-cosine >= options.min_cosine)) return false;  // cosine < 0: the normal faces the sensor
  const double distance = plane / cosine;  // > 0: in front of the surface
  if (distance < 0) ramp *= options.behind;  // the ramp behind the surface may be shorter
  if (!(std::abs(distance) <= ramp)) return false;
  double bary[3];
  own.bary(E, bary);
  double conf = 1.0;
  if (!frame.confidence.empty())
    conf = bary[0] * frame.confidence[idx[0]] + bary[1] * frame.confidence[idx[1]] + bary[2] * frame.confidence[idx[2]];
  const double weight = -cosine * tent_weight(distance, ramp) * conf;
  if (!(weight > 0)) return false;
  out->distance = float(distance);
  out->weight = float(weight);
  sample_colour(frame, idx, bary, packed, out);
  return true;
}

}  // namespace sf::integrate_detail
