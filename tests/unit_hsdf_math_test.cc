// Sections 5-6 formulas against numbers worked out by hand.
#include "engine/hsdf_math.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "engine/fusion.h"
#include "engine/triangulate.h"
#include "storage/voxel_table.h"

namespace sf {

TEST(Equation1, LevelIsCeilOfLog2OfRootOverFootprint) {
  // Root 10 m, footprint 1 cm, λ = 1: log2(1000) = 9.97 -> level 10 (cell 9.77 mm <= 10 mm).
  EXPECT_EQ(triangle_level(10.0, 1.0, 0.01, 18), 10);
  EXPECT_LE(10.0 / 1024, 0.01);
  EXPECT_GT(10.0 / 512, 0.01);
  // Exactly a power of two: 8 m / 1 cm... 8 / 0.0625 = 128 = 2^7 -> level 7, cell == footprint.
  EXPECT_EQ(triangle_level(8.0, 1.0, 0.0625, 18), 7);
  // λ = 2 halves the allowed cell: one level deeper.
  EXPECT_EQ(triangle_level(8.0, 2.0, 0.0625, 18), 8);
  // Footprint larger than the root: level 0; tiny footprint: clamped to the deepest level.
  EXPECT_EQ(triangle_level(1.0, 1.0, 5.0, 18), 0);
  EXPECT_EQ(triangle_level(1.0, 1.0, 1e-9, 18), 18);
}

TEST(Equation1, ExponentShortcutEqualsTheLog2Formula) {
  // triangle_level reads the level off the ratio's exponent unless the ratio lies near a power of
  // two; it must agree with the formula everywhere: log-uniform ratios over 2^-30..2^40, and
  // ratios within 1e-4 (relative) of every power of two, on both sides, where it defers.
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> exponent(-30.0, 40.0), near(-1e-4, 1e-4);
  for (int i = 0; i < 400000; ++i) {
    const double ratio = i % 2 ? std::exp2(exponent(rng)) : std::ldexp(1.0 + near(rng), int(exponent(rng)));
    const double root = 3.7, lambda = i % 3 ? 1.0 : 2.0, footprint = root * lambda / ratio;
    ASSERT_EQ(triangle_level(root, lambda, footprint, 18), triangle_level_log2(root, lambda, footprint, 18))
        << "footprint " << footprint;
  }
  // Exact powers of two and their float neighbours (footprints stored in float).
  for (int k = -20; k <= 30; ++k)
    for (float f : {std::ldexp(1.0f, -k), std::nextafter(std::ldexp(1.0f, -k), 0.0f),
                    std::nextafter(std::ldexp(1.0f, -k), 1e30f)})
      EXPECT_EQ(triangle_level(1.0, 1.0, f, 18), triangle_level_log2(1.0, 1.0, f, 18)) << f;
  // Ratios that are not positive normal numbers go to the formula (root 1e-10): subnormal (a huge
  // footprint), infinite (a subnormal one), zero, negative (-1e10: read off its bits without the
  // sign it would give level 18), NaN.
  const struct {
    double footprint;
    int level;
  } odd[] = {{1e300, 0},
             {1e-320, 18},
             {std::numeric_limits<double>::infinity(), 0},
             {-1e-20, 0},
             {-0.5, 0},
             {std::numeric_limits<double>::quiet_NaN(), 0}};
  for (const auto& [footprint, level] : odd) {
    EXPECT_EQ(triangle_level(1e-10, 1.0, footprint, 18), level) << footprint;
    EXPECT_EQ(triangle_level(1e-10, 1.0, footprint, 18), triangle_level_log2(1e-10, 1.0, footprint, 18)) << footprint;
  }
}

TEST(BrickLevel, AutoIsTheFinestLevelMinus8Clamped) {
  const RootCube root{Eigen::Vector3d::Zero(), 1.6};
  IntegrateOptions o;  // lambda 1
  // 1.6 / 1 mm = 1600 -> log2 10.64 -> level 11 -> bricks of level 3.
  EXPECT_EQ(auto_brick_level(root, 1e-3, o), 3);
  // 1.6 / 0.1 mm = 16000 -> log2 13.97 -> level 14 -> 6.
  EXPECT_EQ(auto_brick_level(root, 1e-4, o), 6);
  // Coarse data clamps at 3; the deepest data at 10 (level 18 - 8).
  EXPECT_EQ(auto_brick_level(root, 0.1, o), 3);
  EXPECT_EQ(auto_brick_level(root, 1e-9, o), 10);
  // A single-level baseline bricks by its level.
  o.single_level = 12;
  EXPECT_EQ(auto_brick_level(root, 1e-3, o), 4);
}

TEST(Ramp, GammaTimesCellSize) {
  EXPECT_DOUBLE_EQ(ramp_length(8.0, 0.005), 0.04);
  EXPECT_DOUBLE_EQ(ramp_length(2.0, 0.25), 0.5);
}

TEST(TentWeight, LinearToZeroAtTheRampEnds) {
  EXPECT_DOUBLE_EQ(tent_weight(0.0, 0.04), 1.0);
  EXPECT_DOUBLE_EQ(tent_weight(0.01, 0.04), 0.75);
  EXPECT_DOUBLE_EQ(tent_weight(-0.03, 0.04), 0.25);
  EXPECT_DOUBLE_EQ(tent_weight(0.04, 0.04), 0.0);
  EXPECT_DOUBLE_EQ(tent_weight(-0.05, 0.04), 0.0);
}

TEST(Equations2And3, RunningWeightedMean) {
  // (D, W) = (0.2, 1) plus (d, w) = (-0.1, 2): W = 3, D = (0.2 - 0.2) / 3 = 0.
  DistanceWeight v = accumulate({0.2, 1.0}, {-0.1, 2.0});
  EXPECT_DOUBLE_EQ(v.weight, 3.0);
  EXPECT_NEAR(v.distance, 0.0, 1e-15);
  // then (0.3, 1): W = 4, D = 0.3 / 4 = 0.075
  v = accumulate(v, {0.3, 1.0});
  EXPECT_DOUBLE_EQ(v.weight, 4.0);
  EXPECT_DOUBLE_EQ(v.distance, 0.075);
}

TEST(Equations2And3, VoxelColourIsAveragedInFixedPointWithItsOwnWeight) {
  VoxelData v;
  const std::uint8_t c1[3] = {100, 50, 0}, c2[3] = {200, 50, 255}, black[3] = {0, 0, 0};
  accumulate(v, 0.2f, 1.0f, c1);
  EXPECT_FLOAT_EQ(v.distance, 0.2f);
  EXPECT_EQ(v.weight, 1.0f);
  EXPECT_EQ(v.colour_fixed[0], 100 * 256);
  EXPECT_EQ(v.colour_share, VoxelData::kFullShare);
  EXPECT_EQ(v.colour_weight(), 1.0f);  // exactly W while every contribution had colour
  // (d, w) = (-0.1, 3): W = 4, D = (0.2 - 0.3) / 4 = -0.025; colour (100 + 600) / 4 = 175,
  // (50 + 150) / 4 = 50, (0 + 765) / 4 = 191.25 = 48960 / 256.
  accumulate(v, -0.1f, 3.0f, c2);
  EXPECT_FLOAT_EQ(v.distance, -0.025f);
  EXPECT_EQ(v.weight, 4.0f);
  EXPECT_EQ(v.colour_fixed[0], 175 * 256);
  EXPECT_EQ(v.colour_fixed[1], 50 * 256);
  EXPECT_EQ(v.colour_fixed[2], 48960);
  EXPECT_EQ(v.colour(2), 191.25f);
  EXPECT_EQ(v.colour_weight(), 4.0f);
  // A contribution without colour (w = 4): W = 8, the colour weight stays 4, a share of
  // 0.5 x 65535 = 32767.5 -> 32768; the colour is unchanged.
  accumulate(v, 0.0f, 4.0f, nullptr);
  EXPECT_EQ(v.weight, 8.0f);
  EXPECT_EQ(v.colour_share, 32768);
  EXPECT_NEAR(v.colour_weight(), 4.0f, 1e-3f);
  EXPECT_EQ(v.colour_fixed[0], 175 * 256);
  // Then black with w = 2: Wc = 6, colour 175 x 4 / 6 = 116.67 (within one 1/256 step, the share's
  // rounding included), W = 10, share 0.6 x 65535 = 39321.
  accumulate(v, 0.0f, 2.0f, black);
  EXPECT_EQ(v.weight, 10.0f);
  EXPECT_NEAR(v.colour(0), 175.0f * 4.0f / 6.0f, 1.0f / 256.0f);
  EXPECT_NEAR(v.colour_share, 39321, 1);
  EXPECT_NEAR(v.colour_weight(), 6.0f, 1e-3f);
  // Colourless voxels stay colourless (share 0), whatever their weight.
  VoxelData g;
  accumulate(g, 0.1f, 1.0f, nullptr);
  accumulate(g, 0.1f, 1.0f, nullptr);
  EXPECT_EQ(g.colour_share, 0);
  EXPECT_EQ(g.colour_weight(), 0.0f);
}

TEST(Equations4And5, BlendWithSaturatedCoarseWeight) {
  // τ0 = 0.5, fine (d, w) = (0.1, 0.2), coarse (0.3, 2.0): min(1, 2/0.5) = 1, k = 0.3,
  // w~ = 0.5, d~ = (0.1*0.2 + 0.3*0.3) / 0.5 = 0.22.
  DistanceWeight b = regularize_blend({0.1, 0.2}, {0.3, 2.0}, 0.5);
  EXPECT_DOUBLE_EQ(b.weight, 0.5);
  EXPECT_NEAR(b.distance, 0.22, 1e-15);
  // Coarse weight 0.25 (< τ0): min(1, 0.5) = 0.5, k = 0.3 * 0.5 = 0.15, w~ = 0.35,
  // d~ = (0.02 + 0.045) / 0.35 = 0.185714...
  b = regularize_blend({0.1, 0.2}, {0.3, 0.25}, 0.5);
  EXPECT_DOUBLE_EQ(b.weight, 0.35);
  EXPECT_NEAR(b.distance, 0.065 / 0.35, 1e-15);
  // An empty fine voxel (w = 0) takes the coarse distance.
  b = regularize_blend({0.0, 0.0}, {0.3, 1.0}, 0.5);
  EXPECT_DOUBLE_EQ(b.distance, 0.3);
  EXPECT_DOUBLE_EQ(b.weight, 0.5);
}

TEST(Discontinuity, ThresholdIsRhoTimesNearerFootprint) {
  // Nearer sample at z = 2 with F = 2 mm: with ρ = 5 the gap may be up to 10 mm.
  EXPECT_FALSE(is_discontinuity(2.0f, 2.0099f, 0.002f, 0.004f, 5.0));
  EXPECT_TRUE(is_discontinuity(2.0f, 2.0101f, 0.002f, 0.004f, 5.0));
  // The nearer one's footprint counts, whichever order the samples come in.
  EXPECT_TRUE(is_discontinuity(2.0101f, 2.0f, 0.004f, 0.002f, 5.0));
}

}  // namespace sf
