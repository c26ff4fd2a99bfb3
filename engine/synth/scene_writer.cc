#include "engine/synth/scene_writer.h"

#include <Eigen/Geometry>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <system_error>

#include "engine/error.h"
#include "engine/input/image_io.h"
#include "engine/meshio/atomic_file.h"
#include "engine/meshio/ply_io.h"

namespace sf {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

static_assert(std::endian::native == std::endian::little, "binary outputs are written in host order");

template <typename T>
void append(std::string& out, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out.append(b, sizeof(T));
}

std::string fmt(const char* format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}
std::string g17(double v) { return fmt("%.17g", v); }

void make_dirs(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw input_error(dir.string(), "cannot create folder: " + ec.message());
}

Image8 rgb_image(const SynthView& v) {
  Image8 img;
  img.width = v.width;
  img.height = v.height;
  img.channels = 3;
  img.data.resize(v.size() * 3);
  for (std::size_t i = 0; i < v.size(); ++i)
    for (int k = 0; k < 3; ++k) img.data[3 * i + k] = v.colour[i][k];
  return img;
}

// COLMAP's dense matrix file (src/colmap/mvs/mat.cc, Mat<float>::Write): "W&H&D&" then float32
// little-endian, slice-major (index = slice * W * H + row * W + col).
std::string colmap_mat(int w, int h, int depth, const std::vector<float>& data) {
  std::string out = std::to_string(w) + "&" + std::to_string(h) + "&" + std::to_string(depth) + "&";
  out.reserve(out.size() + data.size() * 4);
  for (float f : data) append(out, f);
  return out;
}

// Quaternion (w, x, y, z) of a rotation, w >= 0.
Eigen::Vector4d quaternion(const Eigen::Matrix3d& R) {
  Eigen::Quaterniond q(R);
  q.normalize();
  Eigen::Vector4d v(q.w(), q.x(), q.y(), q.z());
  return v[0] < 0 ? Eigen::Vector4d(-v) : v;
}

std::string view_file(const SynthView& v) { return v.name + ".png"; }

struct Files {  // per view: depth and image paths relative to the scene folder
  std::vector<std::string> depth, image;
};

void write_colmap(const SyntheticScene& scene, const fs::path& dir, const SceneWriteOptions& o, WrittenScene& out,
                  Files& files) {
  const fs::path images = dir / "images", sparse = dir / "sparse", depth_dir = dir / "stereo" / "depth_maps",
                 normal_dir = dir / "stereo" / "normal_maps";
  for (const auto& d : {images, sparse, depth_dir, normal_dir}) make_dirs(d);
  auto emit = [&](const fs::path& p, std::string_view bytes) {
    write_file_atomic(p, bytes);
    out.files.push_back(p);
  };

  std::string fusion_cfg;
  for (const SynthView& v : scene.views) {
    const std::string name = view_file(v);
    write_png8(images / name, rgb_image(v));
    out.files.push_back(images / name);
    fusion_cfg += name + "\n";
    const std::string depth = colmap_mat(v.width, v.height, 1, v.depth);
    // Normal maps in the camera frame, pointing towards the camera (COLMAP's patch-match output).
    std::vector<float> normal(v.size() * 3, 0.f);
    for (std::size_t i = 0; i < v.size(); ++i) {
      if (!(v.depth[i] > 0)) continue;
      Eigen::Vector3d n = v.sensor.R * v.normal[i].cast<double>();
      if (n.z() > 0) n = -n;
      for (int k = 0; k < 3; ++k) normal[std::size_t(k) * v.size() + i] = float(n[k]);
    }
    const std::string normals = colmap_mat(v.width, v.height, 3, normal);
    for (const char* type : {"geometric", "photometric"}) {
      emit(depth_dir / (name + "." + type + ".bin"), depth);
      emit(normal_dir / (name + "." + type + ".bin"), normals);
    }
    files.depth.push_back("stereo/depth_maps/" + name + ".geometric.bin");
    files.image.push_back("images/" + name);
  }
  emit(dir / "stereo" / "fusion.cfg", fusion_cfg);

  // Sparse model (src/colmap/scene/reconstruction_io_{text,binary}.cc). IDs start at 1.
  const std::size_t n = scene.views.size();
  if (o.colmap_binary) {
    std::string cams, imgs, pts;
    append<std::uint64_t>(cams, n);
    append<std::uint64_t>(imgs, n);
    for (std::size_t i = 0; i < n; ++i) {
      const SynthView& v = scene.views[i];
      const Sensor& s = v.sensor;
      append<std::uint32_t>(cams, std::uint32_t(i + 1));  // camera_t
      append<std::int32_t>(cams, 1);                      // CameraModelId::kPinhole
      append<std::uint64_t>(cams, std::uint64_t(v.width));
      append<std::uint64_t>(cams, std::uint64_t(v.height));
      for (double p : {s.fx, s.fy, s.cx, s.cy}) append<double>(cams, p);
      const Eigen::Vector4d q = quaternion(s.R);
      append<std::uint32_t>(imgs, std::uint32_t(i + 1));  // image_t
      for (int k = 0; k < 4; ++k) append<double>(imgs, q[k]);
      for (int k = 0; k < 3; ++k) append<double>(imgs, s.t[k]);
      append<std::uint32_t>(imgs, std::uint32_t(i + 1));  // camera_t
      imgs += view_file(v);
      imgs.push_back('\0');
      append<std::uint64_t>(imgs, 0);  // no 2D points
    }
    append<std::uint64_t>(pts, 0);
    emit(sparse / "cameras.bin", cams);
    emit(sparse / "images.bin", imgs);
    emit(sparse / "points3D.bin", pts);
  } else {
    std::string cams = "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
                       "# Number of cameras: " + std::to_string(n) + "\n";
    std::string imgs = "# Image list with two lines of data per image:\n"
                       "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
                       "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
                       "# Number of images: " + std::to_string(n) + ", mean observations per image: 0\n";
    for (std::size_t i = 0; i < n; ++i) {
      const SynthView& v = scene.views[i];
      const Sensor& s = v.sensor;
      const std::string id = std::to_string(i + 1);
      cams += id + " PINHOLE " + std::to_string(v.width) + " " + std::to_string(v.height) + " " + g17(s.fx) + " " +
              g17(s.fy) + " " + g17(s.cx) + " " + g17(s.cy) + "\n";
      const Eigen::Vector4d q = quaternion(s.R);
      imgs += id;
      for (int k = 0; k < 4; ++k) (imgs += ' ') += g17(q[k]);
      for (int k = 0; k < 3; ++k) (imgs += ' ') += g17(s.t[k]);
      imgs += " " + id + " " + view_file(v) + "\n\n";  // then the (empty) 2D points line
    }
    emit(sparse / "cameras.txt", cams);
    emit(sparse / "images.txt", imgs);
    emit(sparse / "points3D.txt",
         "# 3D point list with one line of data per point:\n"
         "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
         "# Number of points: 0, mean track length: 0\n");
  }
}

// MVE (libs/mve/camera.cc CameraInfo::fill_calibration, the inverse of what we write here):
//   landscape (w/h * paspect >= 1): fx = flen * w, fy = flen * w * paspect
//   portrait:                       fy = flen * h, fx = flen * h / paspect
//   cx = ppoint.x * w, cy = ppoint.y * h, with pixel (x,y) centred at (x + 0.5, y + 0.5)
//   (libs/mve/depthmap.cc pixel_3dpos), the same centre convention as ours.
// meta.ini keys as View::set_camera writes them, sorted by util::write_ini.
std::string mve_meta(const SynthView& v, std::size_t id) {
  const Sensor& s = v.sensor;
  const double paspect = s.fy / s.fx;
  const double image_aspect = double(v.width) / v.height * paspect;
  const double flen = image_aspect < 1.0 ? s.fy / v.height : s.fx / v.width;
  std::string out = "# MVE view meta data is stored in INI-file syntax.\n# This file is generated, formatting will get lost.\n";
  out += "\n[camera]\n";
  out += "focal_length = " + g17(flen) + "\n";
  out += "pixel_aspect = " + g17(paspect) + "\n";
  out += "principal_point = " + g17(s.cx / v.width) + " " + g17(s.cy / v.height) + "\n";
  out += "radial_distortion = 0 0\n";
  out += "rotation =";
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) (out += ' ') += g17(s.R(r, c));
  out += "\ntranslation = " + g17(s.t[0]) + " " + g17(s.t[1]) + " " + g17(s.t[2]) + "\n";
  out += "\n[view]\n";
  out += "id = " + std::to_string(id) + "\n";
  out += "name = " + v.name + "\n";
  return out;
}

// MVE image file (libs/mve/image_io.cc save_mvei_file): signature "\x89MVE_IMAGE\n", int32 width,
// height, channels, type (IMAGE_TYPE_FLOAT = 9, libs/mve/image_base.h), then the raw pixels.
std::string mvei_float(int w, int h, const std::vector<float>& data) {
  std::string out("\x89MVE_IMAGE\n", 11);
  for (std::int32_t v : {std::int32_t(w), std::int32_t(h), std::int32_t(1), std::int32_t(9)}) append(out, v);
  for (float f : data) append(out, f);
  return out;
}

void write_mve(const SyntheticScene& scene, const fs::path& dir, WrittenScene& out, Files& files) {
  for (std::size_t i = 0; i < scene.views.size(); ++i) {
    const SynthView& v = scene.views[i];
    char name[32];
    std::snprintf(name, sizeof name, "view_%04zu.mve", i);
    const fs::path vd = dir / "views" / name;
    make_dirs(vd);
    // Distance from the centre of projection along each pixel's ray.
    std::vector<float> dist(v.size(), 0.f);
    for (int row = 0; row < v.height; ++row)
      for (int col = 0; col < v.width; ++col) {
        const std::size_t k = std::size_t(row) * v.width + col;
        if (!(v.depth[k] > 0)) continue;
        const double x = (col + 0.5 - v.sensor.cx) / v.sensor.fx, y = (row + 0.5 - v.sensor.cy) / v.sensor.fy;
        dist[k] = float(v.depth[k] * std::sqrt(x * x + y * y + 1.0));
      }
    write_file_atomic(vd / "meta.ini", mve_meta(v, i));
    write_file_atomic(vd / "depth-L0.mvei", mvei_float(v.width, v.height, dist));
    write_png8(vd / "undistorted.png", rgb_image(v));
    for (const char* f : {"meta.ini", "depth-L0.mvei", "undistorted.png"}) out.files.push_back(vd / f);
    files.depth.push_back("views/" + std::string(name) + "/depth-L0.mvei");
    files.image.push_back("views/" + std::string(name) + "/undistorted.png");
  }
}

std::string matrix_text(const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic>& m) {
  std::string out;
  for (int r = 0; r < m.rows(); ++r) {
    for (int c = 0; c < m.cols(); ++c) {
      if (c) out += ' ';
      out += fmt("%.18e", m(r, c));
    }
    out += "\n";
  }
  return out;
}

void write_rgbd(const SyntheticScene& scene, const fs::path& dir, const SceneWriteOptions& o, WrittenScene& out,
                Files& files) {
  make_dirs(dir);
  const SynthView& first = scene.views.front();
  for (const SynthView& v : scene.views) {
    const Sensor &a = v.sensor, &b = first.sensor;
    if (v.width != first.width || v.height != first.height || a.fx != b.fx || a.fy != b.fy || a.cx != b.cx || a.cy != b.cy)
      throw std::invalid_argument("rgbd output needs one image size and K for all views (render with uniform_resolution)");
  }
  // 7-Scenes / OpenCV: the centre of pixel (col,row) is at integer (col,row), so cx_file = cx - 0.5.
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  K(0, 0) = first.sensor.fx;
  K(1, 1) = first.sensor.fy;
  K(0, 2) = first.sensor.cx - 0.5;
  K(1, 2) = first.sensor.cy - 0.5;
  write_file_atomic(dir / "camera-intrinsics.txt", matrix_text(K));
  out.files.push_back(dir / "camera-intrinsics.txt");

  for (std::size_t i = 0; i < scene.views.size(); ++i) {
    const SynthView& v = scene.views[i];
    char stem[32];
    std::snprintf(stem, sizeof stem, "frame-%06zu", i);
    Image16 depth;
    depth.width = v.width;
    depth.height = v.height;
    depth.data.assign(v.size(), 0);
    for (std::size_t k = 0; k < v.size(); ++k) {
      if (!(v.depth[k] > 0)) continue;
      const double units = std::round(v.depth[k] / o.rgbd_depth_scale);
      if (units >= 1 && units <= 65535) depth.data[k] = std::uint16_t(units);
      else ++out.rgbd_clipped;
    }
    Eigen::Matrix4d pose = Eigen::Matrix4d::Identity();  // camera -> world
    pose.topLeftCorner<3, 3>() = v.sensor.R.transpose();
    pose.topRightCorner<3, 1>() = v.sensor.centre();
    const std::string s = stem;
    write_png16(dir / (s + ".depth.png"), depth);
    write_png8(dir / (s + ".color.png"), rgb_image(v));
    write_file_atomic(dir / (s + ".pose.txt"), matrix_text(pose));
    for (const char* suffix : {".depth.png", ".color.png", ".pose.txt"}) out.files.push_back(dir / (s + suffix));
    files.depth.push_back(s + ".depth.png");
    files.image.push_back(s + ".color.png");
  }
}

json vec(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }
json mat(const Eigen::Matrix3d& m) {
  json a = json::array();
  for (int r = 0; r < 3; ++r) a.push_back(json::array({m(r, 0), m(r, 1), m(r, 2)}));
  return a;
}

json scene_json(const SyntheticScene& scene, const SceneWriteOptions& o, const Files& files) {
  const SynthOptions& so = scene.options;
  json j;
  j["generator"] = "scalefuse synth";
  j["version"] = 1;
  j["format"] = format_name(o.format);
  j["source"] = o.source;
  j["reference"] = "reference.ply";
  j["normalization"] = {{"size", so.size},
                        {"measure", so.size_measure == SynthOptions::SizeMeasure::Extent ? "extent" : "diagonal"},
                        {"scale", scene.scale},
                        {"source_centre", vec(scene.source_centre)}};
  j["options"] = {{"far_views", so.far_views},       {"far_width", so.far_width},
                  {"far_height", so.far_height},     {"far_fill", so.far_fill},
                  {"close_views", so.close_views},   {"close_width", so.close_width},
                  {"close_height", so.close_height}, {"footprint_ratio", so.footprint_ratio},
                  {"close_tilt_deg", so.close_tilt_deg}, {"focal", so.focal},
                  {"uniform_resolution", so.uniform_resolution}, {"noise", so.noise},
                  {"seed", so.seed}};
  if (o.format == SceneFormat::Rgbd) j["options"]["rgbd_depth_scale"] = o.rgbd_depth_scale;
  j["focus"] = vec(scene.focus);
  j["focus_normal"] = vec(scene.focus_normal);
  j["close_radius"] = scene.close_radius;
  j["coarse_footprint"] = scene.coarse_footprint;
  j["fine_footprint"] = scene.fine_footprint;
  j["footprint_ratio"] = scene.fine_footprint > 0 ? scene.coarse_footprint / scene.fine_footprint : 0.0;
  json cams = json::array();
  for (std::size_t i = 0; i < scene.views.size(); ++i) {
    const SynthView& v = scene.views[i];
    const Sensor& s = v.sensor;
    Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
    K(0, 0) = s.fx;
    K(1, 1) = s.fy;
    K(0, 2) = s.cx;
    K(1, 2) = s.cy;
    cams.push_back({{"name", v.name},
                    {"kind", v.close ? "close" : "far"},
                    {"width", v.width},
                    {"height", v.height},
                    {"K", mat(K)},
                    {"R", mat(s.R)},
                    {"t", vec(s.t)},
                    {"centre", vec(s.centre())},
                    {"median_footprint", v.median_footprint},
                    {"valid_pixels", v.valid_pixels},
                    {"depth", files.depth[i]},
                    {"image", files.image[i]}});
  }
  j["cameras"] = std::move(cams);
  return j;
}

}  // namespace

std::optional<SceneFormat> parse_scene_format(std::string_view name) {
  if (name == "colmap") return SceneFormat::Colmap;
  if (name == "mve") return SceneFormat::Mve;
  if (name == "rgbd") return SceneFormat::Rgbd;
  return std::nullopt;
}

const char* format_name(SceneFormat format) {
  switch (format) {
    case SceneFormat::Colmap: return "colmap";
    case SceneFormat::Mve: return "mve";
    case SceneFormat::Rgbd: return "rgbd";
  }
  return "?";
}

void SceneWriteOptions::check() const {
  if (!(rgbd_depth_scale > 0) || !std::isfinite(rgbd_depth_scale))
    throw InputError("rgbd depth scale must be > 0 (got " + fmt("%g", rgbd_depth_scale) + ")");
}

WrittenScene write_scene(const SyntheticScene& scene, const fs::path& dir, const SceneWriteOptions& o) {
  o.check();
  if (scene.views.empty()) throw std::invalid_argument("write_scene: the scene has no views");
  make_dirs(dir);
  WrittenScene out;
  Files files;
  switch (o.format) {
    case SceneFormat::Colmap: write_colmap(scene, dir, o, out, files); break;
    case SceneFormat::Mve: write_mve(scene, dir, out, files); break;
    case SceneFormat::Rgbd: write_rgbd(scene, dir, o, out, files); break;
  }
  out.frames = scene.views.size();
  write_ply_mesh(dir / "reference.ply", scene.reference);
  out.files.push_back(dir / "reference.ply");
  write_file_atomic(dir / "synth.json", scene_json(scene, o, files).dump(2) + "\n");
  out.files.push_back(dir / "synth.json");
  return out;
}

void clear_scene_outputs(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return;
  for (const char* sub : {"images", "sparse", "stereo", "views"}) fs::remove_all(dir / sub, ec);
  for (const char* f : {"synth.json", "reference.ply", "camera-intrinsics.txt"}) fs::remove(dir / f, ec);
  std::vector<fs::path> frames;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string n = e.path().filename().string();
    const bool frame = n.rfind("frame-", 0) == 0 &&
                       (n.ends_with(".depth.png") || n.ends_with(".color.png") || n.ends_with(".pose.txt"));
    if (frame) frames.push_back(e.path());
  }
  for (const auto& p : frames) fs::remove(p, ec);
}

SceneInfo read_scene_info(const fs::path& path) {
  const std::string name = path.string();
  std::ifstream in(path);
  if (!in) throw input_error(name, "missing file");
  json j;
  try {
    j = json::parse(in);
  } catch (const std::exception& e) {
    throw input_error(name, std::string("not valid JSON: ") + e.what());
  }
  auto v3 = [&](const json& a) {
    if (!a.is_array() || a.size() != 3) throw input_error(name, "expected a 3-vector");
    return Eigen::Vector3d(a[0].get<double>(), a[1].get<double>(), a[2].get<double>());
  };
  try {
    SceneInfo info;
    info.format = j.at("format").get<std::string>();
    info.reference = path.parent_path() / j.at("reference").get<std::string>();
    info.focus = v3(j.at("focus"));
    info.close_radius = j.at("close_radius").get<double>();
    info.coarse_footprint = j.at("coarse_footprint").get<double>();
    info.fine_footprint = j.at("fine_footprint").get<double>();
    for (const json& c : j.at("cameras")) {
      SceneCamera cam;
      cam.name = c.at("name").get<std::string>();
      cam.close = c.at("kind").get<std::string>() == "close";
      cam.width = c.at("width").get<int>();
      cam.height = c.at("height").get<int>();
      const json &K = c.at("K"), &R = c.at("R");
      cam.sensor.fx = K.at(0).at(0).get<double>();
      cam.sensor.fy = K.at(1).at(1).get<double>();
      cam.sensor.cx = K.at(0).at(2).get<double>();
      cam.sensor.cy = K.at(1).at(2).get<double>();
      for (int r = 0; r < 3; ++r) cam.sensor.R.row(r) = v3(R.at(r)).transpose();
      cam.sensor.t = v3(c.at("t"));
      if (cam.width <= 0 || cam.height <= 0 || !(cam.sensor.fx > 0) || !(cam.sensor.fy > 0))
        throw input_error(name, "camera " + cam.name + " has a bad size or focal length");
      info.cameras.push_back(std::move(cam));
    }
    return info;
  } catch (const json::exception& e) {
    throw input_error(name, std::string("malformed synth.json: ") + e.what());
  }
}

}  // namespace sf
