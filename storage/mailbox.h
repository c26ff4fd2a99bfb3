#pragma once
// Scratch messages between the passes of a brick-by-brick stage: during one pass any brick may
// post records to any other; in the next, each brick collects what was posted to it. Blobs are
// LZ4-compressed (by the posting thread) and appended to one file, so memory holds only a small
// index entry per blob, and each record is written once and read once.
//
// The file alone is not durable: the index lives in memory. A job's brick extraction
// (engine/extract/brick_extract.h) syncs the file and commits the index entries (blobs) of
// finished bricks to the job's journal; a resumed run reopens the file with the committed blobs
// (blobs written after the last commit stay in the file, unread, and new ones go after them).
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
  // Where a blob is: posted to `dest` by `src`, the seq-th post, `stored` bytes at `offset`.
  struct Blob {
    std::uint64_t dest, src, seq, offset;
    std::uint32_t stored, raw;
  };

  // A new, empty mailbox: the file is `dir`/`name`.box (dir is created, the file truncated).
  Mailbox(std::filesystem::path dir, std::string name);
  // The mailbox a previous run left, holding the blobs `committed` (a journal's record of it).
  // Throws if the file is missing or shorter than they say.
  Mailbox(std::filesystem::path dir, std::string name, std::vector<Blob> committed);
  // One file of a read-only union of mailboxes (a cluster's tiles each post to their own file;
  // storage/blob_manifest below).
  struct Part {
    std::filesystem::path file;
    std::vector<Blob> blobs;
  };
  // The union of several processes' files, read-only: blobs to one destination are collected in
  // (src, order of posting) order, as from one file, provided every src posted to one file only.
  // The files are opened on the first collect (a file is missing or short: that collect throws),
  // so a union may name files whose readers are done and which are gone.
  explicit Mailbox(std::vector<Part> parts);
  ~Mailbox();  // deletes the file unless keep_file() was called
  // The file outlives this object (a journal refers to it); remove_file() deletes it.
  void keep_file() { keep_ = true; }
  void remove_file();
  const std::filesystem::path& path() const { return parts_[0].path; }
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
  // Uncompressed bytes posted to `dest` (after the posting pass).
  std::uint64_t raw_bytes(std::uint64_t dest) const;

  // For a journal: flushes the file to disk (fdatasync), then lists the blobs posted by `srcs`
  // (ascending) since this object was made.
  std::vector<Blob> sync_blobs_from(const std::vector<std::uint64_t>& srcs) const;

  // Flushes the file to disk (fdatasync).
  void sync() const;
  // Every blob (committed when reopened, and posted since), before any collect.
  std::vector<Blob> blobs() const;

  std::uint64_t bytes_stored() const { return stored_.load(); }  // compressed, on disk
  std::uint64_t bytes_raw() const { return raw_.load(); }

 private:
  struct Entry : Blob {
    std::uint32_t part = 0;  // which file
  };
  struct File {
    std::filesystem::path path;
    int fd = -1;
    std::uint64_t needed = 0;  // bytes the blobs need (a union's part, checked when opened)
  };
  void seal() const;  // sorts the index (first collect after posting)
  int fd_of(std::uint32_t part) const;  // opens a union's part on first use

  mutable std::vector<File> parts_;  // [0]: the file this mailbox posts to (unless a union)
  bool union_ = false;
  mutable std::mutex open_mutex_;
  bool keep_ = false;
  std::size_t fresh_ = 0;  // index_[fresh_...] were posted by this object (until sealed)
  std::uint64_t end_ = 0;  // file size (guarded by mutex_)
  std::atomic<std::uint64_t> seq_{0}, stored_{0}, raw_{0};
  mutable std::mutex mutex_;
  mutable std::vector<Entry> index_;  // guarded by mutex_ until sealed
  mutable std::atomic<bool> sealed_{false};
};

// A blob manifest: the blobs of some mailboxes one process committed, as a file that other
// processes read (a cluster tile's record of a pass, engine/extract/brick_extract.h). Text, one
// blob per line, written to a temporary name, synced and renamed.
struct BlobRecord {
  std::string box;
  Mailbox::Blob blob;
};
void write_blob_manifest(const std::filesystem::path& file, const std::vector<BlobRecord>& records);
// Throws InputError naming the file if it is missing or malformed.
std::vector<BlobRecord> read_blob_manifest(const std::filesystem::path& file);

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
