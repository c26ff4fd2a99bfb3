// open_input: options, format detection, errors for unrecognised folders, and concurrent loads.
#include <gtest/gtest.h>

#include <fstream>
#include <functional>
#include <thread>

#include "engine/error.h"
#include "engine/input/frame_source.h"
#include "engine/input/image_io.h"
#include "engine/input/readers.h"
#include "tests/test_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

using test::write_text;

void expect_input_error(const std::function<void()>& fn, const std::string& what) {
  try {
    fn();
    ADD_FAILURE() << "no error; expected \"" << what << "\"";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
}

TEST(InputOpen, OptionsCheck) {
  EXPECT_TRUE(InputOptions{}.check());
  InputOptions o;
  o.format = "ply";
  expect_input_error([&] { o.check(); }, "format must be");
  o = {};
  o.colmap_maps = "fused";
  expect_input_error([&] { o.check(); }, "colmap_maps");
  o = {};
  o.rgbd_depth_scale = 0;
  expect_input_error([&] { o.check(); }, "rgbd_depth_scale");
  o = {};
  o.mve_depth = "../depth";
  expect_input_error([&] { o.check(); }, "plain file names");
  // open_input checks them before touching the folder.
  o = {};
  o.format = "nope";
  expect_input_error([&] { open_input(test::shared_data(), o); }, "format must be");
}

TEST(InputOpen, DetectsEachFormat) {
  const fs::path root = test::scratch_dir("open_detect");
  fs::create_directories(root / "colmap/sparse");
  fs::create_directories(root / "colmap2/stereo/depth_maps");
  fs::create_directories(root / "mve/views/view_0000.mve");
  write_text(root / "rgbd/camera-intrinsics.txt", "1 0 0 0 1 0 0 0 1");
  write_text(root / "rgbd/a.depth.png", "");
  write_text(root / "range/x.conf", "camera 0 0 0 0 0 0 1\nbmesh x.ply 0 0 0 0 0 0 1\n");
  write_text(root / "other/x.conf", "nothing here\n");
  write_text(root / "other/a.depth.png", "");  // no intrinsics: not RGB-D
  EXPECT_EQ(detect_input_format(root / "colmap"), "colmap");
  EXPECT_EQ(detect_input_format(root / "colmap2"), "colmap");
  EXPECT_EQ(detect_input_format(root / "mve"), "mve");
  EXPECT_EQ(detect_input_format(root / "rgbd"), "rgbd");
  EXPECT_EQ(detect_input_format(root / "range"), "rangegrid");
  EXPECT_EQ(detect_input_format(root / "other"), "");
  EXPECT_EQ(detect_input_format(test::shared_data() / "7scenes_50frames"), "rgbd");
  EXPECT_EQ(detect_input_format(test::shared_data() / "stanford_bunny/scans"), "rangegrid");
  expect_input_error([&] { open_input(root / "other", {}); },
                     "other: not a COLMAP workspace, MVE scene, RGB-D folder or range-grid folder");
  expect_input_error([&] { open_input(root / "missing", {}); }, "missing: input folder does not exist");
  expect_input_error([&] { open_input(root / "rgbd/a.depth.png", {}); }, "not a folder");
  // Format given explicitly: the reader's own error.
  InputOptions o;
  o.format = "rgbd";
  expect_input_error([&] { open_input(root / "colmap", o); }, "camera-intrinsics.txt: missing file");
  o.format = "mve";
  expect_input_error([&] { open_input(root / "mve", o); }, "no view holds the depth embedding");
}

// load() is const and keeps no shared state: concurrent loads give the same frames.
TEST(InputOpen, ConcurrentLoadsAgree) {
  const auto src = open_input(test::shared_data() / "7scenes_50frames", {});
  const std::size_t n = 8;
  std::vector<DepthFrame> serial(n), parallel(n);
  for (std::size_t i = 0; i < n; ++i) serial[i] = src->load(i);
  std::vector<std::thread> threads;
  for (std::size_t t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      for (std::size_t i = t; i < n; i += 4) parallel[i] = src->load(i);
    });
  for (auto& th : threads) th.join();
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_EQ(serial[i].position, parallel[i].position);
    EXPECT_EQ(serial[i].colour, parallel[i].colour);
  }
}

}  // namespace
}  // namespace sf
