// Integration throughput (depth samples per second) on synthetic 640x480 depth maps of a sphere,
// with 1 and 2 threads in one run so the ratio is meaningful on a noisy machine.
//   cmake -S . -B build-bench -DSCALEFUSE_BUILD_BENCH=ON && cmake --build build-bench -j2 --target integrate_bench
//   build-bench/bin/integrate_bench [frames=8] [gamma=4] [methods=all|voxel|prisms]
// Compares the voxel-centric enumeration (the default for perspective frames) with the prism
// enumeration (range grids) on the same frames.
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "engine/depth_frame.h"
#include "engine/integrate.h"
#include "engine/triangulate.h"
#include "scheduler/huge_pages.h"
#include "storage/brick_map.h"

using namespace sf;

static DepthFrame sphere_view(double angle) {
  // Unit sphere at the origin seen from distance 3 at `angle` around the y axis.
  DepthFrame f;
  f.width = 640;
  f.height = 480;
  f.sensor.fx = f.sensor.fy = 600;
  f.sensor.cx = 320;
  f.sensor.cy = 240;
  const Eigen::Vector3d C(3 * std::sin(angle), 0.3, -3 * std::cos(angle));
  const Eigen::Vector3d z = (-C).normalized(), x = Eigen::Vector3d::UnitY().cross(z).normalized(), y = z.cross(x);
  f.sensor.R.row(0) = x;
  f.sensor.R.row(1) = y;
  f.sensor.R.row(2) = z;
  f.sensor.t = -f.sensor.R * C;
  std::vector<float> depth(f.size(), 0.f);
  for (int r = 0; r < f.height; ++r)
    for (int c = 0; c < f.width; ++c) {
      const Eigen::Vector3d d = f.sensor.R.transpose() * Eigen::Vector3d((c + 0.5 - 320) / 600, (r + 0.5 - 240) / 600, 1);
      const Eigen::Vector3d u = d.normalized();
      const double b = C.dot(u), disc = b * b - (C.squaredNorm() - 1);
      if (disc < 0) continue;
      const double t = -b - std::sqrt(disc);
      depth[r * f.width + c] = float(t / d.norm());  // z-depth
    }
  fill_perspective_samples(f, depth, false);
  return f;
}

int main(int argc, char** argv) {
  sf::reexec_with_heap_tunables(argv);  // measure with the heap the command-line program has
  const int frames = argc > 1 ? std::atoi(argv[1]) : 8;
  IntegrateOptions opt;
  if (argc > 2) opt.gamma = std::atof(argv[2]);
  const std::string only = argc > 3 ? argv[3] : "all";
  std::vector<DepthFrame> views;
  std::vector<std::vector<FrameTriangle>> tris;
  std::size_t samples = 0;
  for (int i = 0; i < frames; ++i) {
    views.push_back(sphere_view(0.4 * i));
    tris.push_back(triangulate(views.back(), {}));
    samples += views.back().valid_count();
  }
  const RootCube root{Eigen::Vector3d::Constant(-1.1), 2.2};
  std::printf("%d frames, %zu samples, gamma %.1f, %d coarser levels\n", frames, samples, opt.gamma, opt.coarser_levels);
  struct Method {
    const char* name;
    IntegrateStats (*run)(const DepthFrame&, const std::vector<FrameTriangle>&, const RootCube&, const IntegrateOptions&,
                          BrickMap&, IntegrateScratch&);
  };
  // The voxel-centric path reuses its tables across depth maps, as the pipeline's integrating stage does.
  const Method methods[] = {
      {"voxel-centric (default)",
       [](const DepthFrame& f, const std::vector<FrameTriangle>& t, const RootCube& r, const IntegrateOptions& o,
          BrickMap& m, IntegrateScratch& s) { return integrate_frame(f, t, r, o, m, nullptr, &s); }},
      {"prisms", [](const DepthFrame& f, const std::vector<FrameTriangle>& t, const RootCube& r,
                    const IntegrateOptions& o, BrickMap& m, IntegrateScratch&) {
         return integrate_frame_prisms(f, t, r, o, m, nullptr);
       }}};
  for (const Method& method : methods)
  for (int threads : {1, 2}) {
    if (only != "all" && std::string(method.name).rfind(only, 0) != 0) continue;
    std::vector<double> runs;
    std::size_t contributions = 0, voxels = 0;
    for (int rep = 0; rep < 3; ++rep) {
      BrickMap map(4);
      tbb::task_arena arena(threads);
      IntegrateScratch scratch;
      const auto t0 = std::chrono::steady_clock::now();
      arena.execute([&] {
        contributions = 0;
        for (int i = 0; i < frames; ++i) contributions += method.run(views[i], tris[i], root, opt, map, scratch).contributions;
      });
      runs.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      voxels = map.voxel_count();
      if (rep == 0 && threads == 1) {
        std::size_t blocks = 0, bytes = 0;
        for (Brick* b : map.bricks()) {
          blocks += b->voxels.block_count();
          bytes += b->voxels.memory_bytes();
        }
        std::printf("%s: %zu voxels in %zu blocks, %.1f voxels/block, %.1f bytes/voxel\n", method.name, voxels, blocks,
                    double(voxels) / blocks, double(bytes) / voxels);
      }
    }
    std::sort(runs.begin(), runs.end());
    const double med = runs[1];
    std::printf("  threads %d: median %.3f s, %.2f M samples/s (%.2f M/s per thread), %.1f contributions/sample\n", threads,
                med, samples / med / 1e6, samples / med / 1e6 / threads, double(contributions) / samples);
  }
}
