#include "storage/mailbox.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <lz4.h>
#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "engine/error.h"

namespace sf {

namespace {
// A failed scratch file operation: the disk (full, failing) is ResourceError, the rest internal.
// (A scratch file damaged on disk is the job folder's fault: InputError, exit 2, naming it.)
[[noreturn]] void fail_io(const std::filesystem::path& path, const char* what) {
  const int err = errno;
  const std::string message = path.string() + ": " + what + ": " + std::strerror(err);
  if (is_resource_errno(err)) throw ResourceError(message);
  throw std::runtime_error(message);
}
}  // namespace

Mailbox::Mailbox(std::filesystem::path dir, std::string name) {
  std::filesystem::create_directories(dir);
  File& f = parts_.emplace_back();
  f.path = dir / (name + ".box");
  f.fd = ::open(f.path.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (f.fd < 0) fail_io(f.path, "cannot create scratch file");
}

Mailbox::Mailbox(std::filesystem::path dir, std::string name, std::vector<Blob> committed) {
  File& f = parts_.emplace_back();
  f.path = dir / (name + ".box");
  f.fd = ::open(f.path.c_str(), O_RDWR | O_CLOEXEC);
  if (f.fd < 0) fail_io(f.path, "cannot open the scratch file of the job's extraction");
  struct stat st;
  if (::fstat(f.fd, &st) != 0) fail_io(f.path, "cannot read the scratch file's size");
  end_ = std::uint64_t(st.st_size);
  std::uint64_t next = 0;
  for (const Blob& b : committed) {
    if (b.offset + b.stored > end_) {
      ::close(f.fd);
      f.fd = -1;
      throw InputError(f.path.string() + ": scratch file shorter than the job's journal says (" +
                       std::to_string(end_) + " bytes)");
    }
    next = std::max(next, b.seq + 1);
    stored_ += b.stored;
    raw_ += b.raw;
    Entry e;
    static_cast<Blob&>(e) = b;
    index_.push_back(e);
  }
  seq_ = next;
  fresh_ = index_.size();
}

Mailbox::Mailbox(std::vector<Part> parts) : union_(true), keep_(true) {
  for (std::uint32_t p = 0; p < parts.size(); ++p) {
    File& f = parts_.emplace_back();
    f.path = std::move(parts[p].file);
    for (const Blob& b : parts[p].blobs) {
      f.needed = std::max(f.needed, b.offset + b.stored);
      stored_ += b.stored;
      raw_ += b.raw;
      Entry e;
      static_cast<Blob&>(e) = b;
      e.part = p;
      index_.push_back(e);
    }
  }
  if (parts_.empty()) parts_.emplace_back();  // path() names nothing
}

Mailbox::~Mailbox() {
  for (const File& f : parts_)
    if (f.fd >= 0) ::close(f.fd);
  if (!keep_) {
    std::error_code ec;
    std::filesystem::remove(parts_[0].path, ec);
  }
}

void Mailbox::remove_file() {
  if (union_) return;  // the parts are other processes' files
  keep_ = false;
  std::error_code ec;
  std::filesystem::remove(parts_[0].path, ec);
}

int Mailbox::fd_of(std::uint32_t part) const {
  if (!union_) return parts_[0].fd;
  std::lock_guard lock(open_mutex_);
  File& f = parts_[part];
  if (f.fd >= 0) return f.fd;
  const int fd = ::open(f.path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) fail_io(f.path, "cannot open another tile's exchange file");
  struct stat st;
  if (::fstat(fd, &st) != 0 || std::uint64_t(st.st_size) < f.needed) {
    ::close(fd);
    throw InputError(f.path.string() + ": shorter than its tile's manifest says (" + std::to_string(f.needed) +
                     " bytes)");
  }
  f.fd = fd;
  return fd;
}

std::vector<Mailbox::Blob> Mailbox::sync_blobs_from(const std::vector<std::uint64_t>& srcs) const {
  if (union_) throw std::logic_error("Mailbox: sync of a read-only union");
  if (::fdatasync(parts_[0].fd) != 0) fail_io(parts_[0].path, "cannot sync scratch data (disk full?)");
  std::lock_guard lock(mutex_);
  std::vector<Blob> out;
  if (sealed_.load()) throw std::logic_error("Mailbox: journal sync after collect");
  for (std::size_t i = fresh_; i < index_.size(); ++i)
    if (std::binary_search(srcs.begin(), srcs.end(), index_[i].src)) out.push_back(index_[i]);
  return out;
}

void Mailbox::sync() const {
  if (union_) return;
  if (::fdatasync(parts_[0].fd) != 0) fail_io(parts_[0].path, "cannot sync scratch data (disk full?)");
}

std::vector<Mailbox::Blob> Mailbox::blobs() const {
  std::lock_guard lock(mutex_);
  return std::vector<Blob>(index_.begin(), index_.end());
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
  if (union_) throw std::logic_error("Mailbox: post to a read-only union (" + parts_[0].path.string() + ")");
  if (sealed_.load()) throw std::logic_error("Mailbox: post after collect");
  if (bytes > std::size_t(LZ4_MAX_INPUT_SIZE)) throw std::length_error("Mailbox: blob of " + std::to_string(bytes) + " bytes");
  std::vector<char> packed(static_cast<std::size_t>(LZ4_compressBound(int(bytes))));
  const int stored = LZ4_compress_default(static_cast<const char*>(data), packed.data(), int(bytes), int(packed.size()));
  if (stored <= 0) throw std::runtime_error("Mailbox: LZ4 compression failed");
  const std::uint64_t seq = seq_++;
  std::lock_guard lock(mutex_);
  const std::uint64_t offset = end_;
  for (std::size_t done = 0; done < std::size_t(stored);) {
    const ssize_t n = ::pwrite(parts_[0].fd, packed.data() + done, std::size_t(stored) - done, off_t(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) fail_io(parts_[0].path, "cannot write scratch data (disk full?)");
    done += std::size_t(n);
  }
  end_ += std::uint64_t(stored);
  Entry e;
  static_cast<Blob&>(e) = {dest, src, seq, offset, std::uint32_t(stored), std::uint32_t(bytes)};
  index_.push_back(e);
  stored_ += std::uint64_t(stored);
  raw_ += bytes;
}

void Mailbox::seal() const {
  if (sealed_.load()) return;
  std::lock_guard lock(mutex_);
  if (sealed_.load()) return;
  std::sort(index_.begin(), index_.end(), [](const Entry& a, const Entry& b) {
    return a.dest != b.dest ? a.dest < b.dest : a.src != b.src ? a.src < b.src : a.part != b.part ? a.part < b.part : a.seq < b.seq;
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
    const int fd = fd_of(e->part);
    const std::filesystem::path& path = parts_[e->part].path;
    for (std::size_t done = 0; done < e->stored;) {
      const ssize_t n = ::pread(fd, packed.data() + done, e->stored - done, off_t(e->offset + done));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) fail_io(path, "cannot read scratch data");
      done += std::size_t(n);
    }
    const int got = LZ4_decompress_safe(packed.data(), reinterpret_cast<char*>(out.data() + at), int(e->stored), int(e->raw));
    if (got != int(e->raw)) throw InputError(path.string() + ": damaged scratch data");
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

void write_blob_manifest(const std::filesystem::path& file, const std::vector<BlobRecord>& records) {
  std::ostringstream text;
  text << "scalefuse-blobs 1 " << records.size() << "\n";
  for (const BlobRecord& r : records) {
    if (r.box.empty() || r.box.find_first_of(" \n") != std::string::npos)
      throw std::logic_error("blob manifest: bad box name '" + r.box + "'");
    const Mailbox::Blob& b = r.blob;
    text << r.box << ' ' << b.dest << ' ' << b.src << ' ' << b.seq << ' ' << b.offset << ' ' << b.stored << ' ' << b.raw
         << '\n';
  }
  text << "end\n";
  const std::string data = text.str();
  const std::filesystem::path tmp = file.string() + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) fail_io(tmp, "cannot create");
  for (std::size_t done = 0; done < data.size();) {
    const ssize_t n = ::write(fd, data.data() + done, data.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      ::close(fd);
      fail_io(tmp, "cannot write (disk full?)");
    }
    done += std::size_t(n);
  }
  if (::fsync(fd) != 0) {
    ::close(fd);
    fail_io(tmp, "cannot sync (disk full?)");
  }
  ::close(fd);
  std::filesystem::rename(tmp, file);
  const int dir = ::open(file.parent_path().empty() ? "." : file.parent_path().c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir >= 0) {
    ::fsync(dir);
    ::close(dir);
  }
}

std::vector<BlobRecord> read_blob_manifest(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) throw InputError(file.string() + ": cannot read (missing?)");
  const auto bad = [&](const std::string& what) { return InputError(file.string() + ": " + what); };
  std::string magic;
  int version = 0;
  std::uint64_t count = 0;
  if (!(in >> magic >> version >> count) || magic != "scalefuse-blobs" || version != 1)
    throw bad("not a scalefuse blob manifest (version 1)");
  std::vector<BlobRecord> out;
  out.reserve(std::size_t(std::min<std::uint64_t>(count, 1u << 20)));
  for (std::uint64_t i = 0; i < count; ++i) {
    BlobRecord r;
    Mailbox::Blob& b = r.blob;
    if (!(in >> r.box >> b.dest >> b.src >> b.seq >> b.offset >> b.stored >> b.raw))
      throw bad("truncated or malformed at blob " + std::to_string(i + 1) + " of " + std::to_string(count));
    out.push_back(std::move(r));
  }
  std::string end;
  if (!(in >> end) || end != "end") throw bad("truncated (no end line)");
  return out;
}

ScratchFolder::ScratchFolder(const std::string& prefix) {
  std::string pattern = (std::filesystem::temp_directory_path() / (prefix + ".XXXXXX")).string();
  if (!::mkdtemp(pattern.data())) fail_io(pattern, "cannot create a scratch folder");
  path_ = pattern;
}

ScratchFolder::~ScratchFolder() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

}  // namespace sf
