#include "engine/input/mve_io.h"

#include <cmath>
#include <cstring>

#include "engine/error.h"
#include "engine/input/file_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;
using namespace input_detail;

constexpr char kMveiSignature[] = "\x89MVE_IMAGE\n";
constexpr std::size_t kMveiSignatureLen = 11;
constexpr std::size_t kMveiHeaderLen = kMveiSignatureLen + 16;
constexpr std::int64_t kMveiMaxPixels = std::int64_t(1) << 28;  // MVE's own loader limit

int mve_type_size(int type) {
  switch (type) {
    case 1: case 5: return 1;
    case 2: case 6: return 2;
    case 3: case 7: case 9: return 4;
    case 4: case 8: case 10: return 8;
    default: return 0;
  }
}

std::vector<double> parse_numbers(const fs::path& path, const std::string& key, const std::string& value,
                                  std::size_t count) {
  const auto tok = split_ws(value);
  std::vector<double> out(tok.size());
  bool ok = tok.size() == count;
  for (std::size_t i = 0; ok && i < tok.size(); ++i) ok = parse_number(tok[i], &out[i]) && std::isfinite(out[i]);
  if (!ok)
    throw input_error(path.string(), key + " must be " + std::to_string(count) + " finite number" +
                                         (count > 1 ? "s" : "") + ", got \"" + value + "\"");
  return out;
}

}  // namespace

MveImage read_mvei(const fs::path& path) {
  auto bytes = read_file_bytes(path);
  if (bytes.size() < kMveiSignatureLen || std::memcmp(bytes.data(), kMveiSignature, kMveiSignatureLen) != 0)
    throw input_error(path.string(), "not an MVE image (wrong magic)");
  if (bytes.size() < kMveiHeaderLen) throw input_error(path.string(), "MVE image header is truncated");
  MveImage im;
  const std::uint8_t* h = bytes.data() + kMveiSignatureLen;
  im.width = load_le<std::int32_t>(h);
  im.height = load_le<std::int32_t>(h + 4);
  im.channels = load_le<std::int32_t>(h + 8);
  im.type = load_le<std::int32_t>(h + 12);
  const int type_size = mve_type_size(im.type);
  if (type_size == 0) throw input_error(path.string(), "unknown MVE image type " + std::to_string(im.type));
  if (im.width <= 0 || im.height <= 0 || im.channels <= 0 || im.channels > 64 ||
      std::int64_t(im.width) * im.height > kMveiMaxPixels)
    throw input_error(path.string(), "bad MVE image size " + std::to_string(im.width) + "x" +
                                         std::to_string(im.height) + "x" + std::to_string(im.channels));
  const std::uint64_t need = std::uint64_t(im.width) * im.height * im.channels * type_size;
  const std::uint64_t have = bytes.size() - kMveiHeaderLen;
  if (have != need)
    throw input_error(path.string(), "header says " + std::to_string(im.width) + "x" + std::to_string(im.height) +
                                         "x" + std::to_string(im.channels) + " pixels (" + std::to_string(need) +
                                         " bytes) but the file holds " + std::to_string(have) + " bytes" +
                                         (have < need ? " (truncated)" : ""));
  bytes.erase(bytes.begin(), bytes.begin() + kMveiHeaderLen);
  im.bytes = std::move(bytes);
  return im;
}

std::vector<float> mvei_channel0_as_float(const MveImage& im, const fs::path& path) {
  const std::size_t n = std::size_t(im.width) * im.height;
  std::vector<float> out(n);
  const std::size_t stride = std::size_t(im.channels) * mve_type_size(im.type);
  const std::uint8_t* p = im.bytes.data();
  switch (im.type) {
    case 9:
      for (std::size_t i = 0; i < n; ++i) out[i] = load_le<float>(p + i * stride);
      break;
    case 10:
      for (std::size_t i = 0; i < n; ++i) out[i] = float(load_le<double>(p + i * stride));
      break;
    case 1:
      for (std::size_t i = 0; i < n; ++i) out[i] = p[i * stride] / 255.f;
      break;
    default:
      throw input_error(path.string(), "expected an MVE image of type float, double or uint8, found type " +
                                           std::to_string(im.type));
  }
  return out;
}

std::map<std::string, std::string> read_mve_ini(const fs::path& path) {
  const std::string text = read_file_text(path);
  std::map<std::string, std::string> out;
  std::string section;
  std::size_t start = 0, line_no = 0;
  while (start < text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    const std::string_view line = trim(std::string_view(text).substr(start, end - start));
    start = end + 1;
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    if (line.front() == '[' && line.back() == ']') {
      section = std::string(line.substr(1, line.size() - 2));
      continue;
    }
    const std::size_t eq = line.find('=');
    const std::string where = "line " + std::to_string(line_no) + ": ";
    if (eq == std::string_view::npos) throw input_error(path.string(), where + "expected key = value");
    const std::string key(trim(line.substr(0, eq)));
    if (key.empty()) throw input_error(path.string(), where + "empty key");
    if (section.empty()) throw input_error(path.string(), where + "key outside a [section]");
    out[section + "." + key] = std::string(trim(line.substr(eq + 1)));
  }
  return out;
}

MveCamera mve_camera(const std::map<std::string, std::string>& ini, const fs::path& path) {
  auto get = [&](const std::string& key) -> const std::string* {
    const auto it = ini.find(key);
    return it == ini.end() || it->second.empty() ? nullptr : &it->second;
  };
  MveCamera cam;
  const std::string* flen = get("camera.focal_length");
  if (!flen) throw input_error(path.string(), "no camera.focal_length: the view has no camera");
  cam.flen = parse_numbers(path, "camera.focal_length", *flen, 1)[0];
  if (!(cam.flen > 0)) throw input_error(path.string(), "camera.focal_length must be positive, got " + *flen);
  if (const std::string* v = get("camera.pixel_aspect")) {
    cam.paspect = parse_numbers(path, "camera.pixel_aspect", *v, 1)[0];
    if (!(cam.paspect > 0)) throw input_error(path.string(), "camera.pixel_aspect must be positive, got " + *v);
  }
  if (const std::string* v = get("camera.principal_point")) {
    const auto pp = parse_numbers(path, "camera.principal_point", *v, 2);
    cam.ppoint[0] = pp[0];
    cam.ppoint[1] = pp[1];
  }
  // camera.radial_distortion describes the original photo; the undistorted embedding and the
  // depth maps made from it are distortion-free (apps/makescene), so it is ignored.
  const std::string* rot = get("camera.rotation");
  const std::string* trans = get("camera.translation");
  if (!rot || !trans) throw input_error(path.string(), "camera.rotation and camera.translation are required");
  const auto r = parse_numbers(path, "camera.rotation", *rot, 9);
  for (int i = 0; i < 9; ++i) cam.rotation(i / 3, i % 3) = r[i];  // row-major, as MVE stores it
  const auto t = parse_numbers(path, "camera.translation", *trans, 3);
  cam.translation = Eigen::Vector3d(t[0], t[1], t[2]);
  // MVE writes 10 significant digits, so a true rotation is orthonormal to ~1e-9.
  const double err = (cam.rotation * cam.rotation.transpose() - Eigen::Matrix3d::Identity()).norm();
  if (err > 1e-4 || cam.rotation.determinant() < 0)
    throw input_error(path.string(), "camera.rotation is not a rotation matrix");
  return cam;
}

Sensor mve_sensor(const MveCamera& cam, int width, int height) {
  // CameraInfo::fill_calibration: the focal length is normalised by the width for landscape
  // images (width * paspect >= height) and by the height for portrait ones.
  Sensor s;
  s.kind = Sensor::Kind::Perspective;
  const double w = width, h = height;
  if (w / h * cam.paspect < 1.0) {
    s.fx = cam.flen * h / cam.paspect;
    s.fy = cam.flen * h;
  } else {
    s.fx = cam.flen * w;
    s.fy = cam.flen * w * cam.paspect;
  }
  // MVE's pixel (x,y) has its centre at (x+0.5, y+0.5) (depthmap.cc pixel_3dpos), as ours does,
  // so the principal point carries over unchanged.
  s.cx = w * cam.ppoint[0];
  s.cy = h * cam.ppoint[1];
  s.R = cam.rotation;
  s.t = cam.translation;
  return s;
}

}  // namespace sf
