#pragma once
// The pure formulas of sections 5 and 6, kept apart so tests can check them by hand.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>

namespace sf {

// Equation 1: the octree level whose cell size F_box = root_size / 2^l is the largest one not
// exceeding the triangle footprint / lambda:  l_T = ceil(log2(root_size * lambda / F_tri)).
// Clamped to [0, max_level]. A ratio within 1e-6 (relative) of a power of two counts as that power,
// so that footprints stored in float do not flip a level.
// The formula itself, with log2 (the reference for triangle_level's shortcut, and its fallback).
inline int triangle_level_log2(double root_size, double lambda, double footprint, int max_level) {
  const double l = std::ceil(std::log2(root_size * lambda / footprint) - 1.5e-6);
  if (!(l > 0)) return 0;
  return int(std::min<double>(l, max_level));
}

static_assert(std::numeric_limits<double>::is_iec559, "triangle_level reads binary64 bits");

// The same level without a log2 per triangle (run for every triangle of every read of a frame):
// with ratio = m 2^e, m in [0.5, 1), log2(ratio) = e + log2(m). Unless m lies within 1e-5 of 0.5
// or 1, log2(m) stays more than 1.4e-5 from -1 and from 0, far beyond log2's rounding and the
// 1.5e-6 tolerance, so the ceiling is e; near a power of two the formula decides. m and e are read
// off the bits (what frexp does, without its libm call: 2 % of a frame's preparation); a ratio
// that is not a positive normal number goes to the formula.
inline int triangle_level(double root_size, double lambda, double footprint, int max_level) {
  const double ratio = root_size * lambda / footprint;
  const std::uint64_t bits = std::bit_cast<std::uint64_t>(ratio);
  // The biased exponent with the sign bit: above 0x7ff if negative, 0x7ff for inf and NaN, and 0
  // for zero and subnormals, which the subtraction wraps past all of them.
  const std::uint64_t biased = bits >> 52;
  if (biased - 1 >= 0x7fe) return triangle_level_log2(root_size, lambda, footprint, max_level);
  const int e = int(biased) - 1022;
  const double m = std::bit_cast<double>((bits & 0x000fffffffffffffULL) | (std::uint64_t{1022} << 52));
  if (!(m > 0.50001 && m < 0.99999)) return triangle_level_log2(root_size, lambda, footprint, max_level);
  if (e <= 0) return 0;
  return std::min(e, max_level);
}

// The ramp length of a level: gamma times its cell size.
inline double ramp_length(double gamma, double cell_size) { return gamma * cell_size; }

// Truncated tent of the signed distance over the ramp: 1 on the surface, 0 at +-ramp and beyond.
inline double tent_weight(double distance, double ramp) {
  return std::max(0.0, 1.0 - std::abs(distance) / ramp);
}

// Equations 2-3: adding one contribution (d, w) to a voxel holding (D, W).
struct DistanceWeight {
  double distance, weight;
};
inline DistanceWeight accumulate(DistanceWeight voxel, DistanceWeight sample) {
  const double W = voxel.weight + sample.weight;
  return {(voxel.weight * voxel.distance + sample.weight * sample.distance) / W, W};
}

// Equations 4-5: blending a sub-confident voxel (w_l < tau0) with the coarser level's
// interpolated (d_c, w_c). The coarser weight saturates at tau0 (Mitchell's argument).
inline DistanceWeight regularize_blend(DistanceWeight fine, DistanceWeight coarse, double tau0) {
  const double k = (tau0 - fine.weight) * std::min(1.0, coarse.weight / tau0);
  const double w = fine.weight + k;
  return {(fine.distance * fine.weight + coarse.distance * k) / w, w};
}

}  // namespace sf
