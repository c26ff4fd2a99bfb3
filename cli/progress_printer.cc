#include "cli/progress_printer.h"

#include <unistd.h>

#include <cstdio>

namespace sf::cli {

ProgressPrinter::ProgressPrinter(bool quiet) : quiet_(quiet), tty_(::isatty(STDERR_FILENO) == 1) {}

void ProgressPrinter::operator()(std::string_view stage, double done, double total) {
  if (quiet_) return;
  std::lock_guard lock(mutex_);
  const double f = total > 0 ? std::min(1.0, done / total) : 1.0;
  const bool new_stage = stage != stage_;
  if (new_stage) {
    if (bar_open_) std::fputc('\n', stderr);
    bar_open_ = false;
    stage_ = std::string(stage);
    last_decile_ = -1;
  }
  if (tty_) {
    const auto now = std::chrono::steady_clock::now();
    if (!new_stage && f < 1.0 && now - last_draw_ < std::chrono::milliseconds(100)) return;
    last_draw_ = now;
    const int width = 30, filled = int(f * width);
    std::fprintf(stderr, "\r%-15s [%.*s%*s] %5.1f%% (%.0f/%.0f)", stage_.c_str(), filled,
                 "##############################", width - filled, "", 100 * f, done, total);
    bar_open_ = true;
  } else {
    const int decile = int(f * 10);
    if (decile == last_decile_) return;
    last_decile_ = decile;
    std::fprintf(stderr, "%s: %3d%% (%.0f/%.0f)\n", stage_.c_str(), decile * 10, done, total);
  }
  std::fflush(stderr);
}

void ProgressPrinter::finish() {
  std::lock_guard lock(mutex_);
  if (bar_open_) std::fputc('\n', stderr);
  bar_open_ = false;
}

}  // namespace sf::cli
