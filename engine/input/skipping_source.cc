#include "engine/input/skipping_source.h"

#include "engine/error.h"

namespace sf {

DepthFrame SkippingSource::load(std::size_t i) const {
  try {
    return inner_->load(i);
  } catch (const InputError& e) {
    // Only bad data is skipped; an internal error (bad_alloc, a bug) still stops the job.
    const std::string file = inner_->frame_name(i);
    {
      std::lock_guard lock(mutex_);
      skipped_.try_emplace(i, SkippedFrame{i, file, e.what()});
    }
    DepthFrame empty;
    empty.name = file;
    return empty;
  }
}

std::vector<SkippedFrame> SkippingSource::skipped() const {
  std::lock_guard lock(mutex_);
  std::vector<SkippedFrame> out;
  out.reserve(skipped_.size());
  for (const auto& [i, s] : skipped_) out.push_back(s);
  return out;
}

std::string describe_skipped(const SkippedFrame& s) {
  // The reader's message starts with the file it found bad: the depth map itself, or a file
  // beside it (its pose, its meta.ini), which then needs the depth map's name too.
  if (s.error.rfind(s.file, 0) == 0) return s.error;
  return s.file + ": " + s.error;
}

std::string describe_skipped(const std::vector<SkippedFrame>& skipped) {
  std::string text;
  for (const SkippedFrame& s : skipped) text += describe_skipped(s) + "\n";
  return text;
}

}  // namespace sf
