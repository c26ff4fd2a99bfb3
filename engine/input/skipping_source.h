#pragma once
// --skip-bad: a FrameSource that turns a depth map which fails to read (InputError) into an empty
// frame, so that one broken file among thousands does not stop a job, and remembers what it
// skipped and why. An empty frame contributes nothing; its identity is that of an empty frame, so
// a job notices when the file is later repaired (it was not integrated).
#include <cstddef>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "engine/input/frame_source.h"

namespace sf {

struct SkippedFrame {
  std::size_t index = 0;  // source index
  std::string file;       // the depth map's file
  std::string error;      // the reader's one-line message
};

class SkippingSource final : public FrameSource {
 public:
  explicit SkippingSource(std::unique_ptr<FrameSource> inner) : inner_(std::move(inner)) {}
  std::string format() const override { return inner_->format(); }
  std::size_t size() const override { return inner_->size(); }
  std::string frame_name(std::size_t i) const override { return inner_->frame_name(i); }
  DepthFrame load(std::size_t i) const override;
  // Every depth map skipped so far, in source order (each once, however often it was read).
  std::vector<SkippedFrame> skipped() const;

 private:
  std::unique_ptr<FrameSource> inner_;
  mutable std::mutex mutex_;
  mutable std::map<std::size_t, SkippedFrame> skipped_;
};

// One line "file: error" (the reader's message, which names the file it found bad).
std::string describe_skipped(const SkippedFrame& skipped);
// The list as text, one line per depth map (what a job writes to DIR/skipped.txt).
std::string describe_skipped(const std::vector<SkippedFrame>& skipped);

}  // namespace sf
