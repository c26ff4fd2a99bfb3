// Surface extraction throughput (voxels per second through the whole extract_surface) on a band
// of voxels around a sphere, with 1 and 2 threads in one run so the ratio is meaningful on a
// noisy machine. Prints the time of each progress stage.
//   cmake -S . -B build-bench -DSCALEFUSE_BUILD_BENCH=ON && cmake --build build-bench -j2 --target extract_bench
//   build-bench/bin/extract_bench [level=8] [band_cells=3] [threads=1,2]
// or against sf_extract alone (from a build dir that has built it):
//   g++ -O3 -DNDEBUG -std=c++20 -I.. -I/usr/include/eigen3 ../bench/extract_bench.cc libsf_extract.a
//       -o extract_bench -ltbb -ltbbmalloc -lgmp   (one command)
// level 8 with a 3-cell band on each side is about 1.0 M voxels (sphere radius 0.45 of the root).
#include <tbb/task_arena.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "engine/extract/extract.h"

using namespace sf;
using Clock = std::chrono::steady_clock;

static std::vector<SurfaceVoxel> sphere_band(const RootCube& root, int level, double band_cells, double radius) {
  std::vector<SurfaceVoxel> out;
  const std::uint32_t n = 1u << level;
  const double h = root.cell_size(level);
  const Eigen::Vector3d c = root.min + Eigen::Vector3d::Constant(root.size / 2);
  for (std::uint32_t z = 0; z <= n; ++z)
    for (std::uint32_t y = 0; y <= n; ++y)
      for (std::uint32_t x = 0; x <= n; ++x) {
        const VoxelKey k = VoxelKey::make(level, x, y, z);
        const Eigen::Vector3d p = root.position(k);
        const double d = (p - c).norm() - radius;
        if (std::abs(d) >= band_cells * h) continue;
        SurfaceVoxel v;
        v.key = k;
        v.distance = float(d);
        v.weight = 1;
        v.colour = {128, 128, 128};
        out.push_back(v);
      }
  return out;
}

int main(int argc, char** argv) {
  const int level = argc > 1 ? std::atoi(argv[1]) : 8;
  const double band_cells = argc > 2 ? std::atof(argv[2]) : 3.0;
  std::vector<int> thread_counts{1, 2};
  if (argc > 3) thread_counts = {std::atoi(argv[3])};
  RootCube root;
  root.min = Eigen::Vector3d(-0.61, -0.57, -0.63);
  root.size = 1.3;
  const std::vector<SurfaceVoxel> voxels = sphere_band(root, level, band_cells, 0.45 * root.size);
  std::printf("%zu voxels (level %d, band +-%.1f cells)\n", voxels.size(), level, band_cells);
  for (int threads : thread_counts) {
    tbb::task_arena arena(threads);
    std::vector<std::pair<std::string, double>> marks;  // "stage done/total" -> seconds
    const Clock::time_point start = Clock::now();
    const ProgressFn progress = [&](std::string_view stage, double done, double total) {
      if (stage == "tetrahedralize" && done != 0 && done != total) return;
      char name[64];
      std::snprintf(name, sizeof(name), "%.*s %.0f/%.0f", int(stage.size()), stage.data(), done, total);
      marks.emplace_back(name, std::chrono::duration<double>(Clock::now() - start).count());
    };
    ExtractStats st;
    Mesh mesh;
    arena.execute([&] { mesh = extract_surface(voxels, root, ExtractOptions(), progress, &st); });
    const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
    std::printf("%d thread(s): %.2f s, %.0f voxels/s\n", threads, seconds, double(voxels.size()) / seconds);
    for (const auto& [name, t] : marks) std::printf("  %-32s at %.2f s\n", name.c_str(), t);
    std::printf("  %zu tetrahedra, %zu kept, %zu snapped, %zu triangles, %zu vertices\n", st.tetrahedra,
                st.kept_tetrahedra, st.snapped_voxels, st.triangles, mesh.vertices.size());
  }
  return 0;
}
