// End to end on a synthetic multi-scale scene of a real scanned mesh (igea, noise-free):
// 30 far views of 80x60 and 4 close views of 240x180 with footprints 14x apart, written as a
// COLMAP workspace by `scalefuse synth`, fused by `scalefuse fuse`, scored by `scalefuse eval`.
// Also the paper's central claim: adding many coarse views must not degrade the close-up, while a
// single-level VRIP-style fusion of the same input degrades a lot.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "tests/test_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

json read_json(const fs::path& p) {
  std::ifstream in(p);
  return json::parse(in);
}

class MultiScale : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(test::scratch_dir("e2e-multiscale"));
    const fs::path mesh = test::shared_data() / "meshes" / "igea_triangles.ply";
    ASSERT_TRUE(fs::exists(mesh)) << mesh;
    std::string log;
    const std::string cmd = test::scalefuse_binary().string() + " synth " + mesh.string() + " -o " +
                            (*dir_ / "all").string() +
                            " --format colmap --far 30 --far-size 80x60 --close 4 --close-size 240x180 -q";
    ASSERT_EQ(test::run_command(cmd, &log), 0) << log;
    // The close views alone: the same workspace without the far depth maps.
    fs::copy(*dir_ / "all", *dir_ / "close", fs::copy_options::recursive);
    for (auto& e : fs::directory_iterator(*dir_ / "close" / "stereo" / "depth_maps"))
      if (e.path().filename().string().rfind("far_", 0) == 0) fs::remove(e.path());
    scene_ = new json(read_json(*dir_ / "all" / "synth.json"));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
    delete scene_;
  }

  // Fuses `input` ("all" or "close") with extra flags; returns the mesh path.
  static fs::path fuse(const std::string& input, const std::string& name, const std::string& flags) {
    const fs::path out = *dir_ / (name + ".ply");
    if (fs::exists(out)) return out;
    std::string log;
    // One root cube for every run, so that all runs use the same voxel lattice.
    const std::string cmd = test::scalefuse_binary().string() + " fuse " + (*dir_ / input).string() + " -o " +
                            out.string() + " --config " + SCALEFUSE_SOURCE_DIR +
                            "/configs/mvs.toml --set integrate.gamma=4 --bbox=-0.88,-0.88,-0.88,0.88,0.88,0.88 -q " + flags;
    EXPECT_EQ(test::run_command(cmd, &log), 0) << cmd << "\n" << log;
    return out;
  }
  static json eval(const fs::path& mesh, const std::string& flags) {
    std::string log;
    const fs::path out = mesh.string() + ".eval.json";
    const std::string cmd = test::scalefuse_binary().string() + " eval " + mesh.string() + " " +
                            (*dir_ / "all" / "reference.ply").string() + " --scene " +
                            (*dir_ / "all" / "synth.json").string() + " --json -q " + flags + " > " + out.string();
    EXPECT_EQ(test::run_command(cmd, &log), 0) << cmd << "\n" << log;
    return read_json(out);
  }
  static double fine() { return (*scene_)["fine_footprint"].get<double>(); }
  static double coarse() { return (*scene_)["coarse_footprint"].get<double>(); }

  static fs::path* dir_;
  static json* scene_;
};
fs::path* MultiScale::dir_ = nullptr;
json* MultiScale::scene_ = nullptr;

TEST_F(MultiScale, AccuracyAndCompletenessWithinTheFootprints) {
  const double ratio = coarse() / fine();
  EXPECT_GT(ratio, 8.0);
  EXPECT_LT(ratio, 16.0);
  const fs::path mesh = fuse("all", "scalefuse_all", "");
  const json close_up = eval(mesh, "--close-up --tau " + std::to_string(2 * fine()));
  const json whole = eval(mesh, "--observed --tau " + std::to_string(2 * coarse()));
  const double close_acc = close_up["accuracy"]["mean"], whole_acc = whole["accuracy"]["mean"];
  std::printf("fine footprint %.3f mm, coarse %.3f mm\n", 1e3 * fine(), 1e3 * coarse());
  std::printf("close-up: accuracy mean %.4f mm, recall@2F %.4f\n", 1e3 * close_acc, double(close_up["scores"][0]["recall"]));
  std::printf("whole:    accuracy mean %.4f mm, recall@2F %.4f\n", 1e3 * whole_acc, double(whole["scores"][0]["recall"]));
  EXPECT_LT(close_acc, 0.5 * fine());
  EXPECT_LT(whole_acc, 0.5 * coarse());
  EXPECT_GE(double(close_up["scores"][0]["recall"]), 0.95);
  EXPECT_GE(double(whole["scores"][0]["recall"]), 0.95);
}

TEST_F(MultiScale, CoarseViewsDoNotDegradeTheCloseUpButDegradeSingleLevelFusion) {
  // The single-level baseline: every triangle at the close views' level, no regularization (VRIP).
  const fs::path sf_close = fuse("close", "scalefuse_close", "--stats " + (*dir_ / "close_stats.json").string());
  const json stats = read_json(*dir_ / "close_stats.json");
  int fine_level = 0;
  std::size_t most = 0;
  for (const auto& l : stats["levels"])
    if (l["triangles"].get<std::size_t>() > most) {
      most = l["triangles"];
      fine_level = l["level"];
    }
  const std::string vrip = "--set integrate.single_level=" + std::to_string(fine_level) +
                           " --set regularize.tau0=0 --set regularize.tau1=0";
  const fs::path sf_all = fuse("all", "scalefuse_all", "");
  const fs::path vrip_close = fuse("close", "vrip_close", vrip);
  const fs::path vrip_all = fuse("all", "vrip_all", vrip);
  const std::string flags = "--close-up --tau " + std::to_string(2 * fine());
  const double a_sf_close = eval(sf_close, flags)["accuracy"]["mean"];
  const double a_sf_all = eval(sf_all, flags)["accuracy"]["mean"];
  const double a_vrip_close = eval(vrip_close, flags)["accuracy"]["mean"];
  const double a_vrip_all = eval(vrip_all, flags)["accuracy"]["mean"];
  std::printf("close-up mean accuracy (mm)   close views only   + 30 far views   change\n");
  std::printf("scalefuse                     %14.4f   %14.4f   %+6.1f%%\n", 1e3 * a_sf_close, 1e3 * a_sf_all,
              100 * (a_sf_all / a_sf_close - 1));
  std::printf("single-level VRIP (level %2d)   %14.4f   %14.4f   %+6.1f%%\n", fine_level, 1e3 * a_vrip_close,
              1e3 * a_vrip_all, 100 * (a_vrip_all / a_vrip_close - 1));
  EXPECT_LE(a_sf_all, 1.10 * a_sf_close);
  EXPECT_GT(a_vrip_all, 3.0 * a_vrip_close);
}

}  // namespace
}  // namespace sf
