#pragma once
// Scratch messages between the passes of a brick-by-brick stage: during one pass any brick may
// post records to any other; in the next, each brick collects what was posted to it. Blobs are
// LZ4-compressed (by the posting thread) and appended to one file, so memory holds only a small
// index entry per blob, and each record is written once and read once.
//
// Not a durable format: the files live for one run of a stage, under the job's scratch folder,
// and are deleted with the mailbox.
#include <atomic>
#include <cstring>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <type_traits>
#include <vector>

namespace sf {

class Mailbox {
 public:
  // The file is `dir`/`name`.box (dir is created).
  Mailbox(std::filesystem::path dir, std::string name);
  ~Mailbox();  // deletes the files
  Mailbox(const Mailbox&) = delete;
  Mailbox& operator=(const Mailbox&) = delete;

  // Thread-safe. Blobs to one destination are collected in (src, order of posting) order.
  void post_bytes(std::uint64_t dest, std::uint64_t src, const void* data, std::size_t bytes);
  template <typename T>
  void post(std::uint64_t dest, std::uint64_t src, const std::vector<T>& records) {
    static_assert(std::is_trivially_copyable_v<T>);
    if (!records.empty()) post_bytes(dest, src, records.data(), records.size() * sizeof(T));
  }

  // Everything posted to `dest`, concatenated. Call after the posting pass (safe concurrently
  // with other collects, not with posts).
  std::vector<unsigned char> collect_bytes(std::uint64_t dest) const;
  template <typename T>
  std::vector<T> collect(std::uint64_t dest) const {
    static_assert(std::is_trivially_copyable_v<T>);
    const std::vector<unsigned char> raw = collect_bytes(dest);
    std::vector<T> out(raw.size() / sizeof(T));
    if (!out.empty()) std::memcpy(static_cast<void*>(out.data()), raw.data(), out.size() * sizeof(T));
    return out;
  }
  // Destinations that received anything, ascending.
  std::vector<std::uint64_t> destinations() const;

  std::uint64_t bytes_stored() const { return stored_.load(); }  // compressed, on disk
  std::uint64_t bytes_raw() const { return raw_.load(); }

 private:
  struct Entry {
    std::uint64_t dest, src, seq, offset;
    std::uint32_t stored, raw;
  };
  void seal() const;  // sorts the index (first collect after posting)

  std::filesystem::path path_;
  int fd_ = -1;
  std::uint64_t end_ = 0;  // file size (guarded by mutex_)
  std::atomic<std::uint64_t> seq_{0}, stored_{0}, raw_{0};
  mutable std::mutex mutex_;
  mutable std::vector<Entry> index_;  // guarded by mutex_ until sealed
  mutable std::atomic<bool> sealed_{false};
};

// A new folder under the system's temporary directory ($TMPDIR), removed with its contents.
class ScratchFolder {
 public:
  explicit ScratchFolder(const std::string& prefix);
  ~ScratchFolder();
  ScratchFolder(const ScratchFolder&) = delete;
  ScratchFolder& operator=(const ScratchFolder&) = delete;
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

}  // namespace sf
