#include "engine/input/follow_source.h"

#include <thread>
#include <unordered_map>
#include <unordered_set>

#include "engine/error.h"

namespace sf {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

FollowSource::FollowSource(fs::path input, InputOptions input_options, FollowOptions options,
                           std::vector<std::string> recorded)
    : input_(std::move(input)), input_options_(std::move(input_options)), options_(std::move(options)),
      recorded_(std::move(recorded)) {
  std::error_code ec;
  if (!fs::is_directory(input_, ec)) throw input_error(input_.string(), "input folder does not exist");
  input_options_.check();
}

std::string FollowSource::format() const {
  std::lock_guard lock(mutex_);
  return format_.empty() ? input_options_.format : format_;
}

std::size_t FollowSource::size() const {
  std::lock_guard lock(mutex_);
  return names_.size();
}

std::string FollowSource::frame_name(std::size_t i) const {
  std::lock_guard lock(mutex_);
  return names_.at(i);
}

DepthFrame FollowSource::load(std::size_t i) const {
  std::shared_ptr<const FrameSource> snapshot;
  std::size_t index = 0;
  {
    std::lock_guard lock(mutex_);
    snapshot = snapshot_;
    index = snapshot_index_.at(i);
  }
  return snapshot->load(index);
}

bool FollowSource::ended() const {
  if (options_.stop && options_.stop->load()) return true;
  std::error_code ec;
  return !options_.stop_file.empty() && fs::exists(options_.stop_file, ec);
}

std::size_t FollowSource::rescan() {
  std::shared_ptr<const FrameSource> snapshot;
  try {
    snapshot = open_input(input_, input_options_);
  } catch (const InputError& e) {
    // A folder the stereo program has not written a depth map into yet (or is rewriting its model)
    // is normal while following: say why we wait, once per reason.
    if (options_.notice && last_wait_reason_ != e.what()) options_.notice(std::string("waiting: ") + e.what());
    last_wait_reason_ = e.what();
    return 0;
  }
  last_wait_reason_.clear();
  std::unordered_map<std::string, std::size_t> index_of;
  // Names are absolute, as the job records them.
  std::vector<std::string> snapshot_names(snapshot->size());
  for (std::size_t i = 0; i < snapshot->size(); ++i) {
    snapshot_names[i] = fs::absolute(snapshot->frame_name(i)).string();
    index_of.emplace(snapshot_names[i], i);
  }

  std::vector<std::string> names;
  std::vector<std::size_t> indices;
  {
    std::lock_guard lock(mutex_);
    names = names_;
  }
  for (const std::string& n : names) {
    const auto it = index_of.find(n);
    if (it == index_of.end()) throw input_error(n, "depth map disappeared from the input while it was being followed");
    indices.push_back(it->second);
  }
  std::unordered_set<std::string> taken(names.begin(), names.end());
  const std::size_t before = names.size();
  auto accept = [&](const std::string& n, std::size_t i) {
    names.push_back(n);
    indices.push_back(i);
    taken.insert(n);
    pending_.erase(n);
  };
  // The job's own depth maps first, in its order.
  for (std::size_t r = 0; r < recorded_.size(); ++r) {
    if (taken.count(recorded_[r])) continue;
    const auto it = index_of.find(recorded_[r]);
    if (it == index_of.end())
      throw input_error(recorded_[r], "the job integrated this depth map, but it is no longer in the input");
    accept(recorded_[r], it->second);
  }
  recorded_.clear();
  const bool take_now = options_.until_idle || ended();
  const auto now = Clock::now();
  for (std::size_t i = 0; i < snapshot->size(); ++i) {
    const std::string& n = snapshot_names[i];
    if (taken.count(n)) continue;
    std::error_code ec;
    const auto size = fs::file_size(n, ec);
    const auto mtime = fs::last_write_time(n, ec);
    if (ec) continue;  // vanished between listing and stat: look again next time
    auto [it, fresh] = pending_.try_emplace(n);
    Observed& o = it->second;
    if (fresh || o.size != size || o.mtime != mtime) {
      o = Observed{std::uint64_t(size), mtime, now, false};
      if (!take_now) continue;
    }
    if (!take_now && std::chrono::duration<double>(now - o.since).count() < options_.settle_seconds) continue;
    try {
      (void)snapshot->load(i);
    } catch (const InputError& e) {
      if (options_.notice && !o.warned) options_.notice(std::string("not taken yet (incomplete or damaged): ") + e.what());
      o.warned = true;
      continue;
    }
    accept(n, i);
  }
  std::lock_guard lock(mutex_);
  snapshot_ = std::move(snapshot);
  format_ = snapshot_->format();
  names_ = std::move(names);
  snapshot_index_ = std::move(indices);
  return names_.size() - before;
}

bool FollowSource::wait_for_more(std::size_t known) {
  for (;;) {
    const bool last = ended() || options_.until_idle;  // this scan takes what parses, then the feed ends
    rescan();
    if (size() > known) return true;
    if (last) return false;
    std::this_thread::sleep_for(std::chrono::duration<double>(options_.poll_seconds));
  }
}

}  // namespace sf
