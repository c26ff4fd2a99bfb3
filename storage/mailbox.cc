#include "storage/mailbox.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <lz4.h>
#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <stdexcept>

namespace sf {

namespace {
std::runtime_error io_error(const std::filesystem::path& path, const char* what) {
  return std::runtime_error(path.string() + ": " + what + ": " + std::strerror(errno));
}
}  // namespace

Mailbox::Mailbox(std::filesystem::path dir, std::string name) {
  std::filesystem::create_directories(dir);
  path_ = dir / (name + ".box");
  fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) throw io_error(path_, "cannot create scratch file");
}

Mailbox::Mailbox(std::filesystem::path dir, std::string name, std::vector<Blob> committed) {
  path_ = dir / (name + ".box");
  fd_ = ::open(path_.c_str(), O_RDWR | O_CLOEXEC);
  if (fd_ < 0) throw io_error(path_, "cannot open the scratch file of the job's extraction");
  struct stat st;
  if (::fstat(fd_, &st) != 0) throw io_error(path_, "cannot read the scratch file's size");
  end_ = std::uint64_t(st.st_size);
  std::uint64_t next = 0;
  for (const Blob& b : committed) {
    if (b.offset + b.stored > end_) {
      ::close(fd_);
      fd_ = -1;
      throw std::runtime_error(path_.string() + ": scratch file shorter than the job's journal says (" +
                               std::to_string(end_) + " bytes)");
    }
    next = std::max(next, b.seq + 1);
    stored_ += b.stored;
    raw_ += b.raw;
  }
  seq_ = next;
  index_ = std::move(committed);
  fresh_ = index_.size();
}

Mailbox::~Mailbox() {
  if (fd_ >= 0) ::close(fd_);
  if (!keep_) {
    std::error_code ec;
    std::filesystem::remove(path_, ec);
  }
}

void Mailbox::remove_file() {
  keep_ = false;
  std::error_code ec;
  std::filesystem::remove(path_, ec);
}

std::vector<Mailbox::Blob> Mailbox::sync_blobs_from(const std::vector<std::uint64_t>& srcs) const {
  if (::fdatasync(fd_) != 0) throw io_error(path_, "cannot sync scratch data (disk full?)");
  std::lock_guard lock(mutex_);
  std::vector<Blob> out;
  if (sealed_.load()) throw std::logic_error("Mailbox: journal sync after collect");
  for (std::size_t i = fresh_; i < index_.size(); ++i)
    if (std::binary_search(srcs.begin(), srcs.end(), index_[i].src)) out.push_back(index_[i]);
  return out;
}

std::uint64_t Mailbox::raw_bytes(std::uint64_t dest) const {
  seal();
  std::uint64_t total = 0;
  for (auto e = std::lower_bound(index_.begin(), index_.end(), dest,
                                 [](const Entry& x, std::uint64_t d) { return x.dest < d; });
       e != index_.end() && e->dest == dest; ++e)
    total += e->raw;
  return total;
}

void Mailbox::post_bytes(std::uint64_t dest, std::uint64_t src, const void* data, std::size_t bytes) {
  if (sealed_.load()) throw std::logic_error("Mailbox: post after collect");
  if (bytes > std::size_t(LZ4_MAX_INPUT_SIZE)) throw std::length_error("Mailbox: blob of " + std::to_string(bytes) + " bytes");
  std::vector<char> packed(static_cast<std::size_t>(LZ4_compressBound(int(bytes))));
  const int stored = LZ4_compress_default(static_cast<const char*>(data), packed.data(), int(bytes), int(packed.size()));
  if (stored <= 0) throw std::runtime_error("Mailbox: LZ4 compression failed");
  const std::uint64_t seq = seq_++;
  std::lock_guard lock(mutex_);
  const std::uint64_t offset = end_;
  for (std::size_t done = 0; done < std::size_t(stored);) {
    const ssize_t n = ::pwrite(fd_, packed.data() + done, std::size_t(stored) - done, off_t(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw io_error(path_, "cannot write scratch data (disk full?)");
    done += std::size_t(n);
  }
  end_ += std::uint64_t(stored);
  index_.push_back({dest, src, seq, offset, std::uint32_t(stored), std::uint32_t(bytes)});
  stored_ += std::uint64_t(stored);
  raw_ += bytes;
}

void Mailbox::seal() const {
  if (sealed_.load()) return;
  std::lock_guard lock(mutex_);
  if (sealed_.load()) return;
  std::sort(index_.begin(), index_.end(), [](const Entry& a, const Entry& b) {
    return a.dest != b.dest ? a.dest < b.dest : a.src != b.src ? a.src < b.src : a.seq < b.seq;
  });
  sealed_.store(true);
}

std::vector<unsigned char> Mailbox::collect_bytes(std::uint64_t dest) const {
  seal();
  const auto first = std::lower_bound(index_.begin(), index_.end(), dest,
                                      [](const Entry& e, std::uint64_t d) { return e.dest < d; });
  std::size_t total = 0;
  auto last = first;
  for (; last != index_.end() && last->dest == dest; ++last) total += last->raw;
  std::vector<unsigned char> out(total);
  std::vector<char> packed;
  std::size_t at = 0;
  for (auto e = first; e != last; ++e) {
    packed.resize(e->stored);
    for (std::size_t done = 0; done < e->stored;) {
      const ssize_t n = ::pread(fd_, packed.data() + done, e->stored - done, off_t(e->offset + done));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) throw io_error(path_, "cannot read scratch data");
      done += std::size_t(n);
    }
    const int got = LZ4_decompress_safe(packed.data(), reinterpret_cast<char*>(out.data() + at), int(e->stored), int(e->raw));
    if (got != int(e->raw)) throw std::runtime_error(path_.string() + ": damaged scratch data");
    at += e->raw;
  }
  return out;
}

std::vector<std::uint64_t> Mailbox::destinations() const {
  seal();
  std::vector<std::uint64_t> out;
  for (const Entry& e : index_)
    if (out.empty() || out.back() != e.dest) out.push_back(e.dest);
  return out;
}

ScratchFolder::ScratchFolder(const std::string& prefix) {
  std::string pattern = (std::filesystem::temp_directory_path() / (prefix + ".XXXXXX")).string();
  if (!::mkdtemp(pattern.data())) throw io_error(pattern, "cannot create a scratch folder");
  path_ = pattern;
}

ScratchFolder::~ScratchFolder() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

}  // namespace sf
