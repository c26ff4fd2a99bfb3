#include "engine/input/colmap_io.h"

#include <cmath>
#include <set>
#include <sstream>
#include <string_view>
#include <unordered_set>

#include "engine/error.h"
#include "engine/input/file_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;
using namespace input_detail;

// COLMAP's camera model ids and names (src/colmap/sensor/models.h). Only the first two are
// pinhole; the others carry distortion, which the dense maps of an undistorted workspace do not.
constexpr std::string_view kModelNames[] = {
    "SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV", "OPENCV_FISHEYE", "FULL_OPENCV", "FOV",
    "SIMPLE_RADIAL_FISHEYE", "RADIAL_FISHEYE", "THIN_PRISM_FISHEYE", "RAD_TAN_THIN_PRISM_FISHEYE"};

std::string model_name(int id) {
  if (id >= 0 && id < int(std::size(kModelNames))) return std::string(kModelNames[id]);
  return "with id " + std::to_string(id);
}

// Width/height sanity bound: far beyond any camera, small enough that W*H cannot overflow.
constexpr std::uint64_t kMaxImageSide = 1u << 20;

void finish_camera(const fs::path& path, ColmapCamera& cam, const std::vector<double>& params) {
  const std::string where = "camera " + std::to_string(cam.id) + ": ";
  if (cam.model_id != 0 && cam.model_id != 1)
    throw input_error(path.string(), where + "camera model " + model_name(cam.model_id) +
                                         " is not supported; the workspace must be undistorted "
                                         "(colmap image_undistorter gives PINHOLE cameras)");
  const std::size_t expected = cam.model_id == 0 ? 3 : 4;
  if (params.size() != expected)
    throw input_error(path.string(), where + model_name(cam.model_id) + " needs " + std::to_string(expected) +
                                         " parameters, found " + std::to_string(params.size()));
  if (cam.model_id == 0) {
    cam.fx = cam.fy = params[0];
    cam.cx = params[1];
    cam.cy = params[2];
  } else {
    cam.fx = params[0];
    cam.fy = params[1];
    cam.cx = params[2];
    cam.cy = params[3];
  }
  if (!(cam.fx > 0) || !(cam.fy > 0) || !std::isfinite(cam.fx) || !std::isfinite(cam.fy))
    throw input_error(path.string(), where + "focal length must be positive, got fx=" + std::to_string(cam.fx) +
                                         " fy=" + std::to_string(cam.fy));
  if (!std::isfinite(cam.cx) || !std::isfinite(cam.cy))
    throw input_error(path.string(), where + "principal point is not finite");
  if (cam.width == 0 || cam.height == 0 || cam.width > kMaxImageSide || cam.height > kMaxImageSide)
    throw input_error(path.string(), where + "bad image size " + std::to_string(cam.width) + "x" +
                                         std::to_string(cam.height));
}

void check_unique_cameras(const fs::path& path, const std::vector<ColmapCamera>& cams) {
  std::unordered_set<std::uint32_t> ids;
  for (const auto& c : cams)
    if (!ids.insert(c.id).second) throw input_error(path.string(), "duplicate camera id " + std::to_string(c.id));
}

void finish_images(const fs::path& path, const std::vector<ColmapImage>& images) {
  std::unordered_set<std::uint32_t> ids;
  std::set<std::string> names;
  for (const auto& im : images) {
    if (!ids.insert(im.id).second) throw input_error(path.string(), "duplicate image id " + std::to_string(im.id));
    if (!names.insert(im.name).second) throw input_error(path.string(), "duplicate image name \"" + im.name + "\"");
    if (im.name.empty()) throw input_error(path.string(), "image " + std::to_string(im.id) + " has an empty name");
    const double qn = im.qvec.norm();
    const std::string which = "image " + std::to_string(im.id) + " (" + im.name + ")";
    if (!std::isfinite(qn) || qn < 1e-6)
      throw input_error(path.string(), which + ": its rotation quaternion has length " + std::to_string(qn) +
                                           " (a rotation needs a finite, non-zero quaternion)");
    if (!im.tvec.allFinite())
      throw input_error(path.string(), which + ": its translation is not finite (" + std::to_string(im.tvec.x()) +
                                           " " + std::to_string(im.tvec.y()) + " " + std::to_string(im.tvec.z()) + ")");
  }
}

// Reads fixed-size little-endian fields from a byte buffer, failing with "truncated" instead of
// reading past the end.
class ByteReader {
 public:
  ByteReader(const fs::path& path, const std::vector<std::uint8_t>& bytes) : path_(path), bytes_(bytes) {}
  template <typename T>
  T get() {
    need(sizeof(T));
    const T v = load_le<T>(bytes_.data() + pos_);
    pos_ += sizeof(T);
    return v;
  }
  std::string get_cstring() {
    std::string s;
    while (true) {
      need(1);
      const char c = char(bytes_[pos_++]);
      if (c == '\0') return s;
      s += c;
    }
  }
  void skip(std::uint64_t n) {
    need(n);
    pos_ += std::size_t(n);
  }
  std::uint64_t remaining() const { return bytes_.size() - pos_; }
  bool at_end() const { return pos_ == bytes_.size(); }

 private:
  void need(std::uint64_t n) const {
    if (n > remaining()) throw input_error(path_.string(), "file is truncated (at byte " + std::to_string(pos_) + ")");
  }
  const fs::path& path_;
  const std::vector<std::uint8_t>& bytes_;
  std::size_t pos_ = 0;
};

// Lines of a COLMAP text file, with the 1-based line number for messages.
struct TextLines {
  std::vector<std::string_view> lines;
  explicit TextLines(const std::string& text) {
    std::size_t start = 0;
    while (start < text.size()) {
      std::size_t end = text.find('\n', start);
      if (end == std::string::npos) end = text.size();
      lines.push_back(std::string_view(text).substr(start, end - start));
      start = end + 1;
    }
  }
};

std::string line_ref(std::size_t i) { return "line " + std::to_string(i + 1) + ": "; }

template <typename T>
T token_number(const fs::path& path, std::size_t line, std::string_view token, const char* what) {
  T v{};
  if (!parse_number(token, &v))
    throw input_error(path.string(), line_ref(line) + "bad " + what + " \"" + std::string(token) + "\"");
  return v;
}

std::vector<ColmapCamera> read_cameras_text(const fs::path& path) {
  const std::string text = read_file_text(path);
  const TextLines t(text);
  std::vector<ColmapCamera> cams;
  for (std::size_t i = 0; i < t.lines.size(); ++i) {
    const std::string_view line = trim(t.lines[i]);
    if (line.empty() || line[0] == '#') continue;
    const auto tok = split_ws(line);
    if (tok.size() < 4) throw input_error(path.string(), line_ref(i) + "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]");
    ColmapCamera cam;
    cam.id = token_number<std::uint32_t>(path, i, tok[0], "camera id");
    cam.model_id = -1;
    for (int m = 0; m < int(std::size(kModelNames)); ++m)
      if (tok[1] == kModelNames[m]) cam.model_id = m;
    if (cam.model_id < 0)
      throw input_error(path.string(), line_ref(i) + "unknown camera model \"" + std::string(tok[1]) +
                                           "\"; the workspace must be undistorted (PINHOLE cameras)");
    cam.width = token_number<std::uint64_t>(path, i, tok[2], "width");
    cam.height = token_number<std::uint64_t>(path, i, tok[3], "height");
    std::vector<double> params;
    for (std::size_t k = 4; k < tok.size(); ++k) params.push_back(token_number<double>(path, i, tok[k], "parameter"));
    finish_camera(path, cam, params);
    cams.push_back(cam);
  }
  return cams;
}

std::vector<ColmapCamera> read_cameras_binary(const fs::path& path) {
  const auto bytes = read_file_bytes(path);
  ByteReader in(path, bytes);
  const std::uint64_t n = in.get<std::uint64_t>();
  // Each record is at least id + model + width + height (24 bytes): bounds the count before we
  // reserve anything.
  if (n > in.remaining() / 24)
    throw input_error(path.string(), "header claims " + std::to_string(n) + " cameras, more than the file can hold");
  std::vector<ColmapCamera> cams;
  cams.reserve(std::size_t(n));
  for (std::uint64_t i = 0; i < n; ++i) {
    ColmapCamera cam;
    cam.id = in.get<std::uint32_t>();
    cam.model_id = in.get<std::int32_t>();
    cam.width = in.get<std::uint64_t>();
    cam.height = in.get<std::uint64_t>();
    // The number of parameters follows from the model; for other models we cannot even skip the
    // record, so report the model now.
    if (cam.model_id != 0 && cam.model_id != 1) finish_camera(path, cam, {});
    std::vector<double> params(cam.model_id == 0 ? 3 : 4);
    for (double& p : params) p = in.get<double>();
    finish_camera(path, cam, params);
    cams.push_back(cam);
  }
  if (!in.at_end()) throw input_error(path.string(), "unexpected data after the last camera");
  return cams;
}

std::vector<ColmapImage> read_images_text(const fs::path& path) {
  const std::string text = read_file_text(path);
  const TextLines t(text);
  std::vector<ColmapImage> images;
  for (std::size_t i = 0; i < t.lines.size(); ++i) {
    const std::string_view line = trim(t.lines[i]);
    if (line.empty() || line[0] == '#') continue;
    const auto tok = split_ws(line);
    if (tok.size() < 10)
      throw input_error(path.string(), line_ref(i) + "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME");
    ColmapImage im;
    im.id = token_number<std::uint32_t>(path, i, tok[0], "image id");
    for (int k = 0; k < 4; ++k) im.qvec[k] = token_number<double>(path, i, tok[1 + k], "quaternion");
    for (int k = 0; k < 3; ++k) im.tvec[k] = token_number<double>(path, i, tok[5 + k], "translation");
    im.camera_id = token_number<std::uint32_t>(path, i, tok[8], "camera id");
    // COLMAP reads the name as one token (operator>>), so names cannot hold spaces.
    im.name = std::string(tok[9]);
    images.push_back(std::move(im));
    // The next line lists the 2D points; COLMAP reads it unconditionally, even when it is empty or
    // starts with '#', so we skip it the same way.
    ++i;
  }
  return images;
}

std::vector<ColmapImage> read_images_binary(const fs::path& path) {
  const auto bytes = read_file_bytes(path);
  ByteReader in(path, bytes);
  const std::uint64_t n = in.get<std::uint64_t>();
  // Smallest record: id 4 + pose 56 + camera id 4 + name terminator 1 + point count 8.
  if (n > in.remaining() / 73)
    throw input_error(path.string(), "header claims " + std::to_string(n) + " images, more than the file can hold");
  std::vector<ColmapImage> images;
  images.reserve(std::size_t(n));
  for (std::uint64_t i = 0; i < n; ++i) {
    ColmapImage im;
    im.id = in.get<std::uint32_t>();
    for (int k = 0; k < 4; ++k) im.qvec[k] = in.get<double>();
    for (int k = 0; k < 3; ++k) im.tvec[k] = in.get<double>();
    im.camera_id = in.get<std::uint32_t>();
    im.name = in.get_cstring();
    const std::uint64_t points = in.get<std::uint64_t>();
    if (points > in.remaining() / 24)  // x, y double + point3D id uint64
      throw input_error(path.string(), "image " + std::to_string(im.id) + " claims " + std::to_string(points) +
                                           " 2D points, more than the file can hold (truncated?)");
    in.skip(points * 24);
    images.push_back(std::move(im));
  }
  if (!in.at_end()) throw input_error(path.string(), "unexpected data after the last image");
  return images;
}

}  // namespace

std::vector<ColmapCamera> read_colmap_cameras(const fs::path& path) {
  auto cams = path.extension() == ".bin" ? read_cameras_binary(path) : read_cameras_text(path);
  check_unique_cameras(path, cams);
  return cams;
}

std::vector<ColmapImage> read_colmap_images(const fs::path& path) {
  auto images = path.extension() == ".bin" ? read_images_binary(path) : read_images_text(path);
  finish_images(path, images);
  return images;
}

ColmapArray read_colmap_array(const fs::path& path) {
  const auto bytes = read_file_bytes(path);
  // Header: three decimal integers each followed by '&' (COLMAP writes them with operator<<).
  std::size_t pos = 0;
  long long dims[3] = {0, 0, 0};
  for (long long& d : dims) {
    const std::size_t start = pos;
    while (pos < bytes.size() && pos - start < 12 && bytes[pos] >= '0' && bytes[pos] <= '9') ++pos;
    if (pos == start || pos >= bytes.size() || bytes[pos] != '&')
      throw input_error(path.string(), "not a COLMAP depth/normal map (expected a \"width&height&channels&\" header)");
    d = std::stoll(std::string(bytes.begin() + start, bytes.begin() + pos));
    ++pos;
  }
  if (dims[0] <= 0 || dims[1] <= 0 || dims[2] <= 0 || dims[0] > (1 << 20) || dims[1] > (1 << 20) || dims[2] > 16)
    throw input_error(path.string(), "bad map size " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                                         std::to_string(dims[2]));
  const std::uint64_t count = std::uint64_t(dims[0]) * dims[1] * dims[2];
  const std::uint64_t have = bytes.size() - pos;
  if (have != count * 4)
    throw input_error(path.string(), "header says " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                                         std::to_string(dims[2]) + " floats (" + std::to_string(count * 4) +
                                         " bytes) but the file holds " + std::to_string(have) + " bytes" +
                                         (have < count * 4 ? " (truncated)" : ""));
  ColmapArray a;
  a.width = int(dims[0]);
  a.height = int(dims[1]);
  a.channels = int(dims[2]);
  a.data.resize(std::size_t(count));
  std::memcpy(a.data.data(), bytes.data() + pos, std::size_t(count) * 4);  // little-endian host (file_util.h)
  return a;
}

}  // namespace sf
