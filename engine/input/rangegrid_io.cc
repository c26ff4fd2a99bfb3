#include "engine/input/rangegrid_io.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <string_view>

#include "engine/error.h"
#include "engine/input/file_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;
using namespace input_detail;

struct PlyProperty {
  std::string name;
  bool is_list = false;
};
struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> props;
};

// Walks the whitespace-separated tokens of the ASCII body.
class TokenCursor {
 public:
  TokenCursor(const fs::path& path, std::string_view text) : path_(path), text_(text) {}
  std::string_view next(const char* what) {
    while (pos_ < text_.size() && is_space(text_[pos_])) ++pos_;
    const std::size_t start = pos_;
    while (pos_ < text_.size() && !is_space(text_[pos_])) ++pos_;
    if (pos_ == start) throw input_error(path_.string(), std::string("file ends early, while reading ") + what);
    return text_.substr(start, pos_ - start);
  }
  template <typename T>
  T number(const char* what) {
    const std::string_view tok = next(what);
    T v{};
    if (!parse_number(tok, &v))
      throw input_error(path_.string(), std::string("bad ") + what + " \"" + std::string(tok) + "\"");
    return v;
  }

 private:
  static bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; }
  const fs::path& path_;
  std::string_view text_;
  std::size_t pos_ = 0;
};

}  // namespace

RangeScan read_range_grid_ply(const fs::path& path) {
  const std::string text = read_file_text(path);
  // --- header
  std::size_t pos = 0;
  std::vector<PlyElement> elements;
  long long cols = -1, rows = -1;
  bool first = true, ascii = false, ended = false;
  while (pos < text.size() && !ended) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    const std::string_view line = trim(std::string_view(text).substr(pos, end - pos));
    pos = end + 1;
    const auto tok = split_ws(line);
    if (first) {
      if (line != "ply") throw input_error(path.string(), "not a PLY file");
      first = false;
      continue;
    }
    if (tok.empty() || tok[0] == "comment") continue;
    if (tok[0] == "format") {
      if (tok.size() < 2 || tok[1] != "ascii")
        throw input_error(path.string(), "range grids are read from ASCII PLY only, this file is " +
                                             std::string(tok.size() > 1 ? tok[1] : "of no format"));
      ascii = true;
    } else if (tok[0] == "obj_info") {
      if (tok.size() >= 3 && (tok[1] == "num_cols" || tok[1] == "num_rows")) {
        long long v = 0;
        if (!parse_number(tok[2], &v)) throw input_error(path.string(), "bad obj_info " + std::string(tok[1]));
        (tok[1] == "num_cols" ? cols : rows) = v;
      }
    } else if (tok[0] == "element") {
      PlyElement e;
      if (tok.size() != 3 || !parse_number(tok[2], &e.count))
        throw input_error(path.string(), "bad header line \"" + std::string(line) + "\"");
      e.name = std::string(tok[1]);
      elements.push_back(e);
    } else if (tok[0] == "property") {
      if (elements.empty()) throw input_error(path.string(), "property before any element");
      PlyProperty p;
      p.is_list = tok.size() >= 2 && tok[1] == "list";
      if (tok.size() != (p.is_list ? 5u : 3u))
        throw input_error(path.string(), "bad header line \"" + std::string(line) + "\"");
      p.name = std::string(tok.back());
      elements.back().props.push_back(p);
    } else if (tok[0] == "end_header") {
      ended = true;
    } else {
      throw input_error(path.string(), "unknown header line \"" + std::string(line) + "\"");
    }
  }
  if (!ended) throw input_error(path.string(), "PLY header has no end_header");
  if (!ascii) throw input_error(path.string(), "PLY header has no format line");
  if (cols < 0 || rows < 0)
    throw input_error(path.string(), "not a range grid: needs positive obj_info num_cols and num_rows");
  if (cols == 0 || rows == 0 || cols > (1 << 16) || rows > (1 << 16))
    throw input_error(path.string(), "obj_info num_cols x num_rows is " + std::to_string(cols) + "x" + std::to_string(rows) +
                                         ", each must be 1 to 65536");
  input_detail::check_depth_size(path, cols, rows);

  const std::string_view body = std::string_view(text).substr(std::min(pos, text.size()));
  // Each ASCII value takes at least two bytes (digit + separator): bounds every count by the file.
  for (const auto& e : elements) {
    if (e.count > body.size() / 2 / std::max<std::size_t>(1, e.props.size()))
      throw input_error(path.string(), "header claims " + std::to_string(e.count) + " " + e.name +
                                           " entries, more than the file can hold");
  }
  RangeScan scan;
  scan.num_cols = int(cols);
  scan.num_rows = int(rows);
  const std::uint64_t cells = std::uint64_t(cols) * std::uint64_t(rows);
  bool have_vertex = false, have_grid = false;
  TokenCursor in(path, body);
  for (const auto& e : elements) {
    if (e.name == "vertex") {
      int ix = -1, iy = -1, iz = -1, ic = -1;
      for (int k = 0; k < int(e.props.size()); ++k) {
        const auto& p = e.props[k];
        if (p.is_list) throw input_error(path.string(), "list property in element vertex");
        if (p.name == "x") ix = k;
        if (p.name == "y") iy = k;
        if (p.name == "z") iz = k;
        if (p.name == "confidence") ic = k;
      }
      if (ix < 0 || iy < 0 || iz < 0) throw input_error(path.string(), "element vertex needs x, y and z");
      scan.points.resize(std::size_t(e.count));
      if (ic >= 0) scan.confidence.resize(std::size_t(e.count));
      std::vector<double> v(e.props.size());
      for (std::uint64_t i = 0; i < e.count; ++i) {
        for (double& x : v) x = in.number<double>("vertex coordinate");
        scan.points[i] = Eigen::Vector3f(float(v[ix]), float(v[iy]), float(v[iz]));
        if (!scan.points[i].allFinite())
          throw input_error(path.string(), "vertex " + std::to_string(i) + " is not finite");
        if (ic >= 0) scan.confidence[i] = float(v[ic]);
      }
      have_vertex = true;
    } else if (e.name == "range_grid") {
      if (!have_vertex) throw input_error(path.string(), "element range_grid must follow element vertex");
      if (e.props.size() != 1 || !e.props[0].is_list)
        throw input_error(path.string(), "element range_grid must have one list property");
      if (e.count != cells)
        throw input_error(path.string(), "range_grid has " + std::to_string(e.count) + " cells, num_cols x num_rows is " +
                                             std::to_string(cells));
      scan.grid.assign(std::size_t(cells), -1);
      for (std::uint64_t i = 0; i < cells; ++i) {
        const int n = in.number<int>("range_grid list length");
        if (n == 0) continue;
        if (n != 1)
          throw input_error(path.string(), "range_grid cell " + std::to_string(i) + " lists " + std::to_string(n) +
                                               " vertices; a range image has 0 or 1 per cell");
        const long long idx = in.number<long long>("range_grid vertex index");
        if (idx < 0 || std::uint64_t(idx) >= scan.points.size())
          throw input_error(path.string(), "range_grid cell " + std::to_string(i) + " refers to vertex " +
                                               std::to_string(idx) + " of " + std::to_string(scan.points.size()));
        scan.grid[i] = std::int32_t(idx);
      }
      have_grid = true;
    } else {
      // Elements we do not use (e.g. faces) still have to be walked to reach the next one.
      for (std::uint64_t i = 0; i < e.count; ++i)
        for (const auto& p : e.props) {
          const std::uint64_t n = p.is_list ? in.number<std::uint64_t>("list length") : 1;
          if (n > body.size()) throw input_error(path.string(), "bad list length in element " + e.name);
          for (std::uint64_t k = 0; k < n; ++k) in.next("element data");
        }
    }
  }
  if (!have_vertex || !have_grid)
    throw input_error(path.string(), "not a range grid: needs element vertex and element range_grid");
  return scan;
}

std::vector<RangeScanPose> read_range_grid_conf(const fs::path& path) {
  const std::string text = read_file_text(path);
  std::vector<RangeScanPose> out;
  std::size_t pos = 0, line_no = 0;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    const auto tok = split_ws(std::string_view(text).substr(pos, end - pos));
    pos = end + 1;
    ++line_no;
    if (tok.empty() || tok[0] != "bmesh") continue;
    const std::string where = "line " + std::to_string(line_no) + ": ";
    if (tok.size() != 9) throw input_error(path.string(), where + "expected bmesh <file> tx ty tz qx qy qz qw");
    double v[7];
    for (int k = 0; k < 7; ++k)
      if (!parse_number(tok[2 + k], &v[k]) || !std::isfinite(v[k]))
        throw input_error(path.string(), where + "bad number \"" + std::string(tok[2 + k]) + "\"");
    RangeScanPose p;
    p.file = path.parent_path() / std::string(tok[1]);
    p.t = Eigen::Vector3d(v[0], v[1], v[2]);
    const Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);  // Eigen's constructor takes w first
    if (std::abs(q.norm() - 1.0) > 1e-3)
      throw input_error(path.string(), where + "quaternion is not of unit length (norm " + std::to_string(q.norm()) + ")");
    p.q = q.normalized();
    out.push_back(p);
  }
  return out;
}

}  // namespace sf
