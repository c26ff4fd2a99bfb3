// PNG/JPEG round trips and failures of engine/input/image_io.
#include <gtest/gtest.h>

#include <fstream>

#include "engine/error.h"
#include "engine/input/file_util.h"
#include "engine/input/image_io.h"
#include "tests/test_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

void write_bytes(const fs::path& p, const std::string& bytes) {
  std::ofstream(p, std::ios::binary) << bytes;
}
// CRC-32 as PNG chunks use it (so that a forged header passes libpng's CRC check).
std::uint32_t crc32(const std::string& bytes) {
  std::uint32_t c = 0xFFFFFFFFu;
  for (unsigned char b : bytes) {
    c ^= b;
    for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
  }
  return c ^ 0xFFFFFFFFu;
}
std::string read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(InputImageIo, Png8RgbRoundTrip) {
  const fs::path dir = test::scratch_dir("image_io_rgb");
  Image8 img{5, 3, 3, {}};
  for (int i = 0; i < 5 * 3 * 3; ++i) img.data.push_back(std::uint8_t(i * 7));
  write_png8(dir / "a.png", img);
  const Image8 back = read_image_rgb(dir / "a.png");
  EXPECT_EQ(back.width, 5);
  EXPECT_EQ(back.height, 3);
  EXPECT_EQ(back.channels, 3);
  EXPECT_EQ(back.data, img.data);
  // No temporary left behind.
  EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator()), 1);
}

TEST(InputImageIo, Png8GreyIsExpandedToRgb) {
  const fs::path dir = test::scratch_dir("image_io_grey");
  Image8 img{2, 2, 1, {0, 50, 100, 255}};
  write_png8(dir / "g.png", img);
  const Image8 back = read_image_rgb(dir / "g.png");
  ASSERT_EQ(back.data.size(), 12u);
  EXPECT_EQ(back.data[3], 50);
  EXPECT_EQ(back.data[4], 50);
  EXPECT_EQ(back.data[11], 255);
}

TEST(InputImageIo, Png16RoundTripKeepsExactValues) {
  const fs::path dir = test::scratch_dir("image_io_16");
  Image16 img{4, 2, {0, 1, 255, 256, 1000, 40000, 65534, 65535}};
  write_png16(dir / "d.png", img);
  const Image16 back = read_png16(dir / "d.png");
  EXPECT_EQ(back.width, 4);
  EXPECT_EQ(back.height, 2);
  EXPECT_EQ(back.data, img.data);
}

TEST(InputImageIo, ReadsRealKinectFrame) {
  const fs::path dir = test::shared_data() / "7scenes_50frames";
  const Image16 depth = read_png16(dir / "frame-000150.depth.png");
  EXPECT_EQ(depth.width, 640);
  EXPECT_EQ(depth.height, 480);
  const Image8 colour = read_image_rgb(dir / "frame-000150.color.jpg");
  EXPECT_EQ(colour.width, 640);
  EXPECT_EQ(colour.height, 480);
  EXPECT_EQ(colour.channels, 3);
}

// A depth map's colour samples the image pixel whose area holds the depth pixel's centre: a 6x4
// image on a 3x2 depth map (scale 2) gives source columns int((c + 0.5) 2) = 1, 3, 5 and rows 1, 3;
// a 6x5 grey one on a 4x3 map (scale 1.5, 5/3) columns int(0.75) = 0, int(2.25) = 2, 3, 5 and
// rows int(0.83) = 0, int(2.5) = 2, 4.
TEST(InputImageIo, ColourSamplesThePixelHoldingEachDepthPixelsCentre) {
  Image8 rgb{6, 4, 3, {}}, grey{6, 5, 1, {}};
  for (int r = 0; r < 5; ++r)
    for (int c = 0; c < 6; ++c) {
      if (r < 4) rgb.data.insert(rgb.data.end(), {std::uint8_t(10 * r + c), std::uint8_t(100 + c), std::uint8_t(200 + r)});
      grey.data.push_back(std::uint8_t(10 * r + c));
    }
  const std::vector<Rgb8> half = input_detail::sample_colour(rgb, 3, 2);
  ASSERT_EQ(half.size(), 6u);
  const int half_cols[3] = {1, 3, 5}, half_rows[2] = {1, 3};
  for (int r = 0; r < 2; ++r)
    for (int c = 0; c < 3; ++c) {
      const Rgb8 v = half[std::size_t(r) * 3 + c];
      EXPECT_EQ(v[0], 10 * half_rows[r] + half_cols[c]);
      EXPECT_EQ(v[1], 100 + half_cols[c]);
      EXPECT_EQ(v[2], 200 + half_rows[r]);
    }
  const std::vector<Rgb8> odd = input_detail::sample_colour(grey, 4, 3);
  ASSERT_EQ(odd.size(), 12u);
  const int odd_cols[4] = {0, 2, 3, 5}, odd_rows[3] = {0, 2, 4};
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) {
      const Rgb8 v = odd[std::size_t(r) * 4 + c];
      EXPECT_EQ(v[0], 10 * odd_rows[r] + odd_cols[c]);
      EXPECT_EQ(v[1], v[0]);
      EXPECT_EQ(v[2], v[0]);
    }
  // The same size: each pixel itself.
  const std::vector<Rgb8> same = input_detail::sample_colour(rgb, 6, 4);
  EXPECT_EQ(same[2 * 6 + 5][0], 25);
  EXPECT_EQ(same[2 * 6 + 5][2], 202);
}

TEST(InputImageIo, BadFilesAreInputErrorsNamingTheFile) {
  const fs::path dir = test::scratch_dir("image_io_bad");
  Image8 img{64, 64, 3, std::vector<std::uint8_t>(64 * 64 * 3, 9)};
  write_png8(dir / "good.png", img);
  const std::string good = read_bytes(dir / "good.png");
  write_bytes(dir / "trunc.png", good.substr(0, good.size() / 2));
  write_bytes(dir / "text.png", "hello");
  // A header claiming 60000x60000 pixels in a tiny file: must fail before allocating.
  std::string huge = good;
  const unsigned char big[8] = {0, 0, 0xEA, 0x60, 0, 0, 0xEA, 0x60};
  huge.replace(16, 8, reinterpret_cast<const char*>(big), 8);
  const std::uint32_t crc = crc32(huge.substr(12, 17));  // "IHDR" + 13 data bytes
  for (int k = 0; k < 4; ++k) huge[29 + k] = char((crc >> (24 - 8 * k)) & 0xFF);
  write_bytes(dir / "huge.png", huge);
  const std::string jpeg = read_bytes(test::shared_data() / "7scenes_50frames" / "frame-000150.color.jpg");
  write_bytes(dir / "trunc.jpg", jpeg.substr(0, 600));
  for (const char* name : {"missing.png", "trunc.png", "text.png", "huge.png", "trunc.jpg"}) {
    try {
      read_image_rgb(dir / name);
      ADD_FAILURE() << name << " was accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
      if (std::string(name) == "huge.png") {
        EXPECT_NE(std::string(e.what()).find("impossible"), std::string::npos) << e.what();
      }
    }
  }
  EXPECT_THROW(read_png16(dir / "good.png"), InputError);  // 8-bit RGB is not a depth PNG
}

}  // namespace
}  // namespace sf
