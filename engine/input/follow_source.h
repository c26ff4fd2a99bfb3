#pragma once
// fuse --follow: an input folder that a multi-view stereo program is still writing into. The
// source grows while the fusion runs; a depth map joins it once it is complete.
#include <atomic>
#include <chrono>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "engine/input/frame_source.h"

namespace sf {

struct FollowOptions {
  // A depth map is complete when its size and modification time have not changed for this long
  // and its reader parses it (a half-written file fails to parse, or is still changing).
  double settle_seconds = 2.0;
  double poll_seconds = 1.0;
  // The feed ends when this file exists (empty: only `stop` ends it).
  std::filesystem::path stop_file;
  // Set by a signal handler: the feed ends at the next poll.
  const std::atomic<bool>* stop = nullptr;
  // Resume of a followed job without --follow: take every depth map that parses now, then end.
  bool until_idle = false;
  // Called with one line when something is worth telling (a waiting reason, a stable file that
  // does not parse); may be empty.
  std::function<void(const std::string&)> notice;
};

// Depth maps in the order they became complete. Depth maps a job already recorded (`recorded`,
// by file name) come first, in the job's order, so a resumed job sees the same sequence.
class FollowSource : public FrameSource, public FrameFeed {
 public:
  FollowSource(std::filesystem::path input, InputOptions input_options, FollowOptions options,
               std::vector<std::string> recorded);

  std::string format() const override;
  std::size_t size() const override;
  std::string frame_name(std::size_t i) const override;
  DepthFrame load(std::size_t i) const override;

  bool wait_for_more(std::size_t known) override;

  // One look at the folder: adds the depth maps that became complete; returns how many.
  // Throws InputError if a depth map already taken has disappeared.
  std::size_t rescan();

 private:
  struct Observed {
    std::uint64_t size = 0;
    std::filesystem::file_time_type mtime{};
    std::chrono::steady_clock::time_point since{};
    bool warned = false;
  };
  bool ended() const;

  const std::filesystem::path input_;
  const InputOptions input_options_;
  const FollowOptions options_;
  std::vector<std::string> recorded_;  // consumed by the first scan that sees them all
  mutable std::mutex mutex_;           // guards the members below (load() runs on pipeline threads)
  std::shared_ptr<const FrameSource> snapshot_;  // the folder as last opened
  std::string format_;
  std::vector<std::string> names_;            // accepted depth maps, in order
  std::vector<std::size_t> snapshot_index_;   // names_[i] is snapshot_->frame_name(snapshot_index_[i])
  std::map<std::string, Observed> pending_;   // seen, not yet complete
  std::string last_wait_reason_;
};

}  // namespace sf
