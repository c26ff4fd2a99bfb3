#include "engine/meshio/ply_io.h"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "engine/error.h"
#include "engine/meshio/atomic_file.h"

namespace sf {
namespace {

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------------------
// Header model

enum class Format { Ascii, BinaryLE, BinaryBE };
enum class Type : std::uint8_t { I8, U8, I16, U16, I32, U32, F32, F64 };

std::optional<Type> parse_type(std::string_view s) {
  if (s == "char" || s == "int8") return Type::I8;
  if (s == "uchar" || s == "uint8") return Type::U8;
  if (s == "short" || s == "int16") return Type::I16;
  if (s == "ushort" || s == "uint16") return Type::U16;
  if (s == "int" || s == "int32") return Type::I32;
  if (s == "uint" || s == "uint32") return Type::U32;
  if (s == "float" || s == "float32") return Type::F32;
  if (s == "double" || s == "float64") return Type::F64;
  return std::nullopt;
}

std::size_t type_size(Type t) {
  switch (t) {
    case Type::I8: case Type::U8: return 1;
    case Type::I16: case Type::U16: return 2;
    case Type::I32: case Type::U32: case Type::F32: return 4;
    case Type::F64: return 8;
  }
  return 0;
}

bool is_float(Type t) { return t == Type::F32 || t == Type::F64; }

struct Property {
  std::string name;
  Type type = Type::F32;        // value type (of the items, for a list)
  bool is_list = false;
  Type count_type = Type::U8;   // list length type
};

struct Element {
  std::string name;
  std::uint64_t count = 0;
  std::vector<Property> props;
};

struct Header {
  Format format = Format::Ascii;
  std::vector<Element> elements;
};

// ---------------------------------------------------------------------------------------------
// Buffered input: binary records or whitespace-separated ASCII tokens, never reading past the end.

class Input {
 public:
  Input(const fs::path& path, std::string name) : name_(std::move(name)), in_(path, std::ios::binary) {
    std::error_code ec;
    if (!fs::is_regular_file(path, ec)) throw input_error(name_, "missing file");
    size_ = fs::file_size(path, ec);
    if (ec || !in_) throw input_error(name_, "cannot open file" + (ec ? ": " + ec.message() : std::string()));
    buf_.resize(kBuffer);
  }

  std::uint64_t remaining() const { return size_ - offset_; }

  void read(void* dst, std::size_t n) {
    auto* out = static_cast<char*>(dst);
    while (n > 0) {
      if (pos_ == end_ && !refill()) throw truncated();
      const std::size_t k = std::min(n, end_ - pos_);
      std::memcpy(out, buf_.data() + pos_, k);
      pos_ += k;
      offset_ += k;
      out += k;
      n -= k;
    }
  }

  // Next line of the header, without its line break. Throws if the header runs past the limit.
  std::string line() {
    std::string s;
    for (;;) {
      if (pos_ == end_ && !refill()) throw input_error(name_, "truncated header (no end_header)");
      const char c = buf_[pos_++];
      ++offset_;
      if (c == '\n') break;
      if (c != '\r') s.push_back(c);
      if (offset_ > kMaxHeader) throw input_error(name_, "header too long (no end_header)");
    }
    return s;
  }

  // Next whitespace-separated token (ASCII bodies).
  std::string_view token() {
    for (;;) {  // skip whitespace
      if (pos_ == end_ && !refill()) throw truncated();
      const char c = buf_[pos_];
      if (c != ' ' && c != '\t' && c != '\n' && c != '\r') break;
      ++pos_;
      ++offset_;
    }
    token_.clear();
    for (;;) {
      if (pos_ == end_ && !refill()) break;  // a token may end the file
      const char c = buf_[pos_];
      if (c == ' ' || c == '\t' || c == '\n' || c == '\r') break;
      if (token_.size() >= 128) throw input_error(name_, "malformed ascii body (token too long)");
      token_.push_back(c);
      ++pos_;
      ++offset_;
    }
    return token_;
  }

  InputError truncated() const { return input_error(name_, "truncated file (unexpected end of data)"); }

 private:
  static constexpr std::size_t kBuffer = 1 << 20;
  static constexpr std::uint64_t kMaxHeader = 1 << 20;

  bool refill() {
    in_.read(buf_.data(), std::streamsize(buf_.size()));
    pos_ = 0;
    end_ = std::size_t(in_.gcount());
    return end_ > 0;
  }

  std::string name_;
  std::ifstream in_;
  std::uint64_t size_ = 0, offset_ = 0;
  std::vector<char> buf_;
  std::size_t pos_ = 0, end_ = 0;
  std::string token_;
};

// ---------------------------------------------------------------------------------------------
// Values

class ValueReader {
 public:
  ValueReader(Input& in, Format format, const std::string& name) : in_(in), format_(format), name_(name) {}

  double value(Type t) {
    if (format_ == Format::Ascii) return ascii_value(t);
    std::uint8_t b[8];
    const std::size_t n = type_size(t);
    in_.read(b, n);
    const bool swap = (format_ == Format::BinaryBE) != (std::endian::native == std::endian::big);
    if (swap) std::reverse(b, b + n);
    switch (t) {
      case Type::I8: return double(std::int8_t(b[0]));
      case Type::U8: return double(b[0]);
      case Type::I16: return double(load<std::int16_t>(b));
      case Type::U16: return double(load<std::uint16_t>(b));
      case Type::I32: return double(load<std::int32_t>(b));
      case Type::U32: return double(load<std::uint32_t>(b));
      case Type::F32: return double(load<float>(b));
      case Type::F64: return load<double>(b);
    }
    return 0;
  }

  // An integer value (list length or vertex index); rejects non-integral ascii values.
  std::int64_t integer(Type t, const char* what) {
    const double v = value(t);
    if (!std::isfinite(v) || v != std::floor(v) || std::fabs(v) > 9.0e15)
      throw input_error(name_, std::string("malformed ") + what + " (not an integer)");
    return std::int64_t(v);
  }

  // Smallest number of bytes a value of type t can take in the body, and the bytes left to hold
  // them (in ASCII the last value needs no separator after it).
  std::uint64_t min_bytes(Type t) const { return format_ == Format::Ascii ? 2 : type_size(t); }
  std::uint64_t budget() const { return in_.remaining() + (format_ == Format::Ascii ? 1 : 0); }

  void skip_property(const Property& p) {
    if (!p.is_list) {
      value(p.type);
      return;
    }
    const std::int64_t n = list_length(p);
    for (std::int64_t i = 0; i < n; ++i) value(p.type);
  }

  std::int64_t list_length(const Property& p) {
    const std::int64_t n = integer(p.count_type, "list length");
    if (n < 0) throw input_error(name_, "malformed list length " + std::to_string(n) + " in property " + p.name);
    if (std::uint64_t(n) > budget() / min_bytes(p.type))
      throw input_error(name_, "list length " + std::to_string(n) + " in property " + p.name +
                                   " exceeds the rest of the file (truncated or corrupt)");
    return n;
  }

 private:
  template <typename T>
  static T load(const std::uint8_t* b) {
    T v;
    std::memcpy(&v, b, sizeof(T));
    return v;
  }

  double ascii_value(Type t) {
    const std::string_view tok = in_.token();
    if (tok.empty()) throw in_.truncated();
    double v = 0;
    const char* first = tok.data();
    const char* last = tok.data() + tok.size();
    if (*first == '+') ++first;
    const auto [ptr, ec] = std::from_chars(first, last, v);
    if (ec != std::errc() || ptr != last)
      throw input_error(name_, "malformed ascii value '" + std::string(tok) + "'");
    (void)t;
    return v;
  }

  Input& in_;
  Format format_;
  const std::string& name_;
};

// ---------------------------------------------------------------------------------------------
// Header parsing

Header parse_header(Input& in, const std::string& name) {
  Header h;
  if (in.line() != "ply") throw input_error(name, "not a PLY file (first line is not 'ply')");
  bool have_format = false;
  for (;;) {
    const std::string line = in.line();
    std::istringstream ss(line);
    std::string kw;
    ss >> kw;
    if (kw.empty() || kw == "comment" || kw == "obj_info") continue;
    if (kw == "end_header") break;
    if (kw == "format") {
      std::string f, version;
      ss >> f >> version;
      if (f == "ascii") h.format = Format::Ascii;
      else if (f == "binary_little_endian") h.format = Format::BinaryLE;
      else if (f == "binary_big_endian") h.format = Format::BinaryBE;
      else throw input_error(name, "unknown PLY format '" + f + "'");
      have_format = true;
    } else if (kw == "element") {
      Element e;
      std::string count;
      ss >> e.name >> count;
      std::uint64_t n = 0;
      const auto [ptr, ec] = std::from_chars(count.data(), count.data() + count.size(), n);
      if (e.name.empty() || count.empty() || ec != std::errc() || ptr != count.data() + count.size())
        throw input_error(name, "malformed header line '" + line + "'");
      e.count = n;
      h.elements.push_back(std::move(e));
    } else if (kw == "property") {
      if (h.elements.empty()) throw input_error(name, "property before any element: '" + line + "'");
      Property p;
      std::string t;
      ss >> t;
      if (t == "list") {
        std::string ct, it;
        ss >> ct >> it >> p.name;
        const auto c = parse_type(ct), i = parse_type(it);
        if (!c || !i || p.name.empty()) throw input_error(name, "malformed header line '" + line + "'");
        if (is_float(*c)) throw input_error(name, "list length of a floating-point type: '" + line + "'");
        p.is_list = true;
        p.count_type = *c;
        p.type = *i;
      } else {
        ss >> p.name;
        const auto ty = parse_type(t);
        if (!ty || p.name.empty()) throw input_error(name, "malformed header line '" + line + "'");
        p.type = *ty;
      }
      h.elements.back().props.push_back(std::move(p));
    } else {
      throw input_error(name, "unknown header keyword in '" + line + "'");
    }
  }
  if (!have_format) throw input_error(name, "header has no format line");
  return h;
}

int find_prop(const Element& e, std::initializer_list<std::string_view> names) {
  for (std::string_view n : names)
    for (std::size_t i = 0; i < e.props.size(); ++i)
      if (!e.props[i].is_list && e.props[i].name == n) return int(i);
  return -1;
}

std::uint8_t to_colour(double v, Type t) {
  if (is_float(t)) v *= 255.0;  // float colours are in [0, 1]
  if (!(v > 0)) return 0;
  return v >= 255 ? 255 : std::uint8_t(std::lround(v));
}

}  // namespace

// -------------------------------------------------------------------------------------------------

Mesh read_ply_mesh(const fs::path& path) {
  const std::string name = path.string();
  Input in(path, name);
  const Header header = parse_header(in, name);
  ValueReader values(in, header.format, name);

  // Plausibility of the counts before anything is allocated from them: every item of an element
  // takes at least min_item bytes, so count * min_item must fit in what is left of the file.
  {
    const std::uint64_t budget = values.budget();
    std::uint64_t need = 0;
    for (const Element& e : header.elements) {
      std::uint64_t item = 0;
      for (const Property& p : e.props) item += values.min_bytes(p.is_list ? p.count_type : p.type);
      if (item == 0) continue;
      if (e.count > budget / item || need > budget - e.count * item)
        throw input_error(name, "element " + e.name + " declares " + std::to_string(e.count) +
                                    " items, more than the file can hold (truncated or corrupt)");
      need += e.count * item;
    }
  }

  Mesh mesh;
  bool have_vertices = false;
  std::vector<std::int64_t> strip;  // one list of the tristrips element at a time
  auto add_face = [&](std::int64_t a, std::int64_t b, std::int64_t c) {
    mesh.faces.push_back({std::uint32_t(a), std::uint32_t(b), std::uint32_t(c)});
  };
  auto check_index = [&](std::int64_t v) {
    if (v < 0 || v > std::int64_t(std::numeric_limits<std::uint32_t>::max()))
      throw input_error(name, "face refers to vertex " + std::to_string(v) + " (negative or too large)");
  };

  for (const Element& e : header.elements) {
    if (e.props.empty()) continue;  // nothing stored
    if (e.name == "vertex" && !have_vertices) {
      have_vertices = true;
      const int ix = find_prop(e, {"x"}), iy = find_prop(e, {"y"}), iz = find_prop(e, {"z"});
      if (ix < 0 || iy < 0 || iz < 0) throw input_error(name, "element vertex lacks x, y or z");
      const int ir = find_prop(e, {"red", "diffuse_red", "r"});
      const int ig = find_prop(e, {"green", "diffuse_green", "g"});
      const int ib = find_prop(e, {"blue", "diffuse_blue", "b"});
      const bool colour = ir >= 0 && ig >= 0 && ib >= 0;
      const int ic = find_prop(e, {"confidence"}), is = find_prop(e, {"scale"});
      mesh.vertices.resize(e.count);
      if (colour) mesh.colours.resize(e.count);
      if (ic >= 0) mesh.confidence.resize(e.count);
      if (is >= 0) mesh.scale.resize(e.count);
      std::vector<double> v(e.props.size());
      for (std::uint64_t k = 0; k < e.count; ++k) {
        for (std::size_t j = 0; j < e.props.size(); ++j) {
          if (e.props[j].is_list) values.skip_property(e.props[j]);
          else v[j] = values.value(e.props[j].type);
        }
        mesh.vertices[k] = Eigen::Vector3f(float(v[ix]), float(v[iy]), float(v[iz]));
        if (colour)
          mesh.colours[k] = {to_colour(v[ir], e.props[ir].type), to_colour(v[ig], e.props[ig].type),
                             to_colour(v[ib], e.props[ib].type)};
        if (ic >= 0) mesh.confidence[k] = float(v[ic]);
        if (is >= 0) mesh.scale[k] = float(v[is]);
      }
    } else if (e.name == "face" || e.name == "tristrips") {
      int il = -1;
      for (std::size_t j = 0; j < e.props.size(); ++j)
        if (e.props[j].is_list && (e.props[j].name == "vertex_indices" || e.props[j].name == "vertex_index")) il = int(j);
      if (il < 0) throw input_error(name, "element " + e.name + " has no vertex_indices list");
      const bool strips = e.name == "tristrips";
      const Property& lp = e.props[il];
      if (!strips) mesh.faces.reserve(mesh.faces.size() + e.count);
      for (std::uint64_t k = 0; k < e.count; ++k) {
        for (std::size_t j = 0; j < e.props.size(); ++j) {
          if (int(j) != il) {
            values.skip_property(e.props[j]);
            continue;
          }
          const std::int64_t n = values.list_length(lp);
          if (!strips) {
            std::int64_t first = 0, prev = 0;
            for (std::int64_t i = 0; i < n; ++i) {
              const std::int64_t idx = values.integer(lp.type, "vertex index");
              check_index(idx);
              if (i == 0) first = idx;
              else if (i >= 2) add_face(first, prev, idx);  // fan triangulation of polygons
              prev = idx;
            }
            continue;
          }
          // Triangle strips: -1 ends a strip; winding alternates along a strip; triangles with a
          // repeated vertex (used to join strips) are dropped.
          strip.clear();
          auto flush = [&] {
            for (std::size_t i = 2; i < strip.size(); ++i) {
              const std::int64_t a = strip[i - 2], b = strip[i - 1], c = strip[i];
              if (a == b || b == c || a == c) continue;
              if (i % 2 == 0) add_face(a, b, c);
              else add_face(b, a, c);
            }
            strip.clear();
          };
          for (std::int64_t i = 0; i < n; ++i) {
            const std::int64_t idx = values.integer(lp.type, "vertex index");
            if (idx == -1) {
              flush();
              continue;
            }
            check_index(idx);
            strip.push_back(idx);
          }
          flush();
        }
      }
    } else {
      for (std::uint64_t k = 0; k < e.count; ++k)
        for (const Property& p : e.props) values.skip_property(p);
    }
  }

  if (!have_vertices) throw input_error(name, "no vertex element");
  const std::size_t nv = mesh.vertices.size();
  for (std::size_t f = 0; f < mesh.faces.size(); ++f)
    for (std::uint32_t v : mesh.faces[f])
      if (v >= nv)
        throw input_error(name, "face " + std::to_string(f) + " refers to vertex " + std::to_string(v) +
                                    " but the file has " + std::to_string(nv) + " vertices");
  return mesh;
}

// -------------------------------------------------------------------------------------------------

void write_ply_mesh(const fs::path& path, const Mesh& mesh) {
  const std::size_t nv = mesh.vertices.size();
  auto check_size = [&](std::size_t n, const char* what) {
    if (n != 0 && n != nv)
      throw std::invalid_argument(path.string() + ": mesh has " + std::to_string(n) + " " + what + " for " +
                                  std::to_string(nv) + " vertices");
  };
  check_size(mesh.colours.size(), "colours");
  check_size(mesh.confidence.size(), "confidences");
  check_size(mesh.scale.size(), "scales");
  for (const auto& f : mesh.faces)
    for (std::uint32_t v : f)
      if (v >= nv) throw std::invalid_argument(path.string() + ": face refers to a missing vertex");
  const bool colour = !mesh.colours.empty(), conf = !mesh.confidence.empty(), scale = !mesh.scale.empty();
  PlyStreamWriter out(path, colour, conf, scale);
  out.begin(nv, mesh.faces.size());
  for (std::size_t i = 0; i < nv; ++i)
    out.vertex(mesh.vertices[i], colour ? mesh.colours[i] : Rgb8{}, conf ? mesh.confidence[i] : 0.f,
               scale ? mesh.scale[i] : 0.f);
  for (const auto& f : mesh.faces) out.face(f);
  out.end();
}

PlyStreamWriter::PlyStreamWriter(fs::path path, bool colour, bool confidence, bool scale)
    : path_(std::move(path)), colour_(colour), confidence_(confidence), scale_(scale) {}

PlyStreamWriter::~PlyStreamWriter() = default;

void PlyStreamWriter::begin(std::size_t vertices, std::size_t faces) {
  static_assert(std::endian::native == std::endian::little, "the writer emits host-order floats as little-endian");
  if (vertices > std::size_t(std::numeric_limits<std::int32_t>::max()))
    throw std::invalid_argument(path_.string() + ": too many vertices for PLY int indices");
  vertices_ = vertices;
  faces_ = faces;
  std::string header = "ply\nformat binary_little_endian 1.0\ncomment written by scalefuse\n";
  header += "element vertex " + std::to_string(vertices) + "\n";
  header += "property float x\nproperty float y\nproperty float z\n";
  if (colour_) header += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  if (confidence_) header += "property float confidence\n";
  if (scale_) header += "property float scale\n";
  header += "element face " + std::to_string(faces) + "\n";
  header += "property list uchar int vertex_indices\nend_header\n";
  file_ = std::make_unique<AtomicFile>(path_);
  file_->write(header);
  buffer_.reserve(1 << 20);
}

void PlyStreamWriter::put(const void* p, std::size_t n) {
  const char* c = static_cast<const char*>(p);
  buffer_.insert(buffer_.end(), c, c + n);
}

void PlyStreamWriter::drain() {
  file_->write(buffer_.data(), buffer_.size());
  buffer_.clear();
}

void PlyStreamWriter::vertex(const Eigen::Vector3f& position, const Rgb8& colour, float confidence, float scale) {
  if (vertices_seen_++ >= vertices_) throw std::logic_error(path_.string() + ": more vertices than announced");
  put(position.data(), 3 * sizeof(float));
  if (colour_) put(colour.data(), 3);
  if (confidence_) put(&confidence, sizeof(float));
  if (scale_) put(&scale, sizeof(float));
  if (buffer_.size() >= (1 << 20) - 64) drain();
}

void PlyStreamWriter::face(const std::array<std::uint32_t, 3>& f) {
  if (vertices_seen_ != vertices_ || faces_seen_++ >= faces_)
    throw std::logic_error(path_.string() + ": face out of order or more faces than announced");
  const std::uint8_t n = 3;
  const std::int32_t idx[3] = {std::int32_t(f[0]), std::int32_t(f[1]), std::int32_t(f[2])};
  put(&n, 1);
  put(idx, sizeof(idx));
  if (buffer_.size() >= (1 << 20) - 64) drain();
}

void PlyStreamWriter::end() {
  if (vertices_seen_ != vertices_ || faces_seen_ != faces_)
    throw std::logic_error(path_.string() + ": fewer vertices or faces than announced");
  drain();
  file_->commit();
  file_.reset();
}

}  // namespace sf
