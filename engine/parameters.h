#pragma once
// Named parameters: every tunable of every stage is registered once with its dotted name
// ("integrate.gamma"), unit and meaning, so that configs (TOML), --set key=value and the printed
// effective configuration all use the same names.
#include <filesystem>
#include <functional>
#include <string>
#include <variant>
#include <vector>

namespace sf {

// Parses exactly `count` comma-separated numbers ("1,2.5,-3"); throws InputError naming `what`
// (an option or parameter name) otherwise.
std::vector<double> parse_number_list(const std::string& text, std::size_t count, const std::string& what);

class ParameterSet {
 public:
  using Target = std::variant<double*, int*, bool*, std::string*, std::size_t*>;
  struct Parameter {
    std::string name, unit, help;
    Target target;
    std::string origin;  // where its value was last set (a config file, "--set", ...); empty: default
  };

  void add(std::string name, Target target, std::string unit, std::string help);

  // Sets one parameter from text; throws InputError naming `origin` on an unknown name or a bad value.
  void set(const std::string& name, const std::string& value, const std::string& origin = "--set");
  // "key=value".
  void set_assignment(const std::string& assignment);
  // Loads a TOML file: tables give the prefix ([integrate] gamma = 8 -> integrate.gamma).
  void load_toml(const std::filesystem::path& path);

  std::string value_text(const Parameter& p) const;
  // A check's message ("integrate.lambda must be > 0, got -1") prefixed with where the parameter
  // it starts with was set, so the user learns which file to fix; unchanged if none was.
  std::string with_origin(const std::string& message) const;
  const std::vector<Parameter>& parameters() const { return params_; }
  // "name = value  # unit: help" lines, in registration order.
  std::string describe() const;
  // "name = value" lines (valid TOML with dotted keys) of the parameters whose names start with
  // one of `prefixes` (all if empty), in registration order.
  std::string assignments(const std::vector<std::string>& prefixes = {}) const;

 private:
  Parameter* find(const std::string& name);
  std::vector<Parameter> params_;
};

}  // namespace sf
