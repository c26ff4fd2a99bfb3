#pragma once
// Writing a file so that readers never see it half-written: the bytes go to a sibling
// "<path>.tmp-<pid>-<n>", which is flushed, fsync'ed and renamed onto <path> by commit().
// A file that is destroyed without commit() removes its temporary.
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string_view>

namespace sf {

class AtomicFile {
 public:
  // Opens the temporary sibling. Throws InputError naming `path` if it cannot be created (the
  // output folder is missing or not writable: the user's option is wrong).
  explicit AtomicFile(std::filesystem::path path);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  void write(const void* data, std::size_t bytes);  // throws InputError naming the file
  void write(std::string_view text) { write(text.data(), text.size()); }
  // Flushes, fsyncs and renames into place. Throws InputError naming the file on failure.
  void commit();

  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_, tmp_;
  std::FILE* file_ = nullptr;
};

// The whole content at once.
void write_file_atomic(const std::filesystem::path& path, std::string_view bytes);

}  // namespace sf
