#include "scheduler/job.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sqlite3.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <limits>
#include <set>
#include <sstream>

#include <tbb/parallel_for.h>

#include "engine/error.h"
#include "engine/input/file_util.h"
#include "engine/parameters.h"

namespace sf {
namespace {

// Puts another job's tile into this job's store: a hard link where the file system allows, else
// a copy (tiles are never modified in place, so sharing the inode is safe).
void link_tile(const std::filesystem::path& from, const std::filesystem::path& to) {
  std::error_code ec;
  std::filesystem::remove(to, ec);
  std::filesystem::create_hard_link(from, to, ec);
  if (ec) std::filesystem::copy_file(from, to, std::filesystem::copy_options::overwrite_existing);
}

// A journal failure: a full or failing disk is the machine's (ResourceError, exit 3), anything
// else (a damaged or foreign database) bad input naming the journal.
[[noreturn]] void throw_journal_error(sqlite3* db, const std::string& where, const std::string& detail = "") {
  const int code = db ? (sqlite3_errcode(db) & 0xff) : SQLITE_ERROR;
  const std::string message = where + ": job journal error: " + (detail.empty() && db ? sqlite3_errmsg(db) : detail);
  if (code == SQLITE_FULL || code == SQLITE_IOERR) throw ResourceError(message);
  throw InputError(message);
}

constexpr int kJobVersion = 1;

// Thin RAII over the SQLite C API: every failure becomes an exception naming the journal.
class Statement {
 public:
  Statement(sqlite3* db, const std::string& sql, const std::string& where) : db_(db), where_(where) {
    if (sqlite3_prepare_v2(db, sql.c_str(), -1, &stmt_, nullptr) != SQLITE_OK) fail();
  }
  ~Statement() { sqlite3_finalize(stmt_); }
  Statement& bind(int i, std::int64_t v) {
    if (sqlite3_bind_int64(stmt_, i, v) != SQLITE_OK) fail();
    return *this;
  }
  Statement& bind(int i, const std::string& v) {
    if (sqlite3_bind_text(stmt_, i, v.c_str(), int(v.size()), SQLITE_TRANSIENT) != SQLITE_OK) fail();
    return *this;
  }
  bool step() {  // true while a row is available
    const int rc = sqlite3_step(stmt_);
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    fail();
    return false;
  }
  void run() {
    while (step()) {
    }
    sqlite3_reset(stmt_);
  }
  std::int64_t integer(int col) const { return sqlite3_column_int64(stmt_, col); }
  std::string text(int col) const {
    const unsigned char* t = sqlite3_column_text(stmt_, col);
    return t ? std::string(reinterpret_cast<const char*>(t)) : std::string();
  }

 private:
  [[noreturn]] void fail() const { throw_journal_error(db_, where_); }
  sqlite3* db_;
  sqlite3_stmt* stmt_ = nullptr;
  std::string where_;
};

void exec(sqlite3* db, const std::string& sql, const std::string& where) {
  char* err = nullptr;
  if (sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &err) != SQLITE_OK) {
    const std::string msg = err ? err : "unknown";
    sqlite3_free(err);
    throw_journal_error(db, where, msg);
  }
}

// A write transaction that rolls back unless committed, so a failure midway leaves the journal
// as it was.
class Transaction {
 public:
  Transaction(sqlite3* db, const std::string& where) : db_(db), where_(where) { exec(db, "BEGIN IMMEDIATE", where); }
  ~Transaction() {
    if (!committed_) sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
  }
  void commit() {
    exec(db_, "COMMIT", where_);
    committed_ = true;
  }

 private:
  sqlite3* db_;
  std::string where_;
  bool committed_ = false;
};

sqlite3* open_db(const std::filesystem::path& file, bool create) {
  sqlite3* db = nullptr;
  const int flags = SQLITE_OPEN_READWRITE | (create ? SQLITE_OPEN_CREATE : 0) | SQLITE_OPEN_FULLMUTEX;
  if (sqlite3_open_v2(file.c_str(), &db, flags, nullptr) != SQLITE_OK) {
    const std::string msg = db ? sqlite3_errmsg(db) : "out of memory";
    sqlite3_close(db);
    throw InputError(file.string() + ": cannot open the job journal: " + msg);
  }
  sqlite3_busy_timeout(db, 5000);
  return db;
}

std::string meta(sqlite3* db, const std::string& key, const std::string& where) {
  Statement s(db, "SELECT value FROM meta WHERE key = ?1", where);
  s.bind(1, key);
  return s.step() ? s.text(0) : std::string();
}

void set_meta(sqlite3* db, const std::string& key, const std::string& value, const std::string& where) {
  Statement(db, "INSERT OR REPLACE INTO meta(key, value) VALUES(?1, ?2)", where).bind(1, key).bind(2, value).run();
}

std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

std::string root_text(const RootCube& r) {
  std::ostringstream o;
  o.precision(17);
  o << r.min.x() << "," << r.min.y() << "," << r.min.z() << "," << r.size;
  return o.str();
}

std::string hex16(std::uint64_t v) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

// A sweep's plan as text: "x0 y0 z0 x1 y1 z1" per tile, tiles separated by ';'.
std::string tiles_text(const std::vector<BrickBox>& tiles) {
  std::ostringstream o;
  for (std::size_t i = 0; i < tiles.size(); ++i) {
    const BrickBox& t = tiles[i];
    o << (i ? ";" : "") << t.lo.x << ' ' << t.lo.y << ' ' << t.lo.z << ' ' << t.hi.x << ' ' << t.hi.y << ' ' << t.hi.z;
  }
  return o.str();
}

std::vector<BrickBox> parse_tiles(const std::string& text, const std::string& where) {
  std::vector<BrickBox> tiles;
  std::istringstream in(text);
  std::string item;
  while (std::getline(in, item, ';')) {
    std::istringstream f(item);
    BrickBox t;
    if (!(f >> t.lo.x >> t.lo.y >> t.lo.z >> t.hi.x >> t.hi.y >> t.hi.z))
      throw InputError(where + ": job journal: malformed sweep plan '" + item + "'");
    tiles.push_back(t);
  }
  return tiles;
}

// The journal's file for a message, given the job folder or the file itself.
std::string journal_file(const std::string& where) {
  const std::filesystem::path p(where);
  return p.filename() == "job.sqlite" ? where : (p / "job.sqlite").string();
}

// A number the journal keeps as text. A damaged value is a fault of the job folder (bad input,
// exit 2, naming the journal), not an internal error.
std::uint64_t meta_number(sqlite3* db, const std::string& key, const std::string& where, bool required,
                          std::uint64_t max = std::numeric_limits<std::uint64_t>::max()) {
  const std::string v = meta(db, key, where);
  if (v.empty()) {
    if (required) throw InputError(journal_file(where) + ": job journal: " + key + " is missing");
    return 0;
  }
  std::uint64_t n = 0;
  if (!input_detail::parse_number(std::string_view(v), &n) || n > max)
    throw InputError(journal_file(where) + ": job journal: " + key + " is '" + v + "', not a number" +
                     (max != std::numeric_limits<std::uint64_t>::max() ? " up to " + std::to_string(max) : ""));
  return n;
}

std::size_t meta_count(sqlite3* db, const std::string& key, const std::string& where) {
  return meta_number(db, key, where, false);
}

// The progress of the last committed checkpoint.
IntegrationProgress read_progress(sqlite3* db, const std::string& where) {
  IntegrationProgress p;
  p.integrated = meta_count(db, "integrated", where);
  p.sweep_end = std::max(p.integrated, meta_count(db, "sweep_end", where));
  if (p.sweeping()) {
    p.tiles = parse_tiles(meta(db, "sweep_tiles", where), where);
    p.tile = meta_count(db, "sweep_tile", where);
    p.tile_frames = meta_count(db, "sweep_tile_frames", where);
    p.steps = meta_count(db, "sweep_steps", where);
    if (p.tiles.empty() || p.tile > p.tiles.size()) throw InputError(where + ": job journal: inconsistent sweep record");
  }
  return p;
}

// The last checkpoint's bricks and tiles, in brick order.
std::vector<ManifestEntry> read_manifest(sqlite3* db, const std::string& where) {
  std::vector<ManifestEntry> manifest;
  Statement s(db, "SELECT bx, by, bz, generation, bytes FROM manifest ORDER BY bz, by, bx", where);
  while (s.step()) {
    ManifestEntry e;
    for (int k = 0; k < 5; ++k)
      if (s.integer(k) < 0 || (k < 3 && s.integer(k) >= (std::int64_t{1} << kMaxLevel)))
        throw InputError(journal_file(where) + ": job journal: manifest row out of range");
    e.coord = {std::uint32_t(s.integer(0)), std::uint32_t(s.integer(1)), std::uint32_t(s.integer(2))};
    e.generation = std::uint64_t(s.integer(3));
    e.bytes = std::uint64_t(s.integer(4));
    manifest.push_back(e);
  }
  return manifest;
}

DamagedTile missing_tile(const TileStore& store, const ManifestEntry& e) {
  return DamagedTile(store.path(e.coord, e.generation).string() + ": tile of the last checkpoint is missing", e.coord,
                     e.generation);
}

// Records depth maps [from, frames.size()) in the inputs table (inside the caller's transaction).
void insert_inputs(sqlite3* db, const std::vector<FrameIdentity>& frames, std::size_t from, const std::string& where) {
  Statement ins(db, "INSERT INTO inputs(idx, name, size, hash) VALUES(?1, ?2, ?3, ?4)", where);
  for (std::size_t i = from; i < frames.size(); ++i) {
    ins.bind(1, std::int64_t(i)).bind(2, frames[i].name).bind(3, std::int64_t(frames[i].file_size));
    ins.bind(4, hex16(frames[i].hash)).run();
  }
}

// The first line where two texts differ, for a refusal message.
std::string first_difference(const std::string& a, const std::string& b) {
  std::istringstream ia(a), ib(b);
  std::string la, lb;
  while (true) {
    const bool ga = bool(std::getline(ia, la)), gb = bool(std::getline(ib, lb));
    if (!ga && !gb) return "";
    if (!ga) la = "(nothing)";
    if (!gb) lb = "(nothing)";
    if (la != lb) return "job has '" + la + "', this run '" + lb + "'";
  }
}

}  // namespace

std::size_t parse_byte_size(const std::string& text, const std::string& what) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  std::string unit(end ? end : "");
  double scale = 1;
  if (unit == "K" || unit == "k" || unit == "KiB") scale = 1024.0;
  else if (unit == "M" || unit == "MiB") scale = 1024.0 * 1024;
  else if (unit == "G" || unit == "GiB") scale = 1024.0 * 1024 * 1024;
  else if (unit == "T" || unit == "TiB") scale = 1024.0 * 1024 * 1024 * 1024;
  else if (!unit.empty()) throw InputError(what + ": unknown size unit in '" + text + "' (use K, M, G or T)");
  if (text.empty() || end == text.c_str() || !(v > 0) || !std::isfinite(v))
    throw InputError(what + ": expected a positive size like 1.5G, got '" + text + "'");
  return std::size_t(v * scale);
}

Job::Job(JobOptions options, std::string config, std::string input, std::string output)
    : options_(std::move(options)), config_(std::move(config)), input_(std::move(input)), output_(std::move(output)) {
  std::error_code ec;
  std::filesystem::create_directories(options_.dir, ec);
  if (ec) throw InputError(options_.dir.string() + ": cannot create the job directory: " + ec.message());
  // One writer per job: a second process on the same directory is refused, not interleaved. The
  // lock goes with the process, however it ends.
  lock_fd_ = ::open((options_.dir / "job.lock").c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (lock_fd_ < 0)
    throw InputError((options_.dir / "job.lock").string() + ": cannot open the job's lock: " + std::strerror(errno));
  if (::flock(lock_fd_, LOCK_EX | LOCK_NB) != 0) {
    ::close(lock_fd_);
    throw InputError(options_.dir.string() + ": another scalefuse process is using this job");
  }
  const std::string where = (options_.dir / "job.sqlite").string();
  try {
    db_ = open_db(options_.dir / "job.sqlite", true);
  } catch (...) {
    ::close(lock_fd_);
    throw;
  }
  try {
  exec(db_,
       "PRAGMA journal_mode=WAL; PRAGMA synchronous=FULL;"
       "CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);"
       "CREATE TABLE IF NOT EXISTS inputs(idx INTEGER PRIMARY KEY, name TEXT NOT NULL, size INTEGER NOT NULL,"
       "  hash TEXT NOT NULL);"
       "CREATE TABLE IF NOT EXISTS manifest(bx INTEGER, by INTEGER, bz INTEGER, generation INTEGER NOT NULL,"
       "  bytes INTEGER NOT NULL, PRIMARY KEY(bx, by, bz));"
       "CREATE TABLE IF NOT EXISTS reach(idx INTEGER PRIMARY KEY, lx INTEGER NOT NULL, ly INTEGER NOT NULL,"
       "  lz INTEGER NOT NULL, hx INTEGER NOT NULL, hy INTEGER NOT NULL, hz INTEGER NOT NULL);"
       "CREATE TABLE IF NOT EXISTS extract_done(pass TEXT NOT NULL, item INTEGER NOT NULL, PRIMARY KEY(pass, item));"
       "CREATE TABLE IF NOT EXISTS extract_blob(box TEXT NOT NULL, dest INTEGER NOT NULL, src INTEGER NOT NULL,"
       "  seq INTEGER NOT NULL, offset INTEGER NOT NULL, stored INTEGER NOT NULL, raw INTEGER NOT NULL);",
       where);
  store_ = std::make_unique<TileStore>(options_.dir / "tiles", tile_buffer_budget(options_.memory_limit));
  } catch (...) {
    sqlite3_close(db_);
    ::close(lock_fd_);
    throw;
  }
  last_checkpoint_ = std::chrono::steady_clock::now();
}

// The extraction's record: SQLite rows committed in one transaction each (64-bit keys stored as
// their two's-complement int64).
class Job::Extraction : public ExtractJournal {
 public:
  Extraction(sqlite3* db, std::string where, double seconds, std::size_t kill_after, std::size_t term_after)
      : db_(db), where_(std::move(where)), seconds_(seconds), kill_after_(kill_after), term_after_(term_after) {}
  std::vector<std::pair<std::string, std::uint64_t>> finished() const override {
    std::vector<std::pair<std::string, std::uint64_t>> out;
    Statement s(db_, "SELECT pass, item FROM extract_done", where_);
    while (s.step()) out.push_back({s.text(0), std::uint64_t(s.integer(1))});
    return out;
  }
  std::vector<Record> blobs() const override {
    std::vector<Record> out;
    Statement s(db_, "SELECT box, dest, src, seq, offset, stored, raw FROM extract_blob ORDER BY rowid", where_);
    while (s.step()) {
      Record r;
      r.box = s.text(0);
      r.blob = {std::uint64_t(s.integer(1)), std::uint64_t(s.integer(2)), std::uint64_t(s.integer(3)),
                std::uint64_t(s.integer(4)), std::uint32_t(s.integer(5)), std::uint32_t(s.integer(6))};
      out.push_back(std::move(r));
    }
    return out;
  }
  void commit(const std::string& pass, const std::vector<std::uint64_t>& items,
              const std::vector<Record>& blobs) override {
    Transaction t(db_, where_);
    Statement done(db_, "INSERT OR IGNORE INTO extract_done(pass, item) VALUES(?1, ?2)", where_);
    for (std::uint64_t item : items) done.bind(1, pass).bind(2, std::int64_t(item)).run();
    Statement blob(db_, "INSERT INTO extract_blob(box, dest, src, seq, offset, stored, raw) VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7)",
                   where_);
    for (const Record& r : blobs) {
      blob.bind(1, r.box).bind(2, std::int64_t(r.blob.dest)).bind(3, std::int64_t(r.blob.src));
      blob.bind(4, std::int64_t(r.blob.seq)).bind(5, std::int64_t(r.blob.offset)).bind(6, std::int64_t(r.blob.stored));
      blob.bind(7, std::int64_t(r.blob.raw)).run();
    }
    t.commit();
    ++commits_;
    if (kill_after_ > 0 && commits_ == kill_after_) ::kill(::getpid(), SIGKILL);
    if (term_after_ > 0 && commits_ == term_after_) ::kill(::getpid(), SIGTERM);
  }
  void forget(const std::vector<std::string>& boxes) override {
    Transaction t(db_, where_);
    Statement del(db_, "DELETE FROM extract_blob WHERE box = ?1", where_);
    for (const std::string& b : boxes) del.bind(1, b).run();
    t.commit();
  }
  double commit_seconds() const override { return seconds_; }

 private:
  sqlite3* db_;
  std::string where_;
  double seconds_;
  std::size_t kill_after_, term_after_, commits_ = 0;
};

ExtractJournal* Job::extraction(const std::string& signature, const std::filesystem::path& scratch) {
  const std::string where = options_.dir.string();
  // The record holds for this signature on this field: the last checkpoint's tiles.
  const std::string full = signature + " field " + meta(db_, "max_generation", where) + "/" + meta(db_, "integrated", where);
  if (meta(db_, "extract_signature", where) != full) {
    Transaction t(db_, where);
    exec(db_, "DELETE FROM extract_done; DELETE FROM extract_blob;", where);
    set_meta(db_, "extract_signature", full, where);
    t.commit();
    std::error_code ec;
    std::filesystem::remove_all(scratch, ec);
  }
  set_meta(db_, "stage", "extracting", where);
  scratch_ = scratch;
  // Commits at most every 30 s (the integration's checkpoint interval when shorter): a brick
  // pass loses at most that much work.
  extraction_ = std::make_unique<Extraction>(db_, where, std::min(options_.checkpoint_seconds, 30.0),
                                             options_.kill_in_extraction, options_.term_in_extraction);
  return extraction_.get();
}

Job::~Job() {
  sqlite3_close(db_);
  if (lock_fd_ >= 0) ::close(lock_fd_);
}

static RootCube parse_root(const std::string& text, const std::string& where) {
  const std::vector<double> v = parse_number_list(text, 4, where + ": recorded root cube");
  RootCube r;
  r.min = Eigen::Vector3d(v[0], v[1], v[2]);
  r.size = v[3];
  return r;
}

std::optional<RootCube> Job::fixed_root() const {
  const std::string where = options_.dir.string();
  const std::string text = meta(db_, "root", where);
  if (text.empty()) return options_.root;
  return parse_root(text, where);
}

std::optional<int> Job::fixed_brick_level() const {
  const std::string text = meta(db_, "brick_level", options_.dir.string());
  if (text.empty()) return options_.brick_level;
  return int(meta_number(db_, "brick_level", options_.dir.string(), true, kMaxLevel));
}

Job::Field Job::field(const std::filesystem::path& dir) {
  const std::filesystem::path file = dir / "job.sqlite";
  if (!std::filesystem::exists(file)) throw InputError(dir.string() + ": not a scalefuse job directory (no job.sqlite)");
  sqlite3* db = open_db(file, false);
  Field f;
  try {
    const std::string where = file.string();
    const TileStore names(dir / "tiles");
    f.manifest = read_manifest(db, where);
    for (const ManifestEntry& e : f.manifest) f.tiles.push_back(names.path(e.coord, e.generation));
    f.max_generation = meta_number(db, "max_generation", where, false);
  } catch (...) {
    sqlite3_close(db);
    throw;
  }
  sqlite3_close(db);
  return f;
}

void Job::adopt(const std::vector<Field>& fields, std::size_t depth_maps) {
  const std::string where = options_.dir.string();
  if (meta_count(db_, "integrated", where) != 0 || !meta(db_, "sweep_tiles", where).empty())
    throw InputError(where + ": this job has integrated depth maps itself; merge takes a job made by scalefuse plan");
  std::set<std::uint64_t> seen;
  std::uint64_t max_generation = 0;
  for (const Field& f : fields) {
    max_generation = std::max(max_generation, f.max_generation);
    for (std::size_t i = 0; i < f.manifest.size(); ++i) {
      const ManifestEntry& e = f.manifest[i];
      if (!seen.insert(e.coord.packed()).second)
        throw InputError(f.tiles[i].string() + ": brick (" + std::to_string(e.coord.x) + ", " + std::to_string(e.coord.y) +
                         ", " + std::to_string(e.coord.z) + ") is in the fields of two tiles");
      if (!std::filesystem::exists(f.tiles[i])) throw InputError(f.tiles[i].string() + ": tile of a checkpoint is missing");
      link_tile(f.tiles[i], store_->path(e.coord, e.generation));
    }
  }
  store_->sync();
  Transaction t(db_, where);
  exec(db_, "DELETE FROM manifest", where);
  Statement ins(db_, "INSERT INTO manifest(bx, by, bz, generation, bytes) VALUES(?1, ?2, ?3, ?4, ?5)", where);
  for (const Field& f : fields)
    for (const ManifestEntry& e : f.manifest) {
      ins.bind(1, e.coord.x).bind(2, e.coord.y).bind(3, e.coord.z).bind(4, std::int64_t(e.generation));
      ins.bind(5, std::int64_t(e.bytes)).run();
    }
  set_meta(db_, "integrated", std::to_string(depth_maps), where);
  for (const char* key : {"sweep_end", "sweep_tile", "sweep_tile_frames", "sweep_steps"}) set_meta(db_, key, "0", where);
  set_meta(db_, "sweep_tiles", "", where);
  set_meta(db_, "max_generation", std::to_string(max_generation), where);
  set_meta(db_, "stage", "integrated", where);
  set_meta(db_, "checkpoint_time", utc_now(), where);
  t.commit();
}

std::optional<std::size_t> Job::depth_maps_in_brick(BrickCoord c) const {
  const IntegrationProgress p = read_progress(db_, options_.dir.string());
  if (!p.sweeping()) return p.integrated;
  if (p.tiles.size() == 1) return p.integrated + p.tile_frames;  // one tile: every depth map, in order
  std::size_t t = 0;
  while (t < p.tiles.size() && !p.tiles[t].contains(c)) ++t;
  // A finished tile of the sweep took every depth map of it that reaches it; a later one none yet.
  if (t < p.tile) return p.sweep_end;
  if (t > p.tile || p.tile_frames == 0) return p.integrated;
  return std::nullopt;  // the tile under way took the first tile_frames of those reaching it
}

std::vector<DamagedTile> Job::damaged_tiles() const {
  const std::vector<ManifestEntry> manifest = read_manifest(db_, options_.dir.string());
  const std::optional<int> brick_level = fixed_brick_level();
  if (!brick_level) return {};
  std::vector<std::optional<DamagedTile>> found(manifest.size());
  tbb::parallel_for(std::size_t(0), manifest.size(), [&](std::size_t i) {
    const ManifestEntry& e = manifest[i];
    if (!std::filesystem::exists(store_->path(e.coord, e.generation))) {
      found[i] = missing_tile(*store_, e);
      return;
    }
    try {
      VoxelTable voxels(*brick_level);
      store_->read(e.coord, e.generation, voxels);
    } catch (const DamagedTile& d) {
      found[i] = d;
    }
  });
  std::vector<DamagedTile> out;
  for (auto& d : found)
    if (d) out.push_back(std::move(*d));
  return out;
}

void Job::replace_tile(const Field& rebuilt, BrickCoord c) {
  const std::string where = options_.dir.string();
  std::optional<std::uint64_t> old_generation;
  {
    Statement q(db_, "SELECT generation FROM manifest WHERE bx = ?1 AND by = ?2 AND bz = ?3", where);
    q.bind(1, c.x).bind(2, c.y).bind(3, c.z);
    if (q.step()) old_generation = std::uint64_t(q.integer(0));
  }
  if (!old_generation) throw std::logic_error(where + ": replace_tile of a brick the checkpoint does not hold");
  std::size_t i = 0;
  while (i < rebuilt.manifest.size() && rebuilt.manifest[i].coord.packed() != c.packed()) ++i;
  if (i == rebuilt.manifest.size())
    throw InputError(store_->path(c, *old_generation).string() +
                     ": damaged tile, and re-integrating its depth maps gives no data for its brick");
  // A new generation: the damaged file stays until the journal refers to its replacement.
  const std::uint64_t generation = meta_number(db_, "max_generation", where, true) + 1;
  const std::string old_max = meta(db_, "max_generation", where);
  link_tile(rebuilt.tiles[i], store_->path(c, generation));
  store_->sync();
  Transaction t(db_, where);
  Statement up(db_, "UPDATE manifest SET generation = ?4, bytes = ?5 WHERE bx = ?1 AND by = ?2 AND bz = ?3", where);
  up.bind(1, c.x).bind(2, c.y).bind(3, c.z).bind(4, std::int64_t(generation));
  up.bind(5, std::int64_t(rebuilt.manifest[i].bytes)).run();
  set_meta(db_, "max_generation", std::to_string(generation), where);
  // The rebuilt brick holds what the damaged tile held (integration is deterministic), so an
  // extraction under way keeps the bricks it finished: its record follows the field's new name.
  const std::string signature = meta(db_, "extract_signature", where);
  const std::string old_field = " field " + old_max + "/", new_field = " field " + std::to_string(generation) + "/";
  const std::size_t at = signature.rfind(old_field);
  if (at != std::string::npos)
    set_meta(db_, "extract_signature", signature.substr(0, at) + new_field + signature.substr(at + old_field.size()),
             where);
  t.commit();
  store_->remove(c, *old_generation);
}

IntegrationProgress Job::begin(const std::vector<FrameIdentity>& frames, const RootCube& root, BrickMap& map) {
  const std::string where = options_.dir.string();
  map.attach_store(store_.get(), options_.memory_limit);
  const std::string version = meta(db_, "version", where);
  if (version.empty()) {  // a new job
    Transaction t(db_, where);
    set_meta(db_, "version", std::to_string(kJobVersion), where);
    set_meta(db_, "config", config_, where);
    set_meta(db_, "input", input_, where);
    set_meta(db_, "output", output_, where);
    set_meta(db_, "root", root_text(root), where);
    set_meta(db_, "brick_level", std::to_string(map.brick_level()), where);
    set_meta(db_, "stage", "integrating", where);
    set_meta(db_, "integrated", "0", where);
    set_meta(db_, "max_generation", "0", where);
    set_meta(db_, "follow", options_.follow ? "1" : "0", where);
    insert_inputs(db_, frames, 0, where);
    t.commit();
    store_->remove_all_except({});
    return progress_ = IntegrationProgress{};
  }
  if (version != std::to_string(kJobVersion))
    throw InputError(where + ": job format version " + version + ", this build handles " + std::to_string(kJobVersion));
  // Same configuration and inputs, or refuse.
  const std::string old_config = meta(db_, "config", where);
  if (old_config != config_)
    throw JobMismatch(where + ": the configuration differs from the job's (" + first_difference(old_config, config_) +
                     "); use a new --job directory");
  const bool may_grow = options_.allow_new_inputs || options_.follow;
  if (!may_grow && meta(db_, "input", where) != input_)
    throw JobMismatch(where + ": the job was started on " + meta(db_, "input", where) + ", not " + input_ +
                     "; use a new --job directory");
  std::size_t count = 0;
  {
    Statement s(db_, "SELECT idx, name, size, hash FROM inputs ORDER BY idx", where);
    while (s.step()) {
      const std::size_t i = std::size_t(s.integer(0));
      if (i >= frames.size())
        throw JobMismatch(where + ": the inputs changed: the job has more depth maps (" + s.text(1) +
                         " is gone); use a new --job directory");
      if (s.text(1) != frames[i].name || std::uint64_t(s.integer(2)) != frames[i].file_size ||
          s.text(3) != hex16(frames[i].hash))
        throw JobMismatch(where + ": the inputs changed: depth map " + std::to_string(i) + " (" + frames[i].name +
                         ") differs from the one the job integrated; use a new --job directory");
      ++count;
    }
  }
  if (count != frames.size() && !(may_grow && count < frames.size()))
    throw JobMismatch(where + ": the inputs changed: the job has " + std::to_string(count) + " depth maps, the input " +
                     std::to_string(frames.size()) + "; use a new --job directory");
  if (count < frames.size()) {  // scalefuse add, or more depth maps arrived while following: record them
    Transaction t(db_, where);
    insert_inputs(db_, frames, count, where);
    set_meta(db_, "stage", "integrating", where);
    set_meta(db_, "input", input_, where);
    t.commit();
  }
  if (meta(db_, "root", where) != root_text(root) || meta(db_, "brick_level", where) != std::to_string(map.brick_level()))
    throw JobMismatch(where + ": the root cube or brick level differs from the job's");
  // Restore the last checkpoint.
  const std::vector<ManifestEntry> manifest = read_manifest(db_, where);
  std::set<std::pair<std::uint64_t, std::uint64_t>> keep;
  for (const ManifestEntry& e : manifest) keep.insert({e.coord.packed(), e.generation});
  for (const ManifestEntry& e : manifest)
    if (!std::filesystem::exists(store_->path(e.coord, e.generation))) throw missing_tile(*store_, e);
  store_->remove_all_except(keep);
  map.restore(manifest, meta_number(db_, "max_generation", where, true));
  progress_ = read_progress(db_, where);
  if (progress_.sweep_end > frames.size()) throw InputError(where + ": job journal: inconsistent sweep record");
  return progress_;
}

void Job::checkpoint(BrickMap& map, const char* stage) {
  const std::string where = options_.dir.string();
  const std::vector<ManifestEntry> manifest = map.write_checkpoint();  // tiles are fsynced
  Transaction t(db_, where);
  exec(db_, "DELETE FROM manifest", where);
  Statement ins(db_, "INSERT INTO manifest(bx, by, bz, generation, bytes) VALUES(?1, ?2, ?3, ?4, ?5)", where);
  for (const ManifestEntry& e : manifest) {
    ins.bind(1, e.coord.x).bind(2, e.coord.y).bind(3, e.coord.z).bind(4, std::int64_t(e.generation));
    ins.bind(5, std::int64_t(e.bytes)).run();
  }
  set_meta(db_, "integrated", std::to_string(progress_.integrated), where);
  set_meta(db_, "sweep_end", std::to_string(progress_.sweep_end), where);
  set_meta(db_, "sweep_tiles", tiles_text(progress_.tiles), where);
  set_meta(db_, "sweep_tile", std::to_string(progress_.tile), where);
  set_meta(db_, "sweep_tile_frames", std::to_string(progress_.tile_frames), where);
  set_meta(db_, "sweep_steps", std::to_string(progress_.steps), where);
  set_meta(db_, "max_generation", std::to_string(map.max_generation()), where);
  set_meta(db_, "stage", stage, where);
  set_meta(db_, "checkpoint_time", utc_now(), where);
  t.commit();
  map.checkpoint_committed();
  since_checkpoint_ = 0;
  ++checkpoints_;
  last_checkpoint_ = std::chrono::steady_clock::now();
}

void Job::step_done(const IntegrationProgress& progress, BrickMap& map) {
  progress_ = progress;
  ++since_checkpoint_;
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - last_checkpoint_).count();
  if (since_checkpoint_ >= options_.checkpoint_every || elapsed >= options_.checkpoint_seconds)
    checkpoint(map, "integrating");
  map.enforce_limit();
  const std::size_t step = progress.integrated + progress.steps;
  if (options_.kill_after > 0 && step == options_.kill_after) ::kill(::getpid(), SIGKILL);
  if (options_.term_after > 0 && step == options_.term_after) ::kill(::getpid(), SIGTERM);
}

void Job::tile_done(const IntegrationProgress& progress, BrickMap& map) {
  progress_ = progress;
  checkpoint(map, "integrating");
}

void Job::integrated(const IntegrationProgress& progress, BrickMap& map) {
  progress_ = progress;
  checkpoint(map, "integrated");
}

void Job::interrupted(const IntegrationProgress& progress, BrickMap& map) {
  progress_ = progress;
  checkpoint(map, "integrating");
}

void Job::finished(const std::filesystem::path& mesh) {
  const std::string where = options_.dir.string();
  Transaction t(db_, where);
  set_meta(db_, "stage", "done", where);
  set_meta(db_, "mesh", mesh.string(), where);
  exec(db_, "DELETE FROM extract_done; DELETE FROM extract_blob; DELETE FROM meta WHERE key = 'extract_signature';",
       where);
  t.commit();
  if (!scratch_.empty()) {
    std::error_code ec;
    std::filesystem::remove_all(scratch_, ec);
  }
}

JobStatus Job::recorded(const std::filesystem::path& dir, std::string* config) {
  const std::filesystem::path file = dir / "job.sqlite";
  if (!std::filesystem::exists(file)) throw InputError(dir.string() + ": not a scalefuse job directory (no job.sqlite)");
  sqlite3* db = open_db(file, false);
  JobStatus st;
  try {
    const std::string where = file.string();
    st.stage = meta(db, "stage", where);
    if (st.stage.empty()) st.stage = "new";
    st.input = meta(db, "input", where);
    st.output = meta(db, "output", where);
    const IntegrationProgress p = read_progress(db, where);
    st.integrated = p.whole_frames();
    st.sweep_tiles = p.tiles.size();
    st.sweep_tile = p.tile;
    st.sweep_steps = p.steps;
    st.last_checkpoint = meta(db, "checkpoint_time", where);
    st.follow = meta(db, "follow", where) == "1";
    if (config) *config = meta(db, "config", where);
    {
      Statement s(db, "SELECT COUNT(*) FROM inputs", where);
      if (s.step()) st.depth_maps = std::size_t(s.integer(0));
    }
    {
      Statement s(db, "SELECT COUNT(*), COALESCE(SUM(bytes), 0) FROM manifest", where);
      if (s.step()) {
        st.bricks = std::size_t(s.integer(0));
        st.tile_bytes = std::uint64_t(s.integer(1));
      }
    }
    bool has_extraction = false;  // jobs of older builds have no such table
    {
      Statement s(db, "SELECT COUNT(*) FROM sqlite_master WHERE name = 'extract_done'", where);
      has_extraction = s.step() && s.integer(0) > 0;
    }
    if (has_extraction) {
      Statement s(db, "SELECT pass, SUM(item != -1), MAX(item = -1), MIN(rowid) FROM extract_done GROUP BY pass ORDER BY 4",
                  where);
      while (s.step()) st.extraction.push_back({s.text(0), std::size_t(s.integer(1)), s.integer(2) != 0});
    }
  } catch (...) {
    sqlite3_close(db);
    throw;
  }
  sqlite3_close(db);
  std::error_code ec;
  for (const char* f : {"job.sqlite", "job.sqlite-wal"}) {
    const auto n = std::filesystem::file_size(dir / f, ec);
    if (!ec) st.journal_bytes += n;
  }
  return st;
}

JobStatus Job::status(const std::filesystem::path& dir) { return recorded(dir, nullptr); }

std::vector<std::string> Job::recorded_inputs(const std::filesystem::path& dir) {
  const std::filesystem::path file = dir / "job.sqlite";
  std::vector<std::string> names;
  if (!std::filesystem::exists(file)) return names;
  sqlite3* db = open_db(file, false);
  try {
    Statement s(db, "SELECT name FROM inputs ORDER BY idx", file.string());
    while (s.step()) names.push_back(s.text(0));
  } catch (...) {
    sqlite3_close(db);
    throw;
  }
  sqlite3_close(db);
  return names;
}

void Job::reached(std::size_t from, const std::vector<BrickBox>& boxes) {
  // Committed before the depth maps are integrated, so every checkpoint's depth maps have theirs.
  const std::string where = options_.dir.string();
  Transaction t(db_, where);
  Statement ins(db_, "INSERT OR REPLACE INTO reach(idx, lx, ly, lz, hx, hy, hz) VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7)",
                where);
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    const BrickBox& b = boxes[i];
    ins.bind(1, std::int64_t(from + i)).bind(2, b.lo.x).bind(3, b.lo.y).bind(4, b.lo.z);
    ins.bind(5, b.hi.x).bind(6, b.hi.y).bind(7, b.hi.z).run();
  }
  t.commit();
}

std::vector<std::size_t> Job::depth_maps_reaching(const BrickBox& region, std::size_t n) const {
  std::vector<char> reaches(n, 1);  // no record: it may
  Statement s(db_, "SELECT idx, lx, ly, lz, hx, hy, hz FROM reach WHERE idx < ?1", options_.dir.string());
  s.bind(1, std::int64_t(n));
  while (s.step()) {
    const auto at = [&](int col) { return std::uint32_t(s.integer(col)); };
    const BrickBox b{{at(1), at(2), at(3)}, {at(4), at(5), at(6)}};
    reaches[std::size_t(s.integer(0))] = b.meets(region);
  }
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i < n; ++i)
    if (reaches[i]) out.push_back(i);
  return out;
}

void Job::inputs_added(const std::vector<FrameIdentity>& frames, std::size_t from) {
  const std::string where = options_.dir.string();
  Transaction t(db_, where);
  insert_inputs(db_, frames, from, where);
  set_meta(db_, "stage", "integrating", where);
  t.commit();
}

}  // namespace sf
