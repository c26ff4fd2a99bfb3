// The bad input table (issue 6, docs/hardening.md): for every reader, and for configurations,
// plans, tiles and journals, each malformed case run through the command-line program must give
// exit code 2, one line naming the file and the problem, and no output (no mesh, no temporary
// file). Each reader's table starts from a small valid scene that fuses (exit 0), so a case fails
// because of its defect alone. --skip-bad turns per-depth-map defects into a listed skip.
//
// With SCALEFUSE_BAD_INPUT_TABLE=FILE set, every case appends "| reader | case | message |" to FILE
// (how docs/hardening.md's table was made).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "engine/input/image_io.h"
#include "engine/synth/scene_writer.h"
#include "engine/synth/shapes.h"
#include "engine/synth/synth.h"
#include "tests/test_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

std::string read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}
void write_all(const fs::path& p, const std::string& bytes) {
  fs::create_directories(p.parent_path());
  std::ofstream(p, std::ios::binary | std::ios::trunc) << bytes;
}
// `text` with the first occurrence of `a` replaced by `b` (the case must find `a`).
std::string replaced(const std::string& text, const std::string& a, const std::string& b) {
  const std::size_t at = text.find(a);
  if (at == std::string::npos) throw std::logic_error("test fixture lacks \"" + a + "\"");
  return text.substr(0, at) + b + text.substr(at + a.size());
}
void edit(const fs::path& p, const std::string& a, const std::string& b) { write_all(p, replaced(read_all(p), a, b)); }
void truncate_to(const fs::path& p, std::uintmax_t bytes) { fs::resize_file(p, bytes); }
std::string f32(float v) { return std::string(reinterpret_cast<const char*>(&v), 4); }
std::string i32(std::int32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); }
std::string u64(std::uint64_t v) { return std::string(reinterpret_cast<const char*>(&v), 8); }

// The i-th non-comment line of a COLMAP text file.
std::string colmap_line(const fs::path& p, int i) {
  std::istringstream in(read_all(p));
  std::string line;
  while (std::getline(in, line))
    if (!line.empty() && line[0] != '#' && i-- == 0) return line;
  throw std::logic_error("no line");
}
std::vector<std::string> tokens(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> t;
  for (std::string s; in >> s;) t.push_back(s);
  return t;
}
std::string joined(const std::vector<std::string>& t) {
  std::string s;
  for (const auto& x : t) s += (s.empty() ? "" : " ") + x;
  return s;
}

struct CliRun {
  int code = 0;
  std::string log;
};
bool running_as_root() { return ::geteuid() == 0; }
// As root every file is readable: unreadable-file cases run the program as nobody.
std::string as_nobody() { return running_as_root() ? "setpriv --reuid=65534 --regid=65534 --clear-groups " : ""; }

CliRun scalefuse(const std::string& args, bool unprivileged = false) {
  CliRun r;
  r.code = test::run_command((unprivileged ? as_nobody() : "") + test::scalefuse_binary().string() + " " + args, &r.log);
  return r;
}

void note_in_table(const std::string& reader, const std::string& name, const std::string& log, const fs::path& dir) {
  const char* table = std::getenv("SCALEFUSE_BAD_INPUT_TABLE");
  if (!table) return;
  std::string line = log.substr(0, log.find('\n'));
  const std::string prefix = dir.string() + "/";
  for (std::size_t p; (p = line.find(prefix)) != std::string::npos;) line.replace(p, prefix.size(), "");
  for (std::size_t p = 0; (p = line.find('|', p)) != std::string::npos; p += 2) line.replace(p, 1, "\\|");
  std::ofstream(table, std::ios::app) << "| " << reader << " | " << name << " | `" << line << "` |\n";
}

// Exit code 2, a single line that names `file` and contains `what`, and nothing written at `out`
// (nor a temporary beside it).
void expect_bad(const CliRun& r, const fs::path& out, const std::string& file, const std::string& what) {
  EXPECT_EQ(r.code, 2) << r.log;
  EXPECT_EQ(std::count(r.log.begin(), r.log.end(), '\n'), 1) << r.log;
  EXPECT_NE(r.log.find(file), std::string::npos) << "message does not name " << file << ": " << r.log;
  EXPECT_NE(r.log.find(what), std::string::npos) << "message does not say \"" << what << "\": " << r.log;
  EXPECT_FALSE(fs::exists(out)) << out;
  // Nor a job folder: a fuse that stopped on bad input before integrating anything leaves none.
  EXPECT_FALSE(fs::exists(out.string() + ".job")) << out << ".job";
  if (fs::exists(out.parent_path())) {
    for (const auto& e : fs::recursive_directory_iterator(out.parent_path())) {
      EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << "left behind " << e.path();
    }
  }
}

// One malformed case: `mutate` breaks a copy of the reader's valid scene in `input`; the fuse (or
// `command`, with {in} and {out} replaced) must fail as expect_bad says.
struct Case {
  // A constructor rather than an aggregate, so that the many cases without the last two fields
  // need not spell them out (GCC warns of each omitted field otherwise).
  Case(std::string name, std::function<void(const fs::path& input)> mutate, std::string file, std::string what,
       bool unprivileged = false, std::string flags = {})
      : name(std::move(name)), mutate(std::move(mutate)), file(std::move(file)), what(std::move(what)),
        unprivileged(unprivileged), flags(std::move(flags)) {}
  std::string name;
  std::function<void(const fs::path& input)> mutate;
  std::string file, what;
  bool unprivileged = false;
  std::string flags;
};

std::string substitute(std::string s, const std::string& key, const std::string& value) {
  for (std::size_t p; (p = s.find(key)) != std::string::npos;) s.replace(p, key.size(), value);
  return s;
}

// Runs every case of a reader's table on copies of `base` (which must fuse), all in `root`.
void run_table(const std::string& reader, const fs::path& base, const std::vector<Case>& cases,
               const std::string& base_flags = "") {
  const fs::path root = base.parent_path();
  {
    const CliRun ok = scalefuse("fuse " + base.string() + " -o " + (root / "base.ply").string() + " -q " + base_flags);
    ASSERT_EQ(ok.code, 0) << reader << " base scene does not fuse: " << ok.log;
    ASSERT_TRUE(fs::exists(root / "base.ply"));
  }
  int n = 0;
  for (const Case& c : cases) {
    SCOPED_TRACE(reader + ": " + c.name);
    const fs::path dir = root / ("case" + std::to_string(n++));
    fs::create_directories(dir);
    fs::copy(base, dir / "in", fs::copy_options::recursive);
    c.mutate(dir / "in");
    if (c.unprivileged) {  // nobody must reach the input and write the output folder
      fs::permissions(dir, fs::perms::all);
      fs::permissions(root, fs::perms::others_exec, fs::perm_options::add);
    }
    const fs::path out = dir / "m.ply";
    const CliRun r = scalefuse("fuse " + (dir / "in").string() + " -o " + out.string() + " -q " + base_flags + " " + c.flags,
                            c.unprivileged);
    expect_bad(r, out, c.file, c.what);
    note_in_table(reader, c.name, r.log, dir);
  }
}

// A small multi-scale scene: a sphere seen by four far views and one close view.
SyntheticScene small_scene(bool uniform) {
  SynthOptions o;
  o.far_views = 4;
  o.far_width = 40;
  o.far_height = 30;
  o.close_views = 1;
  o.close_width = 48;
  o.close_height = 36;
  o.footprint_ratio = 2.5;
  o.uniform_resolution = uniform;
  return render_scene(make_sphere(Eigen::Vector3d::Zero(), 0.5, 3), o);
}
fs::path write_base(const std::string& name, SceneFormat format, bool binary = false) {
  const fs::path base = test::scratch_dir(name) / "base";
  SceneWriteOptions w;
  w.format = format;
  w.colmap_binary = binary;
  write_scene(small_scene(format == SceneFormat::Rgbd), base, w);
  return base;
}

// The mutations every depth-map format shares, given how to write a map of w x h with `values`.
const float kNaN = std::numeric_limits<float>::quiet_NaN();
const float kInf = std::numeric_limits<float>::infinity();

const char* kMap = "stereo/depth_maps/far_001.png.geometric.bin";
std::string colmap_map(const std::string& header, const std::vector<float>& values) {
  std::string s = header;
  for (float v : values) s += f32(v);
  return s;
}
// The far_001 map with its pixel `i` set to v.
void set_colmap_depth(const fs::path& in, std::size_t pixel, float v) {
  std::string s = read_all(in / kMap);
  const std::size_t data = s.find("&1&") + 3;
  std::memcpy(s.data() + data + 4 * pixel, &v, 4);
  write_all(in / kMap, s);
}

std::vector<Case> colmap_depth_map_cases() {
  return {
      {"depth map truncated", [](const fs::path& in) { truncate_to(in / kMap, fs::file_size(in / kMap) - 3); },
       "far_001.png.geometric.bin", "truncated"},
      {"depth map wrong magic (not W&H&C&)", [](const fs::path& in) { write_all(in / kMap, "PK\x03\x04garbage"); },
       "far_001.png.geometric.bin", "header"},
      {"depth map absurd size 100000x100000", [](const fs::path& in) {
         write_all(in / kMap, colmap_map("100000&100000&1&", std::vector<float>(12, 1.f)));
       }, "far_001.png.geometric.bin", "holds"},
      {"depth map negative size", [](const fs::path& in) {
         write_all(in / kMap, colmap_map("-40&30&1&", std::vector<float>(1200, 1.f)));
       }, "far_001.png.geometric.bin", "header"},
      {"depth map of 3 channels", [](const fs::path& in) {
         write_all(in / kMap, colmap_map("40&30&3&", std::vector<float>(3600, 1.f)));
       }, "far_001.png.geometric.bin", "channel"},
      {"depth map of one pixel", [](const fs::path& in) { write_all(in / kMap, colmap_map("1&1&1&", {2.f})); },
       "far_001.png.geometric.bin", "1x1"},
      {"NaN depth", [](const fs::path& in) { set_colmap_depth(in, 41, kNaN); }, "far_001.png.geometric.bin",
       "col 1, row 1"},
      {"infinite depth", [](const fs::path& in) { set_colmap_depth(in, 41, kInf); }, "far_001.png.geometric.bin",
       "col 1, row 1"},
      {"negative depth", [](const fs::path& in) { set_colmap_depth(in, 41, -1.f); }, "far_001.png.geometric.bin",
       "col 1, row 1"},
      {"depth map larger than its image", [](const fs::path& in) {
         write_all(in / kMap, colmap_map("80&60&1&", std::vector<float>(4800, 1.f)));
       }, "far_001.png.geometric.bin", "larger than"},
      {"depth map unreadable (mode 000)", [](const fs::path& in) { fs::permissions(in / kMap, fs::perms::none); },
       "far_001.png.geometric.bin", "Permission denied", true},
      {"colour image corrupt", [](const fs::path& in) { write_all(in / "images/far_001.png", "\x89PNG\r\n\x1a\nbroken"); },
       "images/far_001.png", "PNG"},
      {"colour image of another size", [](const fs::path& in) {
         write_png8(in / "images/far_001.png", Image8{7, 7, 3, std::vector<std::uint8_t>(147, 9)});
       }, "images/far_001.png", "camera says 40x30"},
      {"empty scene (no depth maps)", [](const fs::path& in) {
         fs::remove_all(in / "stereo/depth_maps");
         fs::create_directories(in / "stereo/depth_maps");
       }, "in", "no geometric depth maps"},
  };
}

TEST(BadInputTable, ColmapTextModel) {
  const fs::path base = write_base("bad-colmap-txt", SceneFormat::Colmap);
  std::vector<Case> cases = {
      {"cameras.txt line cut short", [](const fs::path& in) {
         const fs::path p = in / "sparse/cameras.txt";
         auto t = tokens(colmap_line(p, 0));
         edit(p, joined(t), joined({t[0], t[1], t[2], t[3], t[4]}));
       }, "cameras.txt", "PINHOLE"},
      {"cameras.txt junk number", [](const fs::path& in) {
         const fs::path p = in / "sparse/cameras.txt";
         auto t = tokens(colmap_line(p, 0));
         const std::string old = joined(t);
         t[4] = "12abc";
         edit(p, old, joined(t));
       }, "cameras.txt", "12abc"},
      {"cameras.txt negative width", [](const fs::path& in) {
         const fs::path p = in / "sparse/cameras.txt";
         auto t = tokens(colmap_line(p, 0));
         const std::string old = joined(t);
         t[2] = "-40";
         edit(p, old, joined(t));
       }, "cameras.txt", "-40"},
      {"cameras.txt absurd width", [](const fs::path& in) {
         const fs::path p = in / "sparse/cameras.txt";
         auto t = tokens(colmap_line(p, 0));
         const std::string old = joined(t);
         t[2] = "99999999999";
         edit(p, old, joined(t));
       }, "cameras.txt", "99999999999"},
      {"cameras.txt zero focal length", [](const fs::path& in) {
         const fs::path p = in / "sparse/cameras.txt";
         auto t = tokens(colmap_line(p, 0));
         const std::string old = joined(t);
         t[4] = "0";
         edit(p, old, joined(t));
       }, "cameras.txt", "focal length"},
      {"cameras.txt distorted model", [](const fs::path& in) {
         const fs::path p = in / "sparse/cameras.txt";
         edit(p, "PINHOLE", "OPENCV");
       }, "cameras.txt", "undistorted"},
      {"cameras.txt duplicate id", [](const fs::path& in) {
         const fs::path p = in / "sparse/cameras.txt";
         write_all(p, read_all(p) + colmap_line(p, 0) + "\n");
       }, "cameras.txt", "duplicate camera id"},
      {"cameras.txt missing", [](const fs::path& in) { fs::remove(in / "sparse/cameras.txt"); }, "cameras.{bin,txt}",
       "without a model"},
      {"images.txt missing", [](const fs::path& in) { fs::remove(in / "sparse/images.txt"); }, "images.{bin,txt}",
       "without a model"},
      {"images.txt unreadable (mode 000)", [](const fs::path& in) {
         fs::permissions(in / "sparse/images.txt", fs::perms::none);
       }, "images.txt", "Permission denied", true},
      {"cameras.txt unreadable (mode 000)", [](const fs::path& in) {
         fs::permissions(in / "sparse/cameras.txt", fs::perms::none);
       }, "cameras.txt", "Permission denied", true},
      {"images.txt quaternion of zero length", [](const fs::path& in) {
         const fs::path p = in / "sparse/images.txt";
         auto t = tokens(colmap_line(p, 0));
         const std::string old = joined(t);
         t[1] = t[2] = t[3] = t[4] = "0";
         edit(p, old, joined(t));
       }, "images.txt", "quaternion"},
      {"images.txt NaN translation", [](const fs::path& in) {
         const fs::path p = in / "sparse/images.txt";
         auto t = tokens(colmap_line(p, 0));
         const std::string old = joined(t);
         t[5] = "nan";
         edit(p, old, joined(t));
       }, "images.txt", "nan"},
      {"images.txt translation beyond float range", [](const fs::path& in) {
         const fs::path p = in / "sparse/images.txt";
         auto t = tokens(colmap_line(p, 2));
         const std::string old = joined(t);
         t[6] = "1e300";
         edit(p, old, joined(t));
       }, "png.geometric.bin", "out of range"},
      {"images.txt duplicate id", [](const fs::path& in) {
         const fs::path p = in / "sparse/images.txt";
         auto t = tokens(colmap_line(p, 2));
         const std::string old = joined(t);
         t[0] = tokens(colmap_line(p, 0))[0];
         edit(p, old, joined(t));
       }, "images.txt", "duplicate image id"},
      {"images.txt duplicate name", [](const fs::path& in) {
         const fs::path p = in / "sparse/images.txt";
         auto t = tokens(colmap_line(p, 2));
         const std::string old = joined(t);
         t[9] = tokens(colmap_line(p, 0))[9];
         edit(p, old, joined(t));
       }, "images.txt", "duplicate image name"},
      {"images.txt unknown camera", [](const fs::path& in) {
         const fs::path p = in / "sparse/images.txt";
         auto t = tokens(colmap_line(p, 0));
         const std::string old = joined(t);
         t[8] = "4242";
         edit(p, old, joined(t));
       }, "images.txt", "camera 4242"},
      {"images.txt line cut short", [](const fs::path& in) {
         const fs::path p = in / "sparse/images.txt";
         auto t = tokens(colmap_line(p, 0));
         edit(p, joined(t), joined({t[0], t[1], t[2]}));
       }, "images.txt", "expected"},
  };
  for (Case& c : colmap_depth_map_cases()) cases.push_back(std::move(c));
  run_table("COLMAP (text model)", base, cases);
}

TEST(BadInputTable, ColmapBinaryModel) {
  const fs::path base = write_base("bad-colmap-bin", SceneFormat::Colmap, /*binary=*/true);
  const std::vector<Case> cases = {
      {"cameras.bin truncated", [](const fs::path& in) {
         truncate_to(in / "sparse/cameras.bin", fs::file_size(in / "sparse/cameras.bin") - 8);
       }, "cameras.bin", "truncated"},
      {"cameras.bin count of 2^60", [](const fs::path& in) {
         std::string s = read_all(in / "sparse/cameras.bin");
         write_all(in / "sparse/cameras.bin", u64(std::uint64_t(1) << 60) + s.substr(8));
       }, "cameras.bin", "more than the file can hold"},
      {"cameras.bin unknown model id", [](const fs::path& in) {
         std::string s = read_all(in / "sparse/cameras.bin");
         s.replace(12, 4, i32(99));  // count (8), camera id (4), model id (4)
         write_all(in / "sparse/cameras.bin", s);
       }, "cameras.bin", "model"},
      {"cameras.bin empty file", [](const fs::path& in) { write_all(in / "sparse/cameras.bin", ""); }, "cameras.bin",
       "truncated"},
      {"images.bin truncated", [](const fs::path& in) {
         truncate_to(in / "sparse/images.bin", fs::file_size(in / "sparse/images.bin") - 5);
       }, "images.bin", "truncated"},
      {"images.bin count of 2^60", [](const fs::path& in) {
         std::string s = read_all(in / "sparse/images.bin");
         write_all(in / "sparse/images.bin", u64(std::uint64_t(1) << 60) + s.substr(8));
       }, "images.bin", "more than the file can hold"},
      {"images.bin cut inside the first name", [](const fs::path& in) {
         // Count (8), then the first image: id (4), qvec (32), tvec (24), camera id (4), name.
         std::string s = read_all(in / "sparse/images.bin");
         write_all(in / "sparse/images.bin", s.substr(0, 8 + 64 + 4 + 7));
       }, "images.bin", "more than the file can hold"},
      {"images.bin quaternion of zero length", [](const fs::path& in) {
         std::string s = read_all(in / "sparse/images.bin");
         s.replace(12, 32, std::string(32, '\0'));
         write_all(in / "sparse/images.bin", s);
       }, "images.bin", "quaternion"},
  };
  run_table("COLMAP (binary model)", base, cases);
}

const char* kView = "views/view_0001.mve";
std::string mvei(std::int32_t w, std::int32_t h, std::int32_t c, std::int32_t type, const std::string& pixels) {
  return std::string("\x89MVE_IMAGE\n", 11) + i32(w) + i32(h) + i32(c) + i32(type) + pixels;
}
std::string floats(std::size_t n, float v) {
  std::string s;
  for (std::size_t i = 0; i < n; ++i) s += f32(v);
  return s;
}
void set_mve_depth(const fs::path& in, std::size_t pixel, float v) {
  const fs::path p = in / kView / "depth-L0.mvei";
  std::string s = read_all(p);
  std::memcpy(s.data() + 27 + 4 * pixel, &v, 4);
  write_all(p, s);
}

TEST(BadInputTable, MveScene) {
  const fs::path base = write_base("bad-mve", SceneFormat::Mve);
  const std::string depth = std::string(kView) + "/depth-L0.mvei";
  const std::string meta = std::string(kView) + "/meta.ini";
  const std::vector<Case> cases = {
      {"depth .mvei truncated", [=](const fs::path& in) { truncate_to(in / depth, fs::file_size(in / depth) - 1); },
       "depth-L0.mvei", "truncated"},
      {"depth .mvei header only, cut", [=](const fs::path& in) { truncate_to(in / depth, 15); }, "depth-L0.mvei",
       "truncated"},
      {"depth .mvei wrong magic", [=](const fs::path& in) { edit(in / depth, "MVE_IMAGE", "MVE_IMAGX"); },
       "depth-L0.mvei", "wrong magic"},
      {"depth .mvei absurd size", [=](const fs::path& in) { write_all(in / depth, mvei(1 << 14, 1 << 14, 1, 9, floats(4, 1))); },
       "depth-L0.mvei", "holds"},
      {"depth .mvei negative size", [=](const fs::path& in) { write_all(in / depth, mvei(-40, 30, 1, 9, floats(1200, 1))); },
       "depth-L0.mvei", "-40"},
      {"depth .mvei unknown type", [=](const fs::path& in) { write_all(in / depth, mvei(40, 30, 1, 77, floats(1200, 1))); },
       "depth-L0.mvei", "type"},
      {"depth .mvei of uint8", [=](const fs::path& in) { write_all(in / depth, mvei(40, 30, 1, 1, std::string(1200, '\1'))); },
       "depth-L0.mvei", "float"},
      {"depth .mvei of one pixel", [=](const fs::path& in) { write_all(in / depth, mvei(1, 1, 1, 9, floats(1, 1))); },
       "depth-L0.mvei", "1x1"},
      {"NaN depth", [](const fs::path& in) { set_mve_depth(in, 41, kNaN); }, "depth-L0.mvei", "col 1, row 1"},
      {"infinite depth", [](const fs::path& in) { set_mve_depth(in, 41, -kInf); }, "depth-L0.mvei", "col 1, row 1"},
      {"negative depth", [](const fs::path& in) { set_mve_depth(in, 41, -2.f); }, "depth-L0.mvei", "col 1, row 1"},
      {"depth .mvei unreadable (mode 000)", [=](const fs::path& in) { fs::permissions(in / depth, fs::perms::none); },
       "depth-L0.mvei", "Permission denied", true},
      {"meta.ini without focal_length", [=](const fs::path& in) { edit(in / meta, "focal_length", "focal_lenght"); },
       "meta.ini", "focal_length"},
      {"meta.ini non-orthonormal rotation", [=](const fs::path& in) {
         std::string s = read_all(in / meta);
         const std::size_t at = s.find("rotation");
         const std::size_t end = s.find('\n', at);
         write_all(in / meta, s.substr(0, at) + "rotation = 1 0 0 0 1 0 0 0 2" + s.substr(end));
       }, "meta.ini", "rotation"},
      {"meta.ini NaN translation", [=](const fs::path& in) {
         std::string s = read_all(in / meta);
         const std::size_t at = s.find("translation");
         const std::size_t end = s.find('\n', at);
         write_all(in / meta, s.substr(0, at) + "translation = 0 nan 0" + s.substr(end));
       }, "meta.ini", "translation"},
      {"meta.ini line without '='", [=](const fs::path& in) { write_all(in / meta, read_all(in / meta) + "garbage line\n"); },
       "meta.ini", "expected key = value"},
      {"meta.ini missing", [=](const fs::path& in) { fs::remove(in / meta); }, "meta.ini", "missing file"},
      {"confidence of another size", [](const fs::path& in) {
         write_all(in / kView / "conf-L0.mvei", mvei(4, 3, 1, 9, floats(12, 1)));
       }, "conf-L0.mvei", "the depth map is 40x30"},
      {"negative confidence", [](const fs::path& in) {
         write_all(in / kView / "conf-L0.mvei", mvei(40, 30, 1, 9, floats(1200, -1)));
       }, "conf-L0.mvei", "confidence"},
      {"colour image corrupt", [](const fs::path& in) { write_all(in / kView / "undistorted.png", "\x89PNG\r\n\x1a\nxx"); },
       "undistorted.png", "PNG"},
      {"empty scene (no depth embedding)", [](const fs::path& in) {
         for (const auto& v : fs::directory_iterator(in / "views")) fs::remove(v.path() / "depth-L0.mvei");
       }, "views", "no view holds"},
  };
  run_table("MVE", base, cases);
}

const char* kFrame = "frame-000001";
TEST(BadInputTable, RgbdSequence) {
  const fs::path base = write_base("bad-rgbd", SceneFormat::Rgbd);
  const std::string depth = std::string(kFrame) + ".depth.png";
  const std::string pose = std::string(kFrame) + ".pose.txt";
  const std::vector<Case> cases = {
      {"camera-intrinsics.txt missing", [](const fs::path& in) { fs::remove(in / "camera-intrinsics.txt"); },
       "camera-intrinsics.txt", "missing file"},
      {"camera-intrinsics.txt of 8 numbers", [](const fs::path& in) {
         write_all(in / "camera-intrinsics.txt", "50 0 24\n0 50 18\n0 0\n");
       }, "camera-intrinsics.txt", "expected 9 numbers"},
      {"camera-intrinsics.txt zero focal length", [](const fs::path& in) {
         write_all(in / "camera-intrinsics.txt", "0 0 24\n0 50 18\n0 0 1\n");
       }, "camera-intrinsics.txt", "focal length"},
      {"camera-intrinsics.txt junk", [](const fs::path& in) {
         write_all(in / "camera-intrinsics.txt", "50 0 24\n0 5x0 18\n0 0 1\n");
       }, "camera-intrinsics.txt", "5x0"},
      {"pose of 15 numbers", [=](const fs::path& in) { write_all(in / pose, "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0\n"); },
       pose, "expected 16 numbers"},
      {"pose non-orthonormal rotation", [=](const fs::path& in) {
         write_all(in / pose, "2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n");
       }, pose, "not a rotation"},
      {"pose with NaN", [=](const fs::path& in) { write_all(in / pose, "1 0 0 nan\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"); },
       pose, "nan"},
      {"pose translation beyond float range", [=](const fs::path& in) {
         write_all(in / pose, "1 0 0 0\n0 1 0 1e300\n0 0 1 0\n0 0 0 1\n");
       }, depth, "out of range"},
      {"pose last row not 0 0 0 1", [=](const fs::path& in) {
         write_all(in / pose, "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n");
       }, pose, "last row"},
      {"pose missing", [=](const fs::path& in) { fs::remove(in / pose); }, pose, "missing file"},
      {"depth PNG truncated", [=](const fs::path& in) { truncate_to(in / depth, fs::file_size(in / depth) / 2); },
       depth, "PNG"},
      {"depth PNG wrong magic", [=](const fs::path& in) { write_all(in / depth, "GIF89a garbage"); }, depth, "PNG"},
      {"depth PNG of 8 bits", [=](const fs::path& in) {
         write_png8(in / depth, Image8{48, 36, 1, std::vector<std::uint8_t>(48 * 36, 9)});
       }, depth, "16-bit"},
      {"depth PNG of one pixel", [=](const fs::path& in) { write_png16(in / depth, Image16{1, 1, {1000}}); }, depth,
       "1x1"},
      {"depth PNG unreadable (mode 000)", [=](const fs::path& in) { fs::permissions(in / depth, fs::perms::none); },
       depth, "Permission denied", true},
      {"colour image corrupt", [](const fs::path& in) {
         write_all(in / (std::string(kFrame) + ".color.png"), "\x89PNG\r\n\x1a\nxx");
       }, ".color.png", "PNG"},
      {"empty scene (no depth PNGs)", [](const fs::path& in) {
         for (const auto& e : fs::directory_iterator(in))
           if (e.path().string().ends_with(".depth.png")) fs::remove(e.path());
       }, "in", "without *.depth.png"},
  };
  run_table("RGB-D", base, cases, "--format rgbd");
}

// A range grid of a bumpy 24 x 20 patch seen from +z, and its registration.
std::string range_scan() {
  std::ostringstream v, g;
  int n = 0;
  for (int r = 0; r < 20; ++r)
    for (int c = 0; c < 24; ++c) {
      const double x = 0.002 * c, y = 0.002 * r, z = 0.05 + 0.004 * std::sin(c * 0.3) * std::cos(r * 0.3);
      v << x << " " << y << " " << z << " 1\n";
      g << "1 " << n++ << "\n";
    }
  return "ply\nformat ascii 1.0\nobj_info is_cyberware_data 1\nobj_info num_cols 24\nobj_info num_rows 20\n"
         "element vertex 480\nproperty float x\nproperty float y\nproperty float z\nproperty float confidence\n"
         "element range_grid 480\nproperty list uchar int vertex_indices\nend_header\n" +
         v.str() + g.str();
}

TEST(BadInputTable, RangeGrid) {
  const fs::path base = test::scratch_dir("bad-rangegrid") / "base";
  write_all(base / "s.ply", range_scan());
  write_all(base / "s.conf", "camera 0 0 1 0 0 0 1\nbmesh s.ply 0 0 0 0 0 0 1\n");
  const std::vector<Case> cases = {
      {"conf names a missing scan", [](const fs::path& in) { edit(in / "s.conf", "bmesh s.ply", "bmesh t.ply"); },
       "t.ply", "missing"},
      {"conf quaternion of zero length", [](const fs::path& in) { edit(in / "s.conf", "0 0 0 0 0 0 1", "0 0 0 0 0 0 0"); },
       "s.conf", "unit length"},
      {"conf bmesh line cut short", [](const fs::path& in) { edit(in / "s.conf", "0 0 0 0 0 0 1", "0 0 0"); }, "s.conf",
       "bmesh"},
      {"conf NaN translation", [](const fs::path& in) { edit(in / "s.conf", "0 0 0 0 0 0 1", "nan 0 0 0 0 0 1"); },
       "s.conf", "nan"},
      {"scan truncated", [](const fs::path& in) { truncate_to(in / "s.ply", fs::file_size(in / "s.ply") - 40); },
       "s.ply", "ends early"},
      {"scan grid of the wrong size", [](const fs::path& in) {
         edit(in / "s.ply", "element range_grid 480", "element range_grid 481");
       }, "s.ply", "num_cols x num_rows is 480"},
      {"scan count beyond the file", [](const fs::path& in) {
         edit(in / "s.ply", "element vertex 480", "element vertex 4800000000");
       }, "s.ply", "more than the file can hold"},
      {"scan cell refers past the vertices", [](const fs::path& in) { edit(in / "s.ply", "1 479\n", "1 9999\n"); },
       "s.ply", "9999"},
      {"scan in binary PLY", [](const fs::path& in) {
         edit(in / "s.ply", "format ascii 1.0", "format binary_little_endian 1.0");
       }, "s.ply", "ASCII"},
      {"scan wrong magic", [](const fs::path& in) { edit(in / "s.ply", "ply\n", "plx\n"); }, "s.ply", "PLY"},
      {"scan NaN vertex", [](const fs::path& in) { edit(in / "s.ply", "end_header\n0 0", "end_header\nnan 0"); },
       "s.ply", "vertex 0"},
      {"scan grid of one cell", [](const fs::path& in) {
         write_all(in / "s.ply",
                   "ply\nformat ascii 1.0\nobj_info num_cols 1\nobj_info num_rows 1\nelement vertex 1\nproperty float x\n"
                   "property float y\nproperty float z\nelement range_grid 1\nproperty list uchar int vertex_indices\n"
                   "end_header\n0 0 0.05\n1 0\n");
       }, "s.ply", "1x1"},
      {"scan unreadable (mode 000)", [](const fs::path& in) { fs::permissions(in / "s.ply", fs::perms::none); },
       "s.ply", "Permission denied", true},
      {"scan negative num_cols", [](const fs::path& in) { edit(in / "s.ply", "num_cols 24", "num_cols -24"); }, "s.ply",
       "needs positive obj_info num_cols"},
      {"scan absurd num_cols x num_rows", [](const fs::path& in) {
         edit(in / "s.ply", "num_cols 24\nobj_info num_rows 20", "num_cols 2000000000\nobj_info num_rows 2000000000");
       }, "s.ply", "2000000000x2000000000, each must be 1 to 65536"},
      {"conf unreadable (mode 000)", [](const fs::path& in) { fs::permissions(in / "s.conf", fs::perms::none); },
       "s.conf", "Permission denied", true},
      {"conf without scans (empty scene)", [](const fs::path& in) { write_all(in / "s.conf", "camera 0 0 1 0 0 0 1\n"); },
       "in", "no .conf file with bmesh lines"},
  };
  run_table("range grid", base, cases, "--format rangegrid");
}

// Configurations, and the job's own files: a plan, tiles, the journal.
TEST(BadInputTable, ConfigsPlansTilesJournals) {
  const fs::path root = test::scratch_dir("bad-job");
  const fs::path scene = root / "scene";
  SceneWriteOptions w;
  write_scene(small_scene(false), scene, w);
  const std::string bin = test::scalefuse_binary().string();
  int n = 0;
  // Runs `args` ({dir} = a fresh case folder) after `prepare(dir)`; expects bad input naming `file`.
  auto check = [&](const std::string& table, const std::string& name, const std::function<void(const fs::path&)>& prepare,
                   const std::string& args, const std::string& file, const std::string& what, bool unprivileged = false) {
    SCOPED_TRACE(table + ": " + name);
    const fs::path dir = root / ("case" + std::to_string(n++));
    fs::create_directories(dir);
    prepare(dir);
    const CliRun r = scalefuse(substitute(substitute(args, "{dir}", dir.string()), "{scene}", scene.string()), unprivileged);
    expect_bad(r, dir / "m.ply", file, what);
    EXPECT_FALSE(fs::exists(root / "i.ply"));  // resume writes the job's recorded output: none may appear
    note_in_table(table, name, r.log, dir);
  };
  const std::string fuse = "fuse {scene} -o {dir}/m.ply -q ";
  auto config = [](const std::string& text) {
    return [text](const fs::path& dir) { write_all(dir / "c.toml", text); };
  };
  auto nothing = [](const fs::path&) {};
  check("config", "missing file", nothing, fuse + "--config {dir}/none.toml", "none.toml", "not found");
  check("config", "TOML syntax error", config("[integrate\nlambda = 1\n"), fuse + "--config {dir}/c.toml", "c.toml", "parsing table header");
  check("config", "unknown key", config("[integrate]\nlambada = 1\n"), fuse + "--config {dir}/c.toml", "c.toml",
        "lambada");
  check("config", "wrong type", config("[integrate]\nlambda = \"one\"\n"), fuse + "--config {dir}/c.toml", "c.toml",
        "lambda");
  check("config", "out of range", config("[integrate]\nlambda = -1\n"), fuse + "--config {dir}/c.toml", "c.toml",
        "integrate.lambda must be");
  check("config", "NaN value", config("[integrate]\ngamma = nan\n"), fuse + "--config {dir}/c.toml", "gamma", "expects a number");
  check("config", "--set without '='", nothing, fuse + "--set integrate.lambda", "integrate.lambda", "expected key=value");
  check("config", "--set unknown key", nothing, fuse + "--set nope.x=1", "nope.x", "unknown parameter");
  check("config", "unreadable (mode 000)", [](const fs::path& dir) {
    write_all(dir / "c.toml", "[integrate]\nlambda = 1\n");
    fs::permissions(dir / "c.toml", fs::perms::none);
    fs::permissions(dir, fs::perms::all);
  }, fuse + "--config {dir}/c.toml", "c.toml", "Permission denied", true);

  // A planned job of two tiles, copied per case.
  const fs::path planned = root / "planned";
  ASSERT_EQ(test::run_command(bin + " plan " + scene.string() + " --tiles 2 --job " + planned.string() + " -q"), 0);
  auto planned_copy = [&](const std::function<void(const fs::path& job)>& mutate) {
    return [&, mutate](const fs::path& dir) {
      fs::copy(planned, dir / "job", fs::copy_options::recursive);
      mutate(dir / "job");
    };
  };
  const std::string tile = "run-tile {dir}/job --tile 0 -q";
  check("plan", "plan.json truncated", planned_copy([](const fs::path& j) {
    truncate_to(j / "plan.json", fs::file_size(j / "plan.json") / 2);
  }), tile, "plan.json", "malformed plan");
  check("plan", "plan.json not JSON", planned_copy([](const fs::path& j) { write_all(j / "plan.json", "\x7f" "ELF"); }),
        tile, "plan.json", "malformed plan");
  check("plan", "plan.json of another version", planned_copy([](const fs::path& j) {
    nlohmann::json p = nlohmann::json::parse(read_all(j / "plan.json"));
    p["version"] = 99;
    write_all(j / "plan.json", p.dump());
  }), tile, "plan.json", "version");
  check("plan", "plan.json tile naming a depth map past the input", planned_copy([](const fs::path& j) {
    nlohmann::json p = nlohmann::json::parse(read_all(j / "plan.json"));
    p["tiles"][0]["frames"].push_back(100000);
    write_all(j / "plan.json", p.dump());
  }), tile, "plan.json", "100000");
  check("plan", "tile number past the plan", planned_copy([](const fs::path&) {}),
        "run-tile {dir}/job --tile 7 -q", "job", "tile 7");
  check("plan", "plan.json missing", planned_copy([](const fs::path& j) { fs::remove(j / "plan.json"); }), tile,
        "plan.json", "no plan here");
  check("plan", "plan.json unreadable (mode 000)", planned_copy([](const fs::path& j) {
    fs::permissions(j.parent_path(), fs::perms::all);
    for (const auto& e : fs::recursive_directory_iterator(j)) fs::permissions(e.path(), fs::perms::all);
    fs::permissions(j, fs::perms::all);
    fs::permissions(j / "plan.json", fs::perms::none);
  }), tile, "plan.json", "cannot open file: Permission denied", true);

  // An integrated job (tiles and journal), copied per case; resume must refuse it.
  const fs::path integrated = root / "integrated";
  ASSERT_EQ(test::run_command(bin + " fuse " + scene.string() + " -o " + (root / "i.ply").string() + " --job " +
                              integrated.string() + " --integrate-only -q"),
            0);
  fs::path a_tile;
  for (const auto& e : fs::directory_iterator(integrated / "tiles"))
    if (a_tile.empty() || e.path() < a_tile) a_tile = e.path();
  ASSERT_FALSE(a_tile.empty());
  const std::string tile_name = a_tile.filename().string();
  auto integrated_copy = [&](const std::function<void(const fs::path& job)>& mutate) {
    return [&, mutate](const fs::path& dir) {
      fs::copy(integrated, dir / "job", fs::copy_options::recursive);
      mutate(dir / "job");
    };
  };
  const std::string resume = "resume {dir}/job -q";
  // A damaged or missing tile is not the end of a job: it is rebuilt from the depth maps (the scene
  // is still there) and the mesh is the one the undamaged job gives. The mesh goes to the job's
  // recorded output, root/i.ply, removed after each case.
  std::string undamaged_mesh;
  {
    const fs::path dir = root / "undamaged";
    fs::create_directories(dir);
    integrated_copy([](const fs::path&) {})(dir);
    ASSERT_EQ(scalefuse(substitute(resume, "{dir}", dir.string())).code, 0);
    undamaged_mesh = read_all(root / "i.ply");
    fs::remove(root / "i.ply");
  }
  auto check_rebuilt = [&](const std::string& name, const std::function<void(const fs::path&)>& prepare,
                           const std::string& what) {
    SCOPED_TRACE("tile: " + name);
    const fs::path dir = root / ("case" + std::to_string(n++));
    fs::create_directories(dir);
    prepare(dir);
    const CliRun r = scalefuse(substitute(resume, "{dir}", dir.string()));
    EXPECT_EQ(r.code, 0) << r.log;
    // One line about the tile, then (-q) the line saying where the mesh went.
    EXPECT_EQ(std::count(r.log.begin(), r.log.end(), '\n'), 2) << r.log;
    EXPECT_NE(r.log.find("\nmesh written to "), std::string::npos) << r.log;
    EXPECT_NE(r.log.find(tile_name + ": " + what), std::string::npos) << r.log;
    EXPECT_NE(r.log.find("; rebuilt it by re-integrating the 3 of the job's 5 depth maps that reach it"), std::string::npos)
        << r.log;
    EXPECT_TRUE(read_all(root / "i.ply") == undamaged_mesh) << "the rebuilt job gives the undamaged job's mesh";
    fs::remove(root / "i.ply");
    note_in_table("tile", name, r.log, dir);
  };
  check_rebuilt("payload byte flipped", integrated_copy([&](const fs::path& j) {
    std::string s = read_all(j / "tiles" / tile_name);
    s[s.size() - 3] = char(s[s.size() - 3] ^ 0x40);
    write_all(j / "tiles" / tile_name, s);
  }), "damaged tile: payload checksum mismatch");
  check_rebuilt("header byte flipped", integrated_copy([&](const fs::path& j) {
    std::string s = read_all(j / "tiles" / tile_name);
    s[20] = char(s[20] ^ 0x01);
    write_all(j / "tiles" / tile_name, s);
  }), "damaged tile: header checksum mismatch");
  check_rebuilt("truncated", integrated_copy([&](const fs::path& j) {
    truncate_to(j / "tiles" / tile_name, fs::file_size(j / "tiles" / tile_name) - 10);
  }), "damaged tile: payload of");
  check_rebuilt("wrong magic", integrated_copy([&](const fs::path& j) {
    std::string s = read_all(j / "tiles" / tile_name);
    s[0] = 'X';
    write_all(j / "tiles" / tile_name, s);
  }), "damaged tile: wrong magic");
  check_rebuilt("missing", integrated_copy([&](const fs::path& j) { fs::remove(j / "tiles" / tile_name); }),
                "tile of the last checkpoint is missing");
  check("journal", "job.sqlite not a database", integrated_copy([](const fs::path& j) {
    fs::remove(j / "job.sqlite-wal");
    fs::remove(j / "job.sqlite-shm");
    write_all(j / "job.sqlite", std::string(8192, 'x'));
  }), resume, "job.sqlite", "not a database");
  check("journal", "job.sqlite truncated", integrated_copy([](const fs::path& j) {
    fs::remove(j / "job.sqlite-wal");
    fs::remove(j / "job.sqlite-shm");
    truncate_to(j / "job.sqlite", 100);
  }), resume, "job.sqlite", "malformed");
  check("journal", "job.sqlite of another program", integrated_copy([](const fs::path& j) {
    fs::remove(j / "job.sqlite-wal");
    fs::remove(j / "job.sqlite-shm");
    fs::remove(j / "job.sqlite");
    ASSERT_EQ(test::run_command("python3 -c \"import sqlite3; sqlite3.connect('" + (j / "job.sqlite").string() +
                                "').execute('create table t(x)')\""),
              0);
  }), resume, "job.sqlite", "no such table");
  check("journal", "job folder without a journal", integrated_copy([](const fs::path& j) {
    fs::remove(j / "job.sqlite");
  }), resume, "job", "not a scalefuse job directory");
  // Damaged values inside an intact database: bad input too (exit 2), not an internal error.
  auto journal_sql = [](const std::string& statement) {
    return [statement](const fs::path& j) {
      ASSERT_EQ(test::run_command("python3 -c \"import sqlite3; c = sqlite3.connect('" + (j / "job.sqlite").string() +
                                  "'); c.execute('" + statement + "'); c.commit()\""),
                0);
    };
  };
  check("journal", "max_generation not a number",
        integrated_copy(journal_sql("UPDATE meta SET value = \\'7x\\' WHERE key = \\'max_generation\\'")), resume,
        "job.sqlite", "max_generation is '7x', not a number");
  check("journal", "manifest row out of range",
        integrated_copy(journal_sql("UPDATE manifest SET generation = -1")), resume, "job.sqlite",
        "manifest row out of range");
  check("journal", "job.lock not a file", integrated_copy([](const fs::path& j) {
    fs::remove(j / "job.lock");
    fs::create_directories(j / "job.lock");
  }), resume, "job.lock", "cannot open the job's lock");
}

// --skip-bad: the bad depth maps are skipped, listed (stderr, JOB/skipped.txt, --stats), and the
// mesh is that of the scene without them; when every depth map is bad the job still fails.
TEST(BadInputTable, SkipBadListsWhatItSkipped) {
  const fs::path root = test::scratch_dir("skip-bad");
  const fs::path scene = root / "scene";
  write_scene(small_scene(false), scene, SceneWriteOptions{});
  const fs::path without = root / "without";  // the same scene without far_001 and far_002
  fs::copy(scene, without, fs::copy_options::recursive);
  fs::remove(without / "stereo/depth_maps/far_001.png.geometric.bin");
  fs::remove(without / "stereo/depth_maps/far_002.png.geometric.bin");
  const fs::path far_002 = scene / "stereo/depth_maps/far_002.png.geometric.bin";
  const std::string far_002_good = read_all(far_002);
  set_colmap_depth(scene, 41, kNaN);
  truncate_to(far_002, 30);

  const CliRun refused = scalefuse("fuse " + scene.string() + " -o " + (root / "a.ply").string() + " -q");
  EXPECT_EQ(refused.code, 2) << refused.log;
  EXPECT_FALSE(fs::exists(root / "a.ply"));

  const CliRun r = scalefuse("fuse " + scene.string() + " -o " + (root / "b.ply").string() + " --job " +
                          (root / "b.job").string() + " --skip-bad -q --stats " + (root / "b.json").string());
  ASSERT_EQ(r.code, 0) << r.log;
  EXPECT_NE(r.log.find("skipped 2 bad depth maps"), std::string::npos) << r.log;
  EXPECT_NE(r.log.find("far_001.png.geometric.bin"), std::string::npos) << r.log;
  EXPECT_NE(r.log.find("far_002.png.geometric.bin"), std::string::npos) << r.log;
  const std::string listed = read_all(root / "b.job/skipped.txt");
  EXPECT_EQ(std::count(listed.begin(), listed.end(), '\n'), 2) << listed;
  EXPECT_NE(listed.find("far_001.png.geometric.bin: depth nan at pixel (col 1, row 1)"), std::string::npos) << listed;
  EXPECT_NE(listed.find("far_002.png.geometric.bin"), std::string::npos) << listed;
  const nlohmann::json stats = nlohmann::json::parse(read_all(root / "b.json"));
  ASSERT_EQ(stats["skipped"].size(), 2u);
  EXPECT_NE(stats["skipped"][1]["error"].get<std::string>().find("truncated"), std::string::npos);

  // The skipped depth maps contribute nothing: the mesh is that of the scene without them (the
  // root cube is the same: far_001/002 see nothing the other views do not bound).
  const CliRun w = scalefuse("fuse " + without.string() + " -o " + (root / "c.ply").string() + " -q");
  ASSERT_EQ(w.code, 0) << w.log;
  EXPECT_EQ(read_all(root / "b.ply"), read_all(root / "c.ply"));

  // Resumed, the finished job is accepted as it is (same inputs, skipped ones included).
  const CliRun again = scalefuse("resume " + (root / "b.job").string() + " -q");
  EXPECT_EQ(again.code, 0) << again.log;
  EXPECT_EQ(read_all(root / "b.ply"), read_all(root / "c.ply"));
  // Repaired, a skipped depth map is a changed input (it was never integrated): resume refuses.
  write_all(far_002, far_002_good);
  const CliRun repaired = scalefuse("resume " + (root / "b.job").string() + " -q");
  EXPECT_EQ(repaired.code, 2) << repaired.log;
  EXPECT_NE(repaired.log.find("far_002.png.geometric.bin"), std::string::npos) << repaired.log;
  truncate_to(far_002, 30);

  // Every depth map bad: bad input, and the message says they were skipped.
  const fs::path all_bad = root / "all-bad";
  fs::copy(scene, all_bad, fs::copy_options::recursive);
  for (const auto& e : fs::directory_iterator(all_bad / "stereo/depth_maps")) truncate_to(e.path(), 30);
  const CliRun none = scalefuse("fuse " + all_bad.string() + " -o " + (root / "d.ply").string() + " --skip-bad -q");
  EXPECT_EQ(none.code, 2) << none.log;
  EXPECT_NE(none.log.find("were skipped as bad"), std::string::npos) << none.log;
  EXPECT_FALSE(fs::exists(root / "d.ply"));

  // MVE: a view's missing meta.ini is that view's defect, skippable too.
  const fs::path mve = root / "mve";
  SceneWriteOptions m;
  m.format = SceneFormat::Mve;
  write_scene(small_scene(false), mve, m);
  fs::remove(mve / kView / "meta.ini");
  const CliRun mr = scalefuse("fuse " + mve.string() + " -o " + (root / "e.ply").string() + " --skip-bad -q");
  EXPECT_EQ(mr.code, 0) << mr.log;
  EXPECT_NE(mr.log.find("view_0001.mve/meta.ini: missing file"), std::string::npos) << mr.log;
}

}  // namespace
}  // namespace sf
