#pragma once
// Stage progress on stderr: a redrawn bar on a terminal, plain lines (every 10%) otherwise.
#include <chrono>
#include <mutex>
#include <string>
#include <string_view>

namespace sf::cli {

class ProgressPrinter {
 public:
  explicit ProgressPrinter(bool quiet);
  void operator()(std::string_view stage, double done, double total);
  void finish();  // ends a bar line

 private:
  std::mutex mutex_;
  bool quiet_, tty_;
  std::string stage_;
  int last_decile_ = -1;
  std::chrono::steady_clock::time_point last_draw_{};
  bool bar_open_ = false;
};

}  // namespace sf::cli
