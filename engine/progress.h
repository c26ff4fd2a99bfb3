#pragma once
// Progress and cancellation are passed in, never printed by the engine (cli/ prints).
#include <functional>
#include <string_view>

namespace sf {

// stage: a short stage name ("integrate", "tetrahedralize", ...); done/total: work units.
using ProgressFn = std::function<void(std::string_view stage, double done, double total)>;

inline void report(const ProgressFn& fn, std::string_view stage, double done, double total) {
  if (fn) fn(stage, done, total);
}

}  // namespace sf
