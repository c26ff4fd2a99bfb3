#include "engine/parameters.h"

#include <toml++/toml.h>

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include "engine/error.h"

namespace sf {

namespace {
template <class T>
bool parse_number(const std::string& s, T* out) {
  const char* b = s.data();
  const char* e = s.data() + s.size();
  auto [ptr, ec] = std::from_chars(b, e, *out);
  return ec == std::errc() && ptr == e;
}
}  // namespace

std::vector<double> parse_number_list(const std::string& text, std::size_t count, const std::string& what) {
  const auto fail = [&] {
    return InputError(what + ": '" + text + "' is not " + std::to_string(count) + " comma-separated numbers");
  };
  std::vector<double> v;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    double x;
    if (!parse_number(item, &x) || !std::isfinite(x)) throw fail();
    v.push_back(x);
  }
  if (v.size() != count) throw fail();
  return v;
}

void ParameterSet::add(std::string name, Target target, std::string unit, std::string help) {
  params_.push_back({std::move(name), std::move(unit), std::move(help), target, {}});
}

ParameterSet::Parameter* ParameterSet::find(const std::string& name) {
  for (auto& p : params_)
    if (p.name == name) return &p;
  return nullptr;
}

void ParameterSet::set(const std::string& name, const std::string& value, const std::string& origin) {
  Parameter* p = find(name);
  if (!p) throw input_error(origin, "unknown parameter '" + name + "' (see the effective parameters printed by fuse)");
  auto bad = [&](const char* what) { return input_error(origin, name + " expects " + what + ", got '" + value + "'"); };
  p->origin = origin;
  std::visit(
      [&](auto* target) {
        using T = std::remove_pointer_t<decltype(target)>;
        if constexpr (std::is_same_v<T, double>) {
          double v;
          if (!parse_number(value, &v) || !std::isfinite(v)) throw bad("a number");
          *target = v;
        } else if constexpr (std::is_same_v<T, int>) {
          int v;
          if (!parse_number(value, &v)) throw bad("an integer");
          *target = v;
        } else if constexpr (std::is_same_v<T, std::size_t>) {
          std::size_t v;
          if (!parse_number(value, &v)) throw bad("a non-negative integer");
          *target = v;
        } else if constexpr (std::is_same_v<T, bool>) {
          if (value == "true" || value == "1" || value == "on") *target = true;
          else if (value == "false" || value == "0" || value == "off") *target = false;
          else throw bad("true or false");
        } else {
          *target = value;
        }
      },
      p->target);
}

void ParameterSet::set_assignment(const std::string& assignment) {
  const auto eq = assignment.find('=');
  if (eq == std::string::npos || eq == 0) throw input_error("--set", "expected key=value, got '" + assignment + "'");
  set(assignment.substr(0, eq), assignment.substr(eq + 1), "--set");
}

std::string ParameterSet::with_origin(const std::string& message) const {
  const Parameter* best = nullptr;
  for (const auto& p : params_)
    if (message.rfind(p.name, 0) == 0 && (!best || p.name.size() > best->name.size())) best = &p;
  if (!best || best->origin.empty()) return message;
  return best->origin + ": " + message;
}

void ParameterSet::load_toml(const std::filesystem::path& path) {
  if (std::ifstream probe(path); !probe) {
    const int error = errno;
    throw input_error(path.string(), std::string("cannot open file: ") + (error ? std::strerror(error) : "unknown reason"));
  }
  toml::table root;
  try {
    root = toml::parse_file(path.string());
  } catch (const toml::parse_error& e) {
    std::ostringstream msg;
    msg << "line " << e.source().begin.line << ": " << e.description();
    throw input_error(path.string(), msg.str());
  }
  std::function<void(const toml::table&, const std::string&)> walk = [&](const toml::table& t, const std::string& prefix) {
    for (auto&& [k, node] : t) {
      const std::string name = prefix.empty() ? std::string(k.str()) : prefix + "." + std::string(k.str());
      if (const auto* sub = node.as_table()) {
        walk(*sub, name);
        continue;
      }
      std::string text;
      if (auto v = node.value<std::string>(); node.is_string()) text = *v;
      else if (node.is_boolean()) text = *node.value<bool>() ? "true" : "false";
      else if (node.is_integer()) text = std::to_string(*node.value<std::int64_t>());
      else if (node.is_floating_point()) {
        std::ostringstream o;
        o.precision(17);
        o << *node.value<double>();
        text = o.str();
      } else throw input_error(path.string(), name + " has an unsupported value type");
      set(name, text, path.string());
    }
  };
  walk(root, "");
}

std::string ParameterSet::value_text(const Parameter& p) const {
  return std::visit(
      [](auto* target) -> std::string {
        using T = std::remove_pointer_t<decltype(target)>;
        if constexpr (std::is_same_v<T, std::string>) return "\"" + *target + "\"";
        else if constexpr (std::is_same_v<T, bool>) return *target ? "true" : "false";
        else if constexpr (std::is_same_v<T, double>) {
          // Shortest text that reads back to the same double (the job journal compares it).
          char buf[64];
          const auto r = std::to_chars(buf, buf + sizeof buf, *target);
          std::string t(buf, r.ptr);
          if (t.find_first_of(".eEn") == std::string::npos) t += ".0";  // TOML: a float, not an integer
          return t;
        } else return std::to_string(*target);
      },
      p.target);
}

std::string ParameterSet::assignments(const std::vector<std::string>& prefixes) const {
  std::ostringstream o;
  for (const auto& p : params_) {
    bool wanted = prefixes.empty();
    for (const auto& prefix : prefixes) wanted = wanted || p.name.rfind(prefix, 0) == 0;
    if (wanted) o << p.name << " = " << value_text(p) << "\n";
  }
  return o.str();
}

std::string ParameterSet::describe() const {
  std::ostringstream o;
  for (const auto& p : params_) {
    o << p.name << " = " << value_text(p);
    o << "  # " << (p.unit.empty() ? "" : "[" + p.unit + "] ") << p.help << "\n";
  }
  return o.str();
}

}  // namespace sf
