#pragma once
// Errors cross module boundaries as exceptions; only cli/ turns them into exit codes.
//   InputError    -> exit 2: the user's data or options are wrong (names the file and the problem).
//   anything else -> exit 1: an internal error.
#include <stdexcept>
#include <string>

namespace sf {

class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// "path: what is wrong" — the one-line form every reader uses.
inline InputError input_error(const std::string& path, const std::string& what) {
  return InputError(path + ": " + what);
}

}  // namespace sf
