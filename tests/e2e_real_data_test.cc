// Real data from ../shared/data: the paper's Stanford Bunny experiment (ten Cyberware range grids)
// and 50 Kinect frames of the 7-Scenes kitchen.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "engine/input/frame_source.h"
#include "engine/meshio/ply_io.h"
#include "engine/synth/mesh_query.h"
#include "tests/test_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

TEST(RealData, StanfordBunnyScansFuseWithinAMillimetreOfTheZipperedMesh) {
  const fs::path dir = test::scratch_dir("e2e-bunny");
  const fs::path out = dir / "bunny.ply";
  std::string log;
  ASSERT_EQ(test::run_command(test::scalefuse_binary().string() + " fuse " +
                                  (test::shared_data() / "stanford_bunny" / "scans").string() + " --config " +
                                  SCALEFUSE_SOURCE_DIR + "/configs/laser.toml -q -o " + out.string(),
                              &log),
            0)
      << log;
  const fs::path ref = test::shared_data() / "stanford_bunny" / "reconstruction" / "bun_zipper.ply";
  const fs::path json_out = dir / "eval.json";
  ASSERT_EQ(test::run_command(test::scalefuse_binary().string() + " eval " + out.string() + " " + ref.string() +
                                  " --tau 0.001 --json -q > " + json_out.string(),
                              &log),
            0)
      << log;
  const auto j = nlohmann::json::parse(std::ifstream(json_out));
  const double accuracy = j["accuracy"]["mean"], completeness = j["completeness"]["mean"];
  std::printf("bunny: accuracy mean %.3f mm, completeness mean %.3f mm, F@1mm %.4f\n", 1e3 * accuracy,
              1e3 * completeness, double(j["scores"][0]["fscore"]));
  EXPECT_LT(accuracy, 0.001);
  EXPECT_LT(completeness, 0.001);
  EXPECT_GT(double(j["scores"][0]["fscore"]), 0.95);
  // Closed-looking: few boundary edges relative to the mesh (the zippered reference itself has
  // five holes in the bottom, which the scans never saw).
  const Mesh mesh = read_ply_mesh(out);
  std::vector<std::pair<std::uint32_t, std::uint32_t>> edges;
  for (const auto& f : mesh.faces)
    for (int k = 0; k < 3; ++k) edges.push_back(std::minmax(f[k], f[(k + 1) % 3]));
  std::sort(edges.begin(), edges.end());
  std::size_t boundary = 0;
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j2 = i;
    while (j2 < edges.size() && edges[j2] == edges[i]) ++j2;
    boundary += (j2 - i == 1);
    i = j2;
  }
  std::printf("bunny: %zu triangles, %zu boundary edges\n", mesh.faces.size(), boundary);
  EXPECT_LT(double(boundary), 0.01 * double(edges.size()));
}

TEST(RealData, SevenScenesKitchenFusesIntoTheObservedSurfaces) {
  const fs::path data = test::shared_data() / "7scenes_50frames";
  const fs::path dir = test::scratch_dir("e2e-kitchen");
  const fs::path out = dir / "kitchen.ply";
  std::string log;
  ASSERT_EQ(test::run_command(test::scalefuse_binary().string() + " fuse " + data.string() + " --config " +
                                  SCALEFUSE_SOURCE_DIR + "/configs/rgbd.toml --set input.frame_step=5 -q -o " + out.string(),
                              &log),
            0)
      << log;
  const Mesh mesh = read_ply_mesh(out);
  ASSERT_GT(mesh.faces.size(), 100000u);
  ASSERT_EQ(mesh.colours.size(), mesh.vertices.size());
  // The mesh lies on what the camera saw: most valid depth samples of a first, middle and last
  // frames are within 2 cm of it (Kinect v1 depth noise at 1-3 m is about 0.5-2 cm).
  const MeshQuery query(mesh);
  const auto source = open_input(data, InputOptions{});
  for (std::size_t i : {std::size_t(0), std::size_t(25), std::size_t(45)}) {  // fused frames (step 5)
    const DepthFrame f = source->load(i);
    std::size_t near = 0, total = 0;
    for (std::size_t k = 0; k < f.size(); k += 97) {
      if (!f.valid[k]) continue;
      ++total;
      near += query.squared_distance(f.position[k].cast<double>()) < 0.02 * 0.02;
    }
    std::printf("kitchen frame %zu: %.1f%% of samples within 2 cm of the mesh\n", i, 100.0 * near / total);
    EXPECT_GT(double(near) / double(total), 0.9) << f.name;
  }
}

}  // namespace
}  // namespace sf
