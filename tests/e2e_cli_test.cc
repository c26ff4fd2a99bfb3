// The command-line program on bad input (one line naming the file, exit code 2, no output) and on
// a small valid scene (mesh written atomically, statistics, OpenVDB export).
#include <gtest/gtest.h>
#include <openvdb/openvdb.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>

#include "tests/test_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

// A minimal COLMAP dense workspace: one PINHOLE camera 8x6, one image, one depth map.
void write_workspace(const fs::path& dir, float depth_value = 2.0f, int map_w = 8, int map_h = 6, double focal = 10.0) {
  fs::create_directories(dir / "sparse");
  fs::create_directories(dir / "stereo" / "depth_maps");
  std::ofstream(dir / "sparse" / "cameras.txt") << "# Camera list\n1 PINHOLE 8 6 " << focal << " " << focal << " 4 3\n";
  std::ofstream(dir / "sparse" / "images.txt") << "# Image list\n1 1 0 0 0 0 0 0 1 a.png\n\n";
  std::ofstream(dir / "sparse" / "points3D.txt") << "";
  std::ofstream bin(dir / "stereo" / "depth_maps" / "a.png.geometric.bin", std::ios::binary);
  bin << map_w << "&" << map_h << "&1&";
  for (int i = 0; i < map_w * map_h; ++i) bin.write(reinterpret_cast<const char*>(&depth_value), 4);
}

struct CliRun {
  int code;
  std::string output;
};
CliRun fuse(const fs::path& input, const fs::path& out, const std::string& flags = "") {
  CliRun r;
  r.code = test::run_command(test::scalefuse_binary().string() + " fuse " + input.string() + " -o " + out.string() +
                                 " -q " + flags,
                             &r.output);
  return r;
}

// Exit code 2, one line on stderr naming `needle`, no mesh.
void expect_bad_input(const CliRun& r, const fs::path& out, const std::string& needle) {
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(needle), std::string::npos) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  EXPECT_FALSE(fs::exists(out));
  for (auto& e : fs::directory_iterator(out.parent_path()))
    EXPECT_EQ(e.path().string().find(".tmp"), std::string::npos) << "left behind " << e.path();
}

TEST(CliBadInput, MissingAndUnrecognisedFolders) {
  const fs::path dir = test::scratch_dir("cli-missing");
  expect_bad_input(fuse(dir / "nope", dir / "m.ply"), dir / "m.ply", "nope");
  fs::create_directories(dir / "empty");
  expect_bad_input(fuse(dir / "empty", dir / "m.ply"), dir / "m.ply", "empty");
}

TEST(CliBadInput, ColmapWorkspaceDefects) {
  const fs::path root = test::scratch_dir("cli-colmap");
  const fs::path out = root / "m.ply";
  {  // truncated depth map
    const fs::path ws = root / "truncated";
    write_workspace(ws);
    fs::resize_file(ws / "stereo" / "depth_maps" / "a.png.geometric.bin", 40);
    expect_bad_input(fuse(ws, out), out, "a.png.geometric.bin");
  }
  {  // NaN depths
    const fs::path ws = root / "nan";
    write_workspace(ws, std::numeric_limits<float>::quiet_NaN());
    expect_bad_input(fuse(ws, out), out, "a.png.geometric.bin");
  }
  {  // negative depths
    const fs::path ws = root / "negative";
    write_workspace(ws, -1.0f);
    expect_bad_input(fuse(ws, out), out, "a.png.geometric.bin");
  }
  {  // zero focal length
    const fs::path ws = root / "focal";
    write_workspace(ws, 2.0f, 8, 6, 0.0);
    expect_bad_input(fuse(ws, out), out, "cameras.txt");
  }
  {  // depth map larger than its image
    const fs::path ws = root / "size";
    write_workspace(ws, 2.0f, 16, 12);
    expect_bad_input(fuse(ws, out), out, "a.png.geometric.bin");
  }
  {  // an empty scene: a model but no depth maps
    const fs::path ws = root / "nomaps";
    write_workspace(ws);
    fs::remove(ws / "stereo" / "depth_maps" / "a.png.geometric.bin");
    expect_bad_input(fuse(ws, out), out, "nomaps");
  }
}

TEST(CliBadInput, TruncatedMveiAndBadParameters) {
  const fs::path root = test::scratch_dir("cli-mve");
  const fs::path view = root / "scene" / "views" / "view_0000.mve";
  fs::create_directories(view);
  std::ofstream(view / "meta.ini") << "[camera]\nfocal_length = 1\npixel_aspect = 1\nprincipal_point = 0.5 0.5\n"
                                      "rotation = 1 0 0 0 1 0 0 0 1\ntranslation = 0 0 0\n\n[view]\nid = 0\nname = a\n";
  {
    std::ofstream m(view / "depth-L0.mvei", std::ios::binary);
    m.write("\x89MVE_IMAGE\n", 11);
    const std::int32_t hdr[4] = {8, 8, 1, 9};
    m.write(reinterpret_cast<const char*>(hdr), sizeof hdr);
    const float d = 1.0f;
    for (int i = 0; i < 10; ++i) m.write(reinterpret_cast<const char*>(&d), 4);  // 10 of 64 pixels
  }
  const fs::path out = root / "m.ply";
  expect_bad_input(fuse(root / "scene", out), out, "depth-L0.mvei");
  // A bad parameter value names the parameter; a bad config names the file.
  expect_bad_input(fuse(root / "scene", out, "--set integrate.gamma=-2"), out, "integrate.gamma");
  std::ofstream(root / "bad.toml") << "[integrate\n";
  expect_bad_input(fuse(root / "scene", out, "--config " + (root / "bad.toml").string()), out, "bad.toml");
}

TEST(CliValidScene, ExtractionByBricksGivesTheGlobalMeshOnTheRealBunny) {
  // The ten real scans: a brick boundary runs through the ears and the body; windows hold cells
  // that are not global (a voxel outside the window inside their sphere), which the certificate
  // rejects.
  const fs::path root = test::scratch_dir("cli-extract-bricks");
  const fs::path scans = test::shared_data() / "stanford_bunny" / "scans";
  const std::string config = " --config " + (fs::path(SCALEFUSE_SOURCE_DIR) / "configs" / "laser.toml").string();
  const fs::path global = root / "global.ply", bricks = root / "bricks.ply", stats = root / "bricks.json";
  ASSERT_EQ(fuse(scans, global, config + " --extract global").code, 0);
  // Groups of 131,072 voxels (a quarter of the default): more windows, so more seams between them.
  const CliRun r = fuse(scans, bricks,
                        config + " --extract bricks --set extract.window_group_voxels=131072 --stats " + stats.string());
  ASSERT_EQ(r.code, 0) << r.output;
  std::ifstream a(global, std::ios::binary), b(bricks, std::ios::binary);
  const std::string ga((std::istreambuf_iterator<char>(a)), {}), gb((std::istreambuf_iterator<char>(b)), {});
  EXPECT_GT(ga.size(), 1000000u);
  EXPECT_TRUE(ga == gb) << "the per-brick mesh differs from the global one";
  const auto j = nlohmann::json::parse(std::ifstream(stats));
  EXPECT_EQ(j["extract"]["mode"], "bricks");
  EXPECT_GT(j["extract"]["windows"].get<int>(), 20);  // window groups of several bricks
  EXPECT_GT(j["extract"]["window_cells_rejected"].get<int>(), 0);
  // Every pass ran in this run and is timed.
  for (const char* pass : {"prepare", "tetrahedralize", "snap", "march", "number", "faces", "sort", "write"}) {
    ASSERT_TRUE(j["extract"]["pass_seconds"].contains(pass)) << pass;
    EXPECT_GE(j["extract"]["pass_seconds"][pass].get<double>(), 0.0) << pass;
  }
  EXPECT_GT(j["extract"]["pass_seconds"]["tetrahedralize"].get<double>(), 0.01);
  EXPECT_FALSE(fs::exists(fs::path(bricks.string() + ".job") / "scratch")) << "scratch files are removed";
  // Bricks 4x smaller (level 5, 6 mm): paging, regularization and extraction all cut differently.
  const fs::path small = root / "small.ply", small_stats = root / "small.json";
  const CliRun s = fuse(scans, small, config + " --extract bricks --brick-size 0.012 --stats " + small_stats.string());
  ASSERT_EQ(s.code, 0) << s.output;
  std::ifstream c(small, std::ios::binary);
  EXPECT_TRUE(ga == std::string((std::istreambuf_iterator<char>(c)), {})) << "the mesh depends on the brick size";
  EXPECT_EQ(nlohmann::json::parse(std::ifstream(small_stats))["brick_level"], 5);
  EXPECT_EQ(fuse(scans, root / "bad.ply", config + " --extract sideways").code, 2);
}

TEST(CliValidScene, WritesMeshStatsAndVdb) {
  const fs::path root = test::scratch_dir("cli-valid");
  std::string log;
  const fs::path mesh = test::shared_data() / "stanford_bunny" / "reconstruction" / "bun_zipper_res3.ply";
  ASSERT_EQ(test::run_command(test::scalefuse_binary().string() + " synth " + mesh.string() + " -o " +
                                  (root / "scene").string() +
                                  " --format mve --far 6 --far-size 64x48 --close 1 --close-size 96x72 -q",
                              &log),
            0)
      << log;
  const fs::path out = root / "bunny.ply", vdb = root / "field.vdb", stats = root / "stats.json";
  const CliRun r = fuse(root / "scene", out,
                     "--export-vdb " + vdb.string() + " --stats " + stats.string() + " --threads 2");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("mesh written to"), std::string::npos);
  ASSERT_TRUE(fs::exists(out));
  std::ifstream ply(out, std::ios::binary);
  std::string header, line;
  while (std::getline(ply, line) && line != "end_header") header += line + "\n";
  EXPECT_NE(header.find("format binary_little_endian 1.0"), std::string::npos);
  for (const char* prop : {"property float x", "property uchar red", "property float confidence", "property float scale"})
    EXPECT_NE(header.find(prop), std::string::npos) << prop;
  const auto j = nlohmann::json::parse(std::ifstream(stats));
  EXPECT_EQ(j["depth_maps"], 7);
  EXPECT_GT(j["mesh"]["triangles"].get<int>(), 100);
  // The VDB file holds a distance and a weight grid per level with voxels.
  openvdb::initialize();
  openvdb::io::File file(vdb.string());
  file.open();
  int distance_grids = 0, weight_grids = 0;
  for (auto it = file.beginName(); it != file.endName(); ++it) {
    distance_grids += it.gridName().rfind("distance_L", 0) == 0;
    weight_grids += it.gridName().rfind("weight_L", 0) == 0;
  }
  file.close();
  EXPECT_GT(distance_grids, 1);
  EXPECT_EQ(distance_grids, weight_grids);
  // Same input, 1 thread: byte-identical mesh.
  const fs::path out1 = root / "bunny1.ply";
  ASSERT_EQ(fuse(root / "scene", out1, "--threads 1").code, 0);
  std::ifstream a(out, std::ios::binary), b(out1, std::ios::binary);
  const std::string sa((std::istreambuf_iterator<char>(a)), {}), sb((std::istreambuf_iterator<char>(b)), {});
  EXPECT_TRUE(sa == sb) << "meshes differ between 1 and 2 threads";
  EXPECT_EQ(j["extract"]["mode"], "global");  // the default memory limit holds the global tetrahedralization
  // A memory limit the global tetrahedralization would exceed: --extract auto (the default) goes
  // brick by brick, and the mesh does not change.
  const fs::path out_small = root / "bunny-small.ply", stats_small = root / "small.json";
  ASSERT_EQ(fuse(root / "scene", out_small, "--memory-limit 4M --stats " + stats_small.string()).code, 0);
  std::ifstream c(out_small, std::ios::binary);
  const std::string sc((std::istreambuf_iterator<char>(c)), {});
  EXPECT_TRUE(sa == sc) << "meshes differ between the global and the per-brick tetrahedralization";
  EXPECT_EQ(nlohmann::json::parse(std::ifstream(stats_small))["extract"]["mode"], "bricks");
  // The OpenVDB plugin missing: one line naming it, exit 1, and neither the grids nor the mesh.
  const fs::path vdb_missing = root / "missing.vdb", out_missing = root / "missing.ply";
  CliRun missing;
  missing.code = test::run_command("SCALEFUSE_VDB_PLUGIN=" + (root / "no-such-plugin.so").string() + " " +
                                       test::scalefuse_binary().string() + " fuse " + (root / "scene").string() +
                                       " -o " + out_missing.string() + " -q --export-vdb " + vdb_missing.string(),
                                   &missing.output);
  EXPECT_EQ(missing.code, 1) << missing.output;
  EXPECT_NE(missing.output.find("no-such-plugin.so"), std::string::npos) << missing.output;
  EXPECT_EQ(std::count(missing.output.begin(), missing.output.end(), '\n'), 1) << missing.output;
  EXPECT_FALSE(fs::exists(vdb_missing));
  EXPECT_FALSE(fs::exists(out_missing));
}

}  // namespace
}  // namespace sf
