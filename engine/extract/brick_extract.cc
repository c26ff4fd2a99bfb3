#include "engine/extract/brick_extract.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cmath>
#include <limits>
#include <cstring>
#include <chrono>
#include <functional>
#include <list>
#ifdef __GLIBC__
#include <malloc.h>
#endif
#include <map>
#include <set>
#include <mutex>
#include <numeric>
#include <sstream>
#include <unordered_map>

#include "engine/error.h"
#include "engine/extract/certificate.h"
#include "engine/extract/delaunay.h"
#include "engine/extract/flat_map.h"
#include "engine/extract/lattice_cubes.h"
#include "engine/extract/marching_tets.h"
#include "engine/extract/voxel_set.h"
#include "storage/mailbox.h"

namespace sf {

using namespace extract_detail;

namespace {

// --- Records exchanged between passes (plain data, zero-padded) --------------------------------

// 7.2: voxel `target` may snap onto its crossing with `other` at this fraction of their edge;
// the attributes are the crossing's, computed on the original distances.
struct SnapOffer {
  std::uint64_t target, other;
  std::uint32_t fraction_bits, pad;
  double position[3];
  float colour[3], weight, scale, pad2;
};
// A voxel's decided snap.
struct Snap {
  std::uint64_t key;
  double position[3];
  float colour[3], weight, scale, pad;
};
// An output vertex sent to its home brick by the brick whose cells use it.
struct VertexRequest {
  std::uint64_t a, b;    // voxel keys, a <= b
  std::uint64_t src;     // requesting brick (Morton code)
  std::uint32_t local;   // its index in the requester's vertex list
  float position[3];
  std::uint8_t colour[3], pad;
  float confidence, scale;
};
struct PlyVertex {
  float position[3];
  std::uint8_t colour[3], pad;
  float confidence, scale;
};
// The answer: vertex `local` of the requester is number `rank` of home brick `home`.
struct Rank {
  std::uint32_t local, home, rank;
};
struct Face {
  std::uint32_t v[3];
  std::uint32_t zero;  // a zero face (three zero voxels), cancelled if it meets its twin
};

std::uint32_t float_bits(float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}

// One brick's voxels in key order, with their lattice points (level G).
struct BrickVoxels {
  std::vector<SurfaceVoxel> voxels;
  std::vector<LatticePoint> points;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> by_cell;  // (occupancy cell, voxel), sorted
  std::size_t bytes() const {
    return voxels.capacity() * sizeof(SurfaceVoxel) + points.capacity() * sizeof(LatticePoint) +
           by_cell.capacity() * sizeof(by_cell[0]);
  }
};

// A window's triangulation and its side arrays, per point (CGAL's cells and vertices, about 550
// bytes per point as measured on the global path, plus the window's own lists).
constexpr std::size_t kWindowBytesPerPoint = 650;
// Per window voxel, triangulated or not: its lists and its part of the empty cubes' index.
constexpr std::size_t kWindowBytesPerVoxel = 120;

// Per-item counters of a pass, summed at the end (they go through a mailbox, so that a resumed
// run counts the items an earlier run did).
struct Tally {
  std::uint64_t v[8];
};

// Bit i of v -> bit i of the result, for every third bit (the inverse of spread_bits).
std::uint32_t compact_bits(std::uint64_t v) {
  std::uint32_t out = 0;
  for (int i = 0; i < 21; ++i) out |= std::uint32_t((v >> (3 * i)) & 1) << i;
  return out;
}

struct BrickInfo {
  std::uint64_t code;  // Morton code of the brick coordinates = its place in the output
  std::uint32_t x, y, z;
  std::uint64_t voxels;
};

// Each pass and the mailboxes it posts to (read by later passes only).
const std::vector<std::pair<std::string, std::vector<std::string>>>& pass_outputs() {
  static const std::vector<std::pair<std::string, std::vector<std::string>>> table = {
      {"regularize", {"incoming", "tally_add"}},
      {"prepare", {"survivors", "occupancy", "tally_prepare"}},
      {"tetrahedralize", {"piece_voxels", "piece_cells", "offers", "tally_windows"}},
      {"snap", {"snaps", "tally_snap"}},
      {"march", {"requests", "piece_faces"}},
      {"number", {"vertices", "ranks"}},
      {"faces", {"homed_faces"}},
      {"sort", {"final_faces", "tally_sort"}},
      {"write", {}},
  };
  return table;
}
const std::vector<std::string>& outputs_of(const std::string& pass) {
  for (const auto& [name, boxes] : pass_outputs())
    if (name == pass) return boxes;
  throw std::logic_error("extract: no pass " + pass);
}
int pass_index(const std::string& pass) {
  const auto& t = pass_outputs();
  for (std::size_t i = 0; i < t.size(); ++i)
    if (t[i].first == pass) return int(i);
  throw std::logic_error("extract: no pass " + pass);
}

// A shared extraction's stage ends after its pass (caught in run()).
struct StageEnd {};

}  // namespace

const std::vector<std::string>& BrickExtraction::passes() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n;
    for (const auto& p : pass_outputs()) n.push_back(p.first);
    return n;
  }();
  return names;
}

struct BrickExtraction::Impl {
  std::filesystem::path scratch;
  RootCube root;
  int B;  // brick level
  ExtractOptions options;
  std::size_t cache_bytes;
  // Window triangulations in flight, by estimated bytes, and what the groups being built hold
  // between their windows (owned cells, snap offers): a thread waits while all that and its
  // window would pass the budget. A window alone (no other in flight) always runs, so that threads
  // whose groups hold much never wait on each other for ever.
  std::size_t window_budget;
  std::mutex window_mutex;
  std::condition_variable window_freed;
  std::size_t window_bytes = 0;  // windows in flight and groups' standing bytes
  int windows_in_flight = 0;
  // Sets a group's standing bytes (`counted`, what window_bytes holds for it) to `now`; never
  // waits: what it counts is already made.
  void hold_standing(std::size_t& counted, std::size_t now) {
    {
      std::lock_guard lock(window_mutex);
      window_bytes = window_bytes - counted + now;
    }
    if (now < counted) window_freed.notify_all();
    counted = now;
  }

  // Progress and the mailboxes, durable through the journal when there is one.
  ExtractJournal* journal = nullptr;
  std::map<std::string, std::vector<Mailbox::Blob>> committed;    // by box: an earlier run's
  std::map<std::string, std::set<std::uint64_t>> finished_before;  // by pass: items an earlier run did
  std::mutex boxes_mutex;
  std::map<std::string, std::unique_ptr<Mailbox>> boxes;
  // A pass's items finished since its last commit.
  struct Pass {
    Pass(std::string pass, std::vector<std::string> boxes) : name(std::move(pass)), outputs(std::move(boxes)) {}
    std::string name;
    std::vector<std::string> outputs;
    std::mutex mutex;
    std::vector<std::uint64_t> finished;
    std::chrono::steady_clock::time_point last = std::chrono::steady_clock::now();
    // The bricks whose posts an item makes (the journal commits their blobs with it); unset:
    // the item is a brick and posts as itself.
    std::function<void(std::uint64_t item, std::vector<std::uint64_t>& srcs)> sources;
  };
  Pass adding{"regularize", outputs_of("regularize")};
  // A cluster tile's stage (ExtractShare): the passes before it are every tile's, read through
  // union mailboxes of the tiles' manifests (box -> parts).
  const ExtractShare* share = nullptr;
  int stage = -1;
  bool stage_manifest = false;  // this tile has finished the stage
  std::map<std::string, std::vector<Mailbox::Part>> shared;
  bool own_tile() const { return share && share->tile < share->folders.size(); }
  std::filesystem::path manifest(const std::string& pass) const {
    return share->folders[share->tile] / (pass + ".blobs");
  }
  void write_manifest(const Pass& p);
  mutable std::atomic<std::size_t> resumed{0};  // items skipped: an earlier run finished them
  std::vector<std::pair<std::string, double>> pass_seconds;  // ExtractStats::pass_seconds
  const std::atomic<bool>* stop = nullptr;      // set_stop()
  bool stopping() const { return stop && stop->load(std::memory_order_relaxed); }

  // Set by prepare():
  int G = 0;                      // lattice level: max(finest, B)
  std::int64_t side = 0, brick_side = 0;
  std::vector<BrickInfo> bricks;  // bricks with voxels, by code
  std::uint32_t levels = 0;       // bit l: some voxel of level l
  Occupancy occ;

  // The decoded-brick cache of the windows (least recently used out).
  std::mutex cache_mutex;
  std::list<std::pair<std::uint64_t, std::shared_ptr<const BrickVoxels>>> lru;
  std::unordered_map<std::uint64_t, decltype(lru)::iterator> cached;
  std::size_t cached_bytes = 0;

  std::uint64_t brick_code_of_key(VoxelKey k) const { return home_code(k) >> (3 * (kMaxLevel - B)); }
  std::ptrdiff_t ordinal(std::uint64_t code) const {
    const auto it = std::lower_bound(bricks.begin(), bricks.end(), code,
                                     [](const BrickInfo& b, std::uint64_t c) { return b.code < c; });
    return it != bricks.end() && it->code == code ? it - bricks.begin() : -1;
  }
  LatticePoint lattice(VoxelKey k) const {
    const int s = G - k.level();
    return {std::int32_t(k.x()) << s, std::int32_t(k.y()) << s, std::int32_t(k.z()) << s};
  }
  std::shared_ptr<const BrickVoxels> load(std::uint64_t code);
  void prepare(const ProgressFn& progress, ExtractStats* st);
  std::vector<std::vector<std::uint32_t>> window_groups() const;

  Mailbox& box(const std::string& name);
  void forget(const std::vector<std::string>& names);
  bool done_before(const std::string& pass, std::uint64_t item) const {
    if (share) {
      const int i = pass_index(pass);
      if (i < stage) return true;  // every tile's, or the stage would not have started
      if (i > stage) return false;
      if (item == ExtractJournal::kWholePass) return stage_manifest;
    }
    const auto it = finished_before.find(pass);
    return it != finished_before.end() && (it->second.count(item) || it->second.count(ExtractJournal::kWholePass));
  }
  void commit(Pass& p, bool whole);  // p.mutex held
  void finish(Pass& p, std::uint64_t item);
  // Runs fn(k) for each items[k] an earlier run did not finish, in parallel, committing as it
  // goes; `stage` (if not null) reports progress per item.
  void run_pass(Pass& p, const std::vector<std::uint64_t>& items, const std::function<void(std::size_t)>& fn,
                const ProgressFn& progress, const char* stage);
  // The sum of a pass's tallies (box "tally_<pass>"), or their bitwise or.
  Tally sum(const std::string& pass, bool bitwise_or = false) {
    Tally t{};
    for (const Tally& x : box("tally_" + pass).collect<Tally>(0))
      for (int i = 0; i < 8; ++i) t.v[i] = bitwise_or ? t.v[i] | x.v[i] : t.v[i] + x.v[i];
    return t;
  }
};

// Between passes, the heap the last one freed goes back to the system: glibc keeps freed blocks
// of the windows' triangulations (hundreds of MiB, below its mmap threshold once that has grown)
// in its arenas, where the next pass's different sizes fragment them further.
static void release_freed_memory() {
#ifdef __GLIBC__
  ::malloc_trim(0);
#endif
}

Mailbox& BrickExtraction::Impl::box(const std::string& name) {
  std::lock_guard lock(boxes_mutex);
  std::unique_ptr<Mailbox>& b = boxes[name];
  if (!b && share) {
    const auto it = shared.find(name);
    if (it != shared.end()) b = std::make_unique<Mailbox>(it->second);
  }
  if (!b) {
    const auto it = committed.find(name);
    b = it != committed.end() ? std::make_unique<Mailbox>(scratch, name, it->second)
                              : std::make_unique<Mailbox>(scratch, name);
    if (journal) b->keep_file();
  }
  return *b;
}

void BrickExtraction::Impl::forget(const std::vector<std::string>& names) {
  if (journal) journal->forget(names);
  std::lock_guard lock(boxes_mutex);
  if (share) {
    // Every tile has finished the passes that read these (this stage is later): each deletes its
    // own files, and the merge (every stage done) what is left of anyone's; unions never open
    // them again.
    for (const std::string& name : names) {
      boxes.erase(name);
      committed.erase(name);
      std::error_code ec;
      if (own_tile()) std::filesystem::remove(share->folders[share->tile] / (name + ".box"), ec);
      else
        for (const std::filesystem::path& folder : share->folders) std::filesystem::remove(folder / (name + ".box"), ec);
    }
    return;
  }
  for (const std::string& name : names) {
    const auto it = boxes.find(name);
    if (it != boxes.end()) {
      it->second->remove_file();
      boxes.erase(it);
    } else {
      std::error_code ec;
      std::filesystem::remove(scratch / (name + ".box"), ec);
    }
    committed.erase(name);
  }
}

void BrickExtraction::Impl::commit(Pass& p, bool whole) {
  p.last = std::chrono::steady_clock::now();
  if (!journal) {
    p.finished.clear();
    if (whole && share && pass_index(p.name) == stage) write_manifest(p);
    return;
  }
  std::sort(p.finished.begin(), p.finished.end());
  std::vector<std::uint64_t> srcs;
  if (p.sources) {
    for (std::uint64_t item : p.finished) p.sources(item, srcs);
    std::sort(srcs.begin(), srcs.end());
  } else {
    srcs = p.finished;
  }
  std::vector<ExtractJournal::Record> records;
  for (const std::string& name : p.outputs)
    for (const Mailbox::Blob& b : box(name).sync_blobs_from(srcs)) records.push_back({name, b});
  if (whole) p.finished.push_back(ExtractJournal::kWholePass);
  journal->commit(p.name, p.finished, records);
  p.finished.clear();
  if (whole && share && pass_index(p.name) == stage) write_manifest(p);
}

void BrickExtraction::Impl::write_manifest(const Pass& p) {
  std::vector<BlobRecord> records;
  for (const std::string& name : p.outputs)
    for (const Mailbox::Blob& b : box(name).blobs()) records.push_back({name, b});
  write_blob_manifest(manifest(p.name), records);
  stage_manifest = true;
}

void BrickExtraction::Impl::finish(Pass& p, std::uint64_t item) {
  std::lock_guard lock(p.mutex);
  p.finished.push_back(item);
  if (journal &&
      std::chrono::duration<double>(std::chrono::steady_clock::now() - p.last).count() >= journal->commit_seconds())
    commit(p, false);
}

void BrickExtraction::Impl::run_pass(Pass& p, const std::vector<std::uint64_t>& items,
                                     const std::function<void(std::size_t)>& fn, const ProgressFn& progress,
                                     const char* stage) {
  const bool this_stage = share && pass_index(p.name) == this->stage;
  if (share && pass_index(p.name) > this->stage) throw std::logic_error("extract: pass " + p.name + " after the stage");
  if (share && !this_stage) return;  // every tile's, before this stage
  if (stage) report(progress, stage, 0, double(items.size()));
  if (done_before(p.name, ExtractJournal::kWholePass)) {
    resumed += items.size();
    if (stage) report(progress, stage, double(items.size()), double(items.size()));
    if (this_stage) throw StageEnd{};
    return;
  }
  for (const std::string& name : p.outputs) box(name);  // made before the threads post to them
  const auto start = std::chrono::steady_clock::now();
  std::atomic<std::size_t> done{0}, left{0};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, items.size(), 1), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t k = r.begin(); k != r.end(); ++k) {
      if (share && !share->owns(items[k])) {
        // another tile's
      } else if (!done_before(p.name, items[k])) {
        if (stopping()) {  // the bricks in flight finish; the rest wait for the resumed run
          ++left;
          continue;
        }
        fn(k);
        finish(p, items[k]);
      } else {
        ++resumed;
      }
      if (stage) report(progress, stage, double(++done), double(items.size()));
    }
  });
  {
    std::lock_guard lock(p.mutex);
    commit(p, left == 0);
  }
  if (left > 0)
    throw Interrupted("interrupted in the extraction's " + p.name + " pass (" + std::to_string(left.load()) + " of " +
                      std::to_string(items.size()) + " bricks left)");
  release_freed_memory();
  pass_seconds.emplace_back(p.name, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  if (this_stage) throw StageEnd{};
}

BrickExtraction::BrickExtraction(std::filesystem::path scratch, const RootCube& root, int brick_level,
                                 const ExtractOptions& options, std::size_t memory_budget, ExtractJournal* journal,
                                 const ExtractShare* share)
    : impl_(std::make_unique<Impl>()) {
  options.check();
  if (brick_level < 0 || brick_level > kMaxLevel)
    throw InputError("extract: brick level must be in [0, " + std::to_string(kMaxLevel) + "], got " +
                     std::to_string(brick_level));
  impl_->scratch = std::move(scratch);
  impl_->root = root;
  impl_->B = brick_level;
  impl_->options = options;
  impl_->cache_bytes = memory_budget / 4;
  impl_->window_budget = memory_budget / 5 * 2;
  impl_->journal = journal;
  if (journal) {
    for (const auto& [pass, item] : journal->finished()) impl_->finished_before[pass].insert(item);
    for (const ExtractJournal::Record& r : journal->blobs()) impl_->committed[r.box].push_back(r.blob);
  }
  if (share) {
    Impl& m = *impl_;
    m.share = share;
    m.stage = pass_index(share->stage);
    if (m.own_tile()) {
      if (m.scratch != share->folders[share->tile]) throw std::logic_error("extract: a tile's scratch is its folder");
      m.stage_manifest = std::filesystem::exists(m.manifest(share->stage));
    }
    // The passes before the stage, from every tile's manifests.
    for (int p = 0; p < m.stage; ++p) {
      const std::string& pass = pass_outputs()[std::size_t(p)].first;
      std::map<std::string, Mailbox::Part> parts;  // of one tile
      for (std::size_t t = 0; t < share->folders.size(); ++t) {
        const std::filesystem::path file = share->folders[t] / (pass + ".blobs");
        if (!std::filesystem::exists(file))
          throw StageNotReady("tile " + std::to_string(t) + " has not finished stage " + pass + " (no " + file.string() +
                              ")");
        parts.clear();
        for (BlobRecord& r : read_blob_manifest(file)) {
          Mailbox::Part& part = parts[r.box];
          part.file = share->folders[t] / (r.box + ".box");
          part.blobs.push_back(r.blob);
        }
        for (const std::string& box : outputs_of(pass)) {
          std::vector<Mailbox::Part>& all = m.shared[box];  // made even if no tile posted to it
          const auto it = parts.find(box);
          if (it != parts.end()) all.push_back(std::move(it->second));
        }
      }
    }
  }
}

bool BrickExtraction::stage_finished() const { return impl_->stage_manifest; }

BrickExtraction::~BrickExtraction() {
  const std::filesystem::path scratch = impl_->scratch;
  impl_.reset();  // the mailboxes delete their files (unless a journal refers to them)
  std::error_code ec;
  std::filesystem::remove(scratch, ec);  // only if empty: the folder may be the caller's
}

void BrickExtraction::set_stop(const std::atomic<bool>* stop) { impl_->stop = stop; }

void BrickExtraction::commit_added() {
  std::lock_guard lock(impl_->adding.mutex);
  impl_->commit(impl_->adding, false);
}

bool BrickExtraction::added_before(std::uint64_t source) const {
  const bool done = impl_->done_before("regularize", source);
  if (done) ++impl_->resumed;
  return done;
}
bool BrickExtraction::all_added_before() const {
  return impl_->done_before("regularize", ExtractJournal::kWholePass);
}
void BrickExtraction::all_added() {
  if (impl_->share && impl_->stage > 0) return;  // every tile did
  std::lock_guard lock(impl_->adding.mutex);
  impl_->box("incoming");  // even if nothing was added
  impl_->box("tally_add");
  impl_->commit(impl_->adding, true);
}
std::size_t BrickExtraction::size() const { return impl_->sum("add").v[1]; }

void BrickExtraction::add(std::uint64_t source, const std::vector<SurfaceVoxel>& voxels) {
  Impl& m = *impl_;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> order(voxels.size());
  std::uint32_t levels = 0;
  for (std::size_t i = 0; i < voxels.size(); ++i) {
    const VoxelKey k = voxels[i].key;
    if (!valid_voxel(k.level(), k.x(), k.y(), k.z()) || (k.bits >> 62) != 0) {
      std::ostringstream s;
      s << "extract: voxel with an invalid key (bits 0x" << std::hex << k.bits << ")";
      throw InputError(s.str());
    }
    levels |= 1u << k.level();
    order[i] = {m.brick_code_of_key(k), std::uint32_t(i)};
  }
  std::sort(order.begin(), order.end());
  std::vector<SurfaceVoxel> group;
  for (std::size_t i = 0; i < order.size();) {
    const std::uint64_t code = order[i].first;
    group.clear();
    for (; i < order.size() && order[i].first == code; ++i) group.push_back(voxels[order[i].second]);
    m.box("incoming").post(code, source, group);
  }
  m.box("tally_add").post(0, source, std::vector<Tally>{{{levels, voxels.size()}}});
  m.finish(m.adding, source);
}

std::vector<SurfaceVoxel> BrickExtraction::voxels() const {
  std::vector<SurfaceVoxel> all;
  all.reserve(size());
  Mailbox& incoming = impl_->box("incoming");
  for (std::uint64_t code : incoming.destinations()) {
    const std::vector<SurfaceVoxel> b = incoming.collect<SurfaceVoxel>(code);
    all.insert(all.end(), b.begin(), b.end());
  }
  return all;
}

std::shared_ptr<const BrickVoxels> BrickExtraction::Impl::load(std::uint64_t code) {
  {
    std::lock_guard lock(cache_mutex);
    const auto it = cached.find(code);
    if (it != cached.end()) {
      lru.splice(lru.begin(), lru, it->second);
      return it->second->second;
    }
  }
  auto b = std::make_shared<BrickVoxels>();
  b->voxels = box("survivors").collect<SurfaceVoxel>(code);
  b->points.resize(b->voxels.size());
  b->by_cell.resize(b->voxels.size());
  for (std::size_t i = 0; i < b->voxels.size(); ++i) {
    const LatticePoint p = b->points[i] = lattice(b->voxels[i].key);
    b->by_cell[i] = {Occupancy::pack(p[0] / occ.side, p[1] / occ.side, p[2] / occ.side), std::uint32_t(i)};
  }
  std::sort(b->by_cell.begin(), b->by_cell.end());
  std::lock_guard lock(cache_mutex);
  if (cached.count(code)) return cached[code]->second;
  lru.emplace_front(code, b);
  cached[code] = lru.begin();
  cached_bytes += b->bytes();
  while (cached_bytes > cache_bytes && lru.size() > 1) {
    cached_bytes -= lru.back().second->bytes();
    cached.erase(lru.back().first);
    lru.pop_back();
  }
  return b;
}

// Pass 1's items: octree cells of bricks, coarse to fine, each split into its eight children
// while it holds more than options.window_group_voxels voxels or, in a cluster tile's stage, another
// tile's bricks too. A group is the ascending indices (into `bricks`) of its bricks; never empty.
std::vector<std::vector<std::uint32_t>> BrickExtraction::Impl::window_groups() const {
  std::vector<std::vector<std::uint32_t>> groups;
  const auto mine = [&](std::size_t i) { return !share || share->owns(bricks[i].code); };
  // bricks[a, b) are those of one cell of level g.
  const auto visit = [&](const auto& self, std::size_t a, std::size_t b, int g) -> void {
    std::uint64_t voxels = 0;
    std::size_t owned = 0;
    for (std::size_t i = a; i < b; ++i) {
      voxels += bricks[i].voxels;
      owned += mine(i) ? 1 : 0;
    }
    if (owned == 0) return;
    if (g == B || (voxels <= options.window_group_voxels && owned == b - a)) {
      std::vector<std::uint32_t>& group = groups.emplace_back();
      for (std::size_t i = a; i < b; ++i)
        if (mine(i)) group.push_back(std::uint32_t(i));
      return;
    }
    const int shift = 3 * (B - g - 1);
    for (std::size_t i = a; i < b;) {
      std::size_t j = i;
      while (j < b && (bricks[j].code >> shift & 7) == (bricks[i].code >> shift & 7)) ++j;
      self(self, i, j, g + 1);
      i = j;
    }
  };
  visit(visit, 0, bricks.size(), 0);
  return groups;
}

// Pass 0: each brick's voxels sorted and checked, coarser twins dropped, then indexed.
void BrickExtraction::Impl::prepare(const ProgressFn& progress, ExtractStats* st) {
  int finest = 0;
  for (std::uint64_t bits = sum("add", true).v[0]; bits >> (finest + 1) != 0;) ++finest;
  G = std::max(finest, B);
  side = std::int64_t{1} << G;
  brick_side = std::int64_t{1} << (G - B);
  occ.side = std::max<std::int64_t>(1, brick_side / 8);
  Pass pass{"prepare", outputs_of("prepare")};
  Mailbox& incoming = box("incoming");
  const std::vector<std::uint64_t> codes = incoming.destinations();
  run_pass(pass, codes, [&](std::size_t bi) {
    std::vector<SurfaceVoxel> v = incoming.collect<SurfaceVoxel>(codes[bi]);
    std::sort(v.begin(), v.end(), [](const SurfaceVoxel& a, const SurfaceVoxel& b) { return a.key < b.key; });
    for (std::size_t i = 0; i < v.size(); ++i) {
      const auto fail = [&](const std::string& what) {
        throw InputError("extract: voxel at " + describe(v[i].key) + " " + what);
      };
      if (i > 0 && v[i].key == v[i - 1].key) fail("is given twice");
      if (const char* problem = value_problem(v[i])) fail(problem);
    }
    // A voxel coincides with the voxels its even coordinates reach by halving, all in this brick;
    // keep the finest (section 6 has normally dropped the others already).
    std::vector<std::uint8_t> drop(v.size(), 0);
    for (const SurfaceVoxel& s : v) {
      VoxelKey k = s.key;
      while (k.has_coarser_twin()) {
        k = k.coarser_twin();
        const auto it = std::lower_bound(v.begin(), v.end(), k, [](const SurfaceVoxel& a, VoxelKey b) { return a.key < b; });
        if (it != v.end() && it->key == k) drop[std::size_t(it - v.begin())] = 1;
      }
    }
    std::vector<SurfaceVoxel> out;
    out.reserve(v.size());
    std::uint64_t bits = 0;
    std::vector<std::uint64_t> cells;
    for (std::size_t i = 0; i < v.size(); ++i) {
      if (drop[i]) continue;
      out.push_back(v[i]);
      bits |= 1u << v[i].key.level();
      const LatticePoint p = lattice(v[i].key);
      cells.push_back(Occupancy::pack(p[0] / occ.side, p[1] / occ.side, p[2] / occ.side));
    }
    std::sort(cells.begin(), cells.end());
    cells.erase(std::unique(cells.begin(), cells.end()), cells.end());  // at most 512
    box("survivors").post(codes[bi], codes[bi], out);
    box("occupancy").post(0, codes[bi], cells);
    box("tally_prepare").post(0, codes[bi], std::vector<Tally>{{{bits, out.size(), v.size() - out.size(), codes[bi]}}});
  }, progress, "prepare");
  forget({"incoming"});
  // The bricks and their counts, from the tallies (they outlive the survivors, which pass 1
  // consumes).
  std::vector<std::pair<std::uint64_t, std::uint64_t>> codes_kept;  // (code, voxels)
  for (const Tally& t : box("tally_prepare").collect<Tally>(0)) {
    levels |= std::uint32_t(t.v[0]);
    st->voxels += t.v[1];
    st->coincident_voxels += t.v[2];
    codes_kept.push_back({t.v[3], t.v[1]});
  }
  std::sort(codes_kept.begin(), codes_kept.end());
  for (const auto& [code, count] : codes_kept)
    bricks.push_back({code, compact_bits(code), compact_bits(code >> 1), compact_bits(code >> 2), count});
  if (done_before("tetrahedralize", ExtractJournal::kWholePass)) return;  // (its only reader; gone)
  occ.cells = box("occupancy").collect<std::uint64_t>(0);
  tbb::parallel_sort(occ.cells.begin(), occ.cells.end());
  occ.cells.erase(std::unique(occ.cells.begin(), occ.cells.end()), occ.cells.end());
  occ.cells.shrink_to_fit();
}

void BrickExtraction::run(MeshStream& out, const ProgressFn& progress, ExtractStats* stats) {
  if (impl_->share && impl_->stage == 0) throw std::logic_error("extract: the regularize stage adds, it does not run");
  try {
    run_passes(out, progress, stats);
  } catch (const StageEnd&) {
    // this tile's stage is done
  }
}

void BrickExtraction::run_passes(MeshStream& out, const ProgressFn& progress, ExtractStats* stats) {
  Impl& m = *impl_;
  ExtractStats st;
  st.by_brick = true;
  if (size() < 4) throw InputError("too few confident voxels to extract a surface (" + std::to_string(size()) + ")");
  m.prepare(progress, &st);
  const int n = m.options.neighbourhood_n;
  const double snap_fraction = m.options.snap_fraction;
  const std::int64_t side = m.side, brick_side = m.brick_side, last_brick = (std::int64_t{1} << m.B) - 1;
  const std::size_t nb = m.bricks.size();
  const auto brick_axis_of = [&](std::int64_t p) { return std::min<std::int64_t>(p / brick_side, last_brick); };

  // --- Pass 1: windows -------------------------------------------------------------------------
  Impl::Pass windows_pass{"tetrahedralize", outputs_of("tetrahedralize")};
  Mailbox &piece_voxels = m.box("piece_voxels"), &piece_cells = m.box("piece_cells"), &offers = m.box("offers");
  struct Counters {
    std::uint64_t tetrahedra, kept, windows, points, regrown, split, rejected, in_cubes;
  };
  static_assert(sizeof(Counters) == sizeof(Tally));
  // The pass's items are window groups (brick_extract.h): octree cells of bricks, named by their
  // first brick's code.
  const std::vector<std::vector<std::uint32_t>> groups = m.window_groups();
  std::vector<std::uint64_t> group_items(groups.size());
  std::unordered_map<std::uint64_t, std::size_t> group_of_item;
  for (std::size_t g = 0; g < groups.size(); ++g) {
    group_items[g] = m.bricks[groups[g][0]].code;
    group_of_item[group_items[g]] = g;
  }
  windows_pass.sources = [&](std::uint64_t item, std::vector<std::uint64_t>& srcs) {
    for (std::uint32_t b : groups.at(group_of_item.at(item))) srcs.push_back(m.bricks[b].code);
  };
  m.run_pass(windows_pass, group_items, [&](std::size_t gi) {
    Counters count{};
    {
      const std::uint64_t item = group_items[gi];
      std::vector<std::uint64_t> group_codes;  // ascending
      for (std::uint32_t b : groups[gi]) group_codes.push_back(m.bricks[b].code);
      // Bricks held while X's windows are built (the cache may drop them meanwhile). Their voxels
      // get group-wide ids, consecutive per brick from its base (bases ascending in id_base).
      struct Held {
        std::shared_ptr<const BrickVoxels> brick;
        std::uint32_t base;
      };
      std::unordered_map<std::uint64_t, Held> held;
      std::vector<std::pair<std::uint32_t, const BrickVoxels*>> id_base;
      std::uint32_t next_id = 0;
      const auto hold_with_base = [&](std::uint64_t code) -> const Held* {
        auto it = held.find(code);
        if (it == held.end()) {
          if (m.ordinal(code) < 0) return nullptr;
          std::shared_ptr<const BrickVoxels> b = m.load(code);
          id_base.emplace_back(next_id, b.get());
          it = held.emplace(code, Held{std::move(b), next_id}).first;
          next_id += std::uint32_t(it->second.brick->voxels.size());
        }
        return &it->second;
      };
      const auto hold = [&](std::uint64_t code) -> const BrickVoxels* {
        const Held* h = hold_with_base(code);
        return h ? h->brick.get() : nullptr;
      };
      const auto voxel_of = [&](std::uint32_t id) {
        const auto it = std::prev(std::upper_bound(id_base.begin(), id_base.end(), id,
                                                   [](std::uint32_t v, const auto& e) { return v < e.first; }));
        return &it->second->voxels[id - it->first];
      };
      // Windows by owner level. A cell X owns has its coarsest vertex, of level L, in X, and by
      // 7.1 every other vertex, of level l >= L, within h(L) + n h(l) of it on each axis. So the
      // window of X's level-L owners needs the level-l voxels of the owners' box grown by that
      // much and no others: its triangulation has every global cell whose vertices it holds, and
      // the certificate tells the cells that are not global apart. Fine voxels thus need a margin
      // of about h(L), not (1 + n) h(L) — dense detail next to a coarse voxel is what a window is
      // mostly made of. A finer level shares a window whose boxes hold its own; a window too big
      // for the memory budget is split in halves between its owners while they span more than
      // 2 h(L).
      std::vector<const BrickVoxels*> own;
      for (std::uint64_t code : group_codes) own.push_back(hold(code));
      const auto h = [&](int l) { return std::int64_t{1} << (m.G - l); };
      struct Window {
        std::uint32_t levels = 0;  // owner levels
        std::int64_t region[2][3];  // owners: [lo, hi) in lattice coordinates
        std::int64_t extra = 0;    // regrowth margin (a sliver's ball too big to certify)
      };
      // Voxels of level l are in the window iff in box[max(l, first)] (closed lattice boxes).
      struct Extent {
        std::int64_t box[kMaxLevel + 1][2][3];
        std::int64_t owners[2][3];  // the owners' bounding box
        std::int64_t inner[2][3];   // every voxel in it is in the window, whatever its level
        std::int64_t outer[2][3];   // every voxel in the window is in it
        int first = 0;              // the coarsest owner level in the region
        bool has_owners = false;
      };
      const auto in_region = [](const Window& w, const LatticePoint& p) {
        return p[0] >= w.region[0][0] && p[0] < w.region[1][0] && p[1] >= w.region[0][1] && p[1] < w.region[1][1] &&
               p[2] >= w.region[0][2] && p[2] < w.region[1][2];
      };
      const auto extent_of = [&](const Window& w) {
        Extent e;
        std::int64_t ob[kMaxLevel + 1][2][3];
        std::uint32_t with_owners = 0;
        for (const BrickVoxels* b : own)
          for (std::size_t i = 0; i < b->voxels.size(); ++i) {
            const int L = b->voxels[i].key.level();
            const LatticePoint& p = b->points[i];
            if (!(w.levels >> L & 1) || !in_region(w, p)) continue;
            if (!(with_owners >> L & 1)) {
              with_owners |= 1u << L;
              for (int a = 0; a < 3; ++a) ob[L][0][a] = ob[L][1][a] = p[a];
            }
            for (int a = 0; a < 3; ++a) {
              ob[L][0][a] = std::min<std::int64_t>(ob[L][0][a], p[a]);
              ob[L][1][a] = std::max<std::int64_t>(ob[L][1][a], p[a]);
            }
          }
        e.has_owners = with_owners != 0;
        if (!e.has_owners) return e;
        while (!(with_owners >> e.first & 1)) ++e.first;
        for (int a = 0; a < 3; ++a) {
          e.owners[0][a] = e.inner[0][a] = e.outer[0][a] = side;
          e.owners[1][a] = e.inner[1][a] = e.outer[1][a] = 0;
        }
        bool first = true;
        for (int l = e.first; l <= m.G; ++l) {
          if (l != e.first && !(m.levels >> l & 1)) continue;  // no voxel of level l anywhere
          std::int64_t(&b)[2][3] = e.box[l];
          for (int a = 0; a < 3; ++a) {
            b[0][a] = side;
            b[1][a] = 0;
          }
          for (int L = e.first; L <= l; ++L) {
            if (!(with_owners >> L & 1)) continue;
            const std::int64_t margin = h(L) + n * h(l) + w.extra;
            for (int a = 0; a < 3; ++a) {
              b[0][a] = std::min(b[0][a], std::max<std::int64_t>(0, ob[L][0][a] - margin));
              b[1][a] = std::max(b[1][a], std::min(side, ob[L][1][a] + margin));
            }
          }
          for (int a = 0; a < 3; ++a) {
            e.outer[0][a] = std::min(e.outer[0][a], b[0][a]);
            e.outer[1][a] = std::max(e.outer[1][a], b[1][a]);
            e.inner[0][a] = first ? b[0][a] : std::max(e.inner[0][a], b[0][a]);
            e.inner[1][a] = first ? b[1][a] : std::min(e.inner[1][a], b[1][a]);
          }
          first = false;
        }
        for (int L = 0; L <= kMaxLevel; ++L)
          if (with_owners >> L & 1)
            for (int a = 0; a < 3; ++a) {
              e.owners[0][a] = std::min(e.owners[0][a], ob[L][0][a]);
              e.owners[1][a] = std::max(e.owners[1][a], ob[L][1][a]);
            }
        return e;
      };
      // The voxels a window of extent e holds.
      const auto members_of = [&](const Extent& e) {
        std::size_t count = 0;
        if (!e.has_owners) return count;
        for (std::int64_t z = brick_axis_of(e.outer[0][2]); z <= brick_axis_of(e.outer[1][2]); ++z)
          for (std::int64_t y = brick_axis_of(e.outer[0][1]); y <= brick_axis_of(e.outer[1][1]); ++y)
            for (std::int64_t x = brick_axis_of(e.outer[0][0]); x <= brick_axis_of(e.outer[1][0]); ++x) {
              const BrickVoxels* b = hold(morton(std::uint32_t(x), std::uint32_t(y), std::uint32_t(z)));
              if (!b) continue;
              for (std::size_t i = 0; i < b->voxels.size(); ++i) {
                const LatticePoint& p = b->points[i];
                const std::int64_t(&w)[2][3] = e.box[std::max(int(b->voxels[i].key.level()), e.first)];
                count += p[0] >= w[0][0] && p[0] <= w[1][0] && p[1] >= w[0][1] && p[1] <= w[1][1] && p[2] >= w[0][2] &&
                         p[2] <= w[1][2];
              }
            }
        return count;
      };
      std::vector<Window> windows;
      {
        // Per window, the voxels it holds once counted (kUncounted until then): the level merge
        // below asks for each window again with every finer level.
        constexpr std::size_t kUncounted = ~std::size_t{0};
        std::vector<std::size_t> held_voxels;
        std::uint32_t present = 0;
        for (const BrickVoxels* b : own)
          for (const SurfaceVoxel& s : b->voxels) present |= 1u << s.key.level();
        for (int L = 0; L <= kMaxLevel; ++L) {  // coarse to fine
          if (!(present >> L & 1)) continue;
          Window alone;
          alone.levels = 1u << L;
          for (int a = 0; a < 3; ++a) {
            alone.region[0][a] = 0;
            alone.region[1][a] = side + 1;
          }
          const Extent mine = extent_of(alone);
          bool joined = false;
          for (Window& w : windows) {
            const Extent theirs = extent_of(w);
            bool inside = true;
            for (int l = L; l <= m.G && inside; ++l) {
              if (!(m.levels >> l & 1)) continue;
              for (int a = 0; a < 3; ++a)
                inside = inside && mine.box[l][0][a] >= theirs.box[l][0][a] && mine.box[l][1][a] <= theirs.box[l][1][a];
            }
            if (inside) {
              w.levels |= 1u << L;
              held_voxels[std::size_t(&w - windows.data())] = kUncounted;
              joined = true;
              break;
            }
          }
          if (!joined) {
            // Or the window whose union with this level's holds fewer voxels than the two apart,
            // which would triangulate the voxels they share twice.
            const std::size_t apart = members_of(mine);
            for (std::size_t k = 0; k < windows.size() && !joined; ++k) {
              Window both = windows[k];
              both.levels |= 1u << L;
              if (held_voxels[k] == kUncounted) held_voxels[k] = members_of(extent_of(windows[k]));
              const std::size_t together = members_of(extent_of(both));
              if (together <= held_voxels[k] + apart) {
                windows[k] = both;
                held_voxels[k] = together;
                joined = true;
              }
            }
          }
          if (!joined) {
            windows.push_back(alone);
            held_voxels.push_back(kUncounted);
          }
        }
      }
      // The cells the group's bricks own, over all its windows, by their voxels' ids and owner
      // brick (its place in group_codes).
      struct Owned {
        std::array<std::uint32_t, 4> voxels;
        std::uint32_t brick;
      };
      std::vector<Owned> owned;
      std::vector<SnapOffer> offered;
      // What the group holds between its windows, counted in the window budget (Impl::hold_standing):
      // its cells, offers and brick table. Not its bricks: they are the cache's (a quarter of the
      // budget), and counting them twice made groups take turns needlessly (city: 165 % CPU and
      // the windows pass 1.3x slower than without them, bench/README.md session 23).
      const auto standing_now = [&] {
        return owned.capacity() * sizeof(Owned) + offered.capacity() * sizeof(SnapOffer) +
               held.size() * 64 + id_base.capacity() * sizeof(id_base[0]);
      };
      std::size_t standing = 0;
      struct Unhold {
        Impl& m;
        std::size_t& standing;
        ~Unhold() { m.hold_standing(standing, 0); }
      } unhold{m, standing};
      while (!windows.empty()) {
        const Window window = windows.back();
        windows.pop_back();
        const Extent ext = extent_of(window);
        if (!ext.has_owners) continue;
        const auto in_window = [&](const LatticePoint& p, int level) {
          const std::int64_t(&b)[2][3] = ext.box[std::max(level, ext.first)];
          return p[0] >= b[0][0] && p[0] <= b[1][0] && p[1] >= b[0][1] && p[1] <= b[1][1] && p[2] >= b[0][2] &&
                 p[2] <= b[1][2];
        };
        std::vector<const SurfaceVoxel*> members;
        std::vector<LatticePoint> member_points;
        std::vector<std::uint32_t> member_ids;
        {
          struct Found {
            std::uint64_t key;
            const SurfaceVoxel* voxel;
            LatticePoint point;
            std::uint32_t id;
          };
          std::vector<Found> found;
          for (std::int64_t z = brick_axis_of(ext.outer[0][2]); z <= brick_axis_of(ext.outer[1][2]); ++z)
            for (std::int64_t y = brick_axis_of(ext.outer[0][1]); y <= brick_axis_of(ext.outer[1][1]); ++y)
              for (std::int64_t x = brick_axis_of(ext.outer[0][0]); x <= brick_axis_of(ext.outer[1][0]); ++x) {
                const Held* h = hold_with_base(morton(std::uint32_t(x), std::uint32_t(y), std::uint32_t(z)));
                if (!h) continue;
                const BrickVoxels* b = h->brick.get();
                for (std::size_t i = 0; i < b->voxels.size(); ++i)
                  if (in_window(b->points[i], b->voxels[i].key.level()))
                    found.push_back({b->voxels[i].key.bits, &b->voxels[i], b->points[i], h->base + std::uint32_t(i)});
              }
          // Local index order = key order, as in the global extraction.
          std::sort(found.begin(), found.end(), [](const Found& p, const Found& q) { return p.key < q.key; });
          members.resize(found.size());
          member_points.resize(found.size());
          member_ids.resize(found.size());
          for (std::size_t i = 0; i < found.size(); ++i) {
            members[i] = found[i].voxel;
            member_points[i] = found[i].point;
            member_ids[i] = found[i].id;
          }
        }
        // Empty lattice cubes (lattice_cubes.h) give their cells outright; the voxels inside their
        // union stay out of the triangulation, which the others get.
        std::vector<std::uint8_t> member_levels(members.size());
        for (std::size_t i = 0; i < members.size(); ++i) member_levels[i] = std::uint8_t(members[i]->key.level());
        const EmptyCubes cubes(member_points, member_levels, m.G, m.levels,
                               [&](int L, const std::int64_t lo[3], const std::int64_t hi[3]) {
                                 const std::int64_t(&b)[2][3] = ext.box[std::max(L, ext.first)];
                                 for (int a = 0; a < 3; ++a)
                                   if (lo[a] < b[0][a] || hi[a] > b[1][a]) return false;
                                 return true;
                               });
        std::vector<LatticePoint> tri_points;
        std::vector<std::uint32_t> tri_member;  // triangulated point -> member
        for (std::size_t i = 0; i < members.size(); ++i) {
          if (!cubes.interior(i)) {
            tri_member.push_back(std::uint32_t(i));
            tri_points.push_back(member_points[i]);
          }
        }
        const std::size_t need = tri_points.size() * kWindowBytesPerPoint + members.size() * kWindowBytesPerVoxel;
        {
          int widest = 0;
          for (int a = 1; a < 3; ++a)
            if (ext.owners[1][a] - ext.owners[0][a] > ext.owners[1][widest] - ext.owners[0][widest]) widest = a;
          if (2 * need > m.window_budget && ext.owners[1][widest] - ext.owners[0][widest] > 2 * h(ext.first)) {
            const std::int64_t mid = (ext.owners[0][widest] + ext.owners[1][widest] + 1) / 2;
            Window lower = window, upper = window;
            lower.region[1][widest] = upper.region[0][widest] = mid;
            windows.push_back(upper);
            windows.push_back(lower);
            ++count.split;
            continue;
          }
        }
        // The certificate's voxels outside the window, loaded per occupied cell when a sphere
        // reaching out of the window's inner box meets it.
        std::unordered_map<std::uint64_t, std::vector<LatticePoint>> outside_cells;
        const OutsidePoints outside = [&](std::uint64_t cell) -> const std::vector<LatticePoint>& {
          auto [it, fresh] = outside_cells.try_emplace(cell);
          if (!fresh) return it->second;
          const std::int64_t c[3] = {std::int64_t(cell & 0x1FFFFF), std::int64_t((cell >> 21) & 0x1FFFFF),
                                     std::int64_t(cell >> 42)};
          const BrickVoxels* b = hold(morton(std::uint32_t(brick_axis_of(c[0] * m.occ.side)),
                                             std::uint32_t(brick_axis_of(c[1] * m.occ.side)),
                                             std::uint32_t(brick_axis_of(c[2] * m.occ.side))));
          if (!b) return it->second;
          for (auto e = std::lower_bound(b->by_cell.begin(), b->by_cell.end(),
                                         std::pair<std::uint64_t, std::uint32_t>{cell, 0});
               e != b->by_cell.end() && e->first == cell; ++e)
            if (!in_window(b->points[e->second], b->voxels[e->second].key.level()))
              it->second.push_back(b->points[e->second]);
          return it->second;
        };
        Voxels v;
        v.key.resize(members.size());
        v.distance.resize(members.size());
        for (std::size_t i = 0; i < members.size(); ++i) {
          v.key[i] = members[i]->key;
          v.distance[i] = members[i]->distance;
        }
        const bool whole = ext.inner[0][0] == 0 && ext.inner[0][1] == 0 && ext.inner[0][2] == 0 &&
                           ext.inner[1][0] == side && ext.inner[1][1] == side && ext.inner[1][2] == side;
        Counters mine{};
        std::vector<Tet> cells;
        std::vector<std::uint32_t> cell_brick;  // per cell: its owner's place in group_codes
        bool certified = true;
        {
          m.hold_standing(standing, standing_now());
          {
            std::unique_lock lock(m.window_mutex);
            m.window_freed.wait(lock, [&] { return m.windows_in_flight == 0 || m.window_bytes + need <= m.window_budget; });
            m.window_bytes += need;
            ++m.windows_in_flight;
          }
          struct Release {
            Impl& m;
            std::size_t bytes;
            ~Release() {
              {
                std::lock_guard lock(m.window_mutex);
                m.window_bytes -= bytes;
                --m.windows_in_flight;
              }
              m.window_freed.notify_all();
            }
          } release{m, need};
          // t: member indices. Cells the brick owns, kept by 7.1, with a negative voxel; `known`:
          // a cell of an empty cube, global without a certificate. A triangulated cell whose
          // centroid an empty cube covers is either that cube's or not global (lattice_cubes.h);
          // the others are global cells of the window's voxels.
          const auto consider = [&](const Tet& t, bool known) {
            int owner = 0;
            for (int k = 1; k < 4; ++k) {
              const int lk = v.key[t[k]].level(), lo_ = v.key[t[owner]].level();
              if (lk < lo_ || (lk == lo_ && t[k] < t[owner])) owner = k;
            }
            if (!(window.levels >> v.key[t[owner]].level() & 1)) return;
            const LatticePoint& op = member_points[t[owner]];
            if (!in_region(window, op)) return;
            const std::uint64_t owner_brick = morton(std::uint32_t(brick_axis_of(op[0])),
                                                     std::uint32_t(brick_axis_of(op[1])),
                                                     std::uint32_t(brick_axis_of(op[2])));
            const auto slot = std::lower_bound(group_codes.begin(), group_codes.end(), owner_brick);
            if (slot == group_codes.end() || *slot != owner_brick) return;
            if (!known && cubes.covers(t)) return;
            ++mine.tetrahedra;
            if (!keep_cell(t, v, n)) return;
            ++mine.kept;
            // Cells without a negative voxel never emit; the others may once snapping (7.2) has
            // zeroed some of their voxels.
            if (cell_kind(cell_distances(t, v.distance)) == CellKind::kNever) return;
            if (!known && !whole) {
              const LatticePoint* corners[4] = {&member_points[t[0]], &member_points[t[1]], &member_points[t[2]],
                                                &member_points[t[3]]};
              Ball ball;
              const Certificate c = !circumball(corners, &ball)
                                        ? Certificate::kUnknown
                                        : certify(ball, corners, ext.inner[0], ext.inner[1], outside, m.occ);
              if (c == Certificate::kUnknown) {
                certified = false;
                return;
              }
              if (c == Certificate::kNotGlobal) {
                ++mine.rejected;
                return;
              }
            }
            cells.push_back(t);
            cell_brick.push_back(std::uint32_t(slot - group_codes.begin()));
          };
          const DelaunayTetrahedralization dt(tri_points, false, nullptr);
          dt.for_each_cell([&](const Tet& local) {
            if (!certified) return;
            const Tet t{tri_member[local[0]], tri_member[local[1]], tri_member[local[2]], tri_member[local[3]]};
            consider(t, false);
          });
          if (certified)
            for (const std::array<std::uint32_t, 8>& corner : cubes.cubes()) {
              bool negative = false;
              for (std::uint32_t i : corner) negative = negative || v.distance[i] < 0;
              if (!negative) continue;  // none of its cells has a negative voxel
              for (const auto& c : kCubeCells) consider(Tet{corner[c[0]], corner[c[1]], corner[c[2]], corner[c[3]]}, true);
            }
        }
        ++count.windows;
        count.points += tri_points.size();
        count.in_cubes += members.size() - tri_points.size();
        if (!certified) {
          ++count.regrown;
          Window wider = window;
          wider.extra = window.extra > 0 ? 2 * window.extra : (1 + n) * h(ext.first);
          windows.push_back(wider);
          continue;
        }
        count.tetrahedra += mine.tetrahedra;
        count.kept += mine.kept;
        count.rejected += mine.rejected;
        for (std::size_t ci = 0; ci < cells.size(); ++ci) {
          const Tet& t = cells[ci];
          owned.push_back({{member_ids[t[0]], member_ids[t[1]], member_ids[t[2]], member_ids[t[3]]}, cell_brick[ci]});
          const std::array<float, 4> d = cell_distances(t, v.distance);
          if (!(snap_fraction > 0 && cell_kind(d) == CellKind::kMixed)) continue;
          for (int i = 0; i < 4; ++i)
            for (int j = i + 1; j < 4; ++j) {
              const std::uint32_t a = std::min(t[i], t[j]), b = std::max(t[i], t[j]);
              const float da = v.distance[a], db = v.distance[b];
              if (!((da < 0 && db > 0) || (da > 0 && db < 0))) continue;
              const double f = crossing_fraction(da, db);
              const auto offer = [&](std::uint32_t target, std::uint32_t other, double fraction) {
                const SurfaceVoxel& sa = *members[a];
                const SurfaceVoxel& sb = *members[b];
                const auto mix = [f](float x, float y) { return float(double(x) + f * (double(y) - double(x))); };
                SnapOffer o{};
                o.target = v.key[target].bits;
                o.other = v.key[other].bits;
                o.fraction_bits = float_bits(float(fraction));
                const Eigen::Vector3d p = lerp(m.root.position(sa.key), m.root.position(sb.key), f);
                for (int c = 0; c < 3; ++c) {
                  o.position[c] = p[c];
                  o.colour[c] = mix(sa.colour[c], sb.colour[c]);
                }
                o.weight = mix(sa.weight, sb.weight);
                o.scale = mix(float(m.root.cell_size(sa.key.level())), float(m.root.cell_size(sb.key.level())));
                offered.push_back(o);
              };
              if (f < snap_fraction) offer(a, b, f);
              if (1.0 - f < snap_fraction) offer(b, a, 1.0 - f);
            }
        }
      }
      // Each brick's piece: its cells' voxels in key order, the cells re-indexed (orientation
      // kept). Distinct voxels by id first (a voxel is in some 20 cells: no sort of all their
      // corners), then in key order.
      std::stable_sort(owned.begin(), owned.end(), [](const Owned& a, const Owned& b) { return a.brick < b.brick; });
      constexpr std::uint32_t kUnused = ~std::uint32_t{0};
      m.hold_standing(standing, standing_now() + (owned.empty() ? 0 : next_id) * sizeof(std::uint32_t));
      std::vector<std::uint32_t> first_use(owned.empty() ? 0 : next_id, kUnused);  // id -> place in `used`
      for (std::size_t first = 0; first < owned.size();) {
        std::size_t last = first;
        while (last < owned.size() && owned[last].brick == owned[first].brick) ++last;
        const std::uint64_t code = group_codes[owned[first].brick];
        std::vector<std::uint32_t> used;  // ids, in first-use order
        std::vector<Tet> cells(last - first);
        for (std::size_t c = first; c < last; ++c)
          for (int k = 0; k < 4; ++k) {
            std::uint32_t& u = first_use[owned[c].voxels[k]];
            if (u == kUnused) {
              u = std::uint32_t(used.size());
              used.push_back(owned[c].voxels[k]);
            }
            cells[c - first][k] = u;
          }
        std::vector<const SurfaceVoxel*> voxel(used.size());
        for (std::size_t i = 0; i < used.size(); ++i) {
          voxel[i] = voxel_of(used[i]);
          first_use[used[i]] = kUnused;
        }
        std::vector<std::uint32_t> by_key(used.size());
        std::iota(by_key.begin(), by_key.end(), 0u);
        std::sort(by_key.begin(), by_key.end(), [&](std::uint32_t p, std::uint32_t q) { return voxel[p]->key < voxel[q]->key; });
        std::vector<std::uint32_t> rank(used.size());
        std::vector<SurfaceVoxel> piece(used.size());
        for (std::size_t i = 0; i < by_key.size(); ++i) {
          rank[by_key[i]] = std::uint32_t(i);
          piece[i] = *voxel[by_key[i]];
        }
        for (Tet& t : cells)
          for (std::uint32_t& i : t) i = rank[i];
        piece_voxels.post(code, code, piece);
        piece_cells.post(code, code, cells);
        first = last;
      }
      if (!offered.empty()) {
        // The closest offer per voxel (ties: the lower other key), grouped by the voxel's brick.
        // Sorted as small keys (an offer is 72 bytes), then gathered.
        struct Order {
          std::uint64_t brick, target, other;
          std::uint32_t fraction_bits, index;
        };
        std::vector<Order> order(offered.size());
        for (std::size_t i = 0; i < offered.size(); ++i)
          order[i] = {m.brick_code_of_key(VoxelKey{offered[i].target}), offered[i].target, offered[i].other,
                      offered[i].fraction_bits, std::uint32_t(i)};
        std::sort(order.begin(), order.end(), [](const Order& a, const Order& b) {
          return a.brick != b.brick                 ? a.brick < b.brick
                 : a.target != b.target             ? a.target < b.target
                 : a.fraction_bits != b.fraction_bits ? a.fraction_bits < b.fraction_bits
                                                    : a.other < b.other;
        });
        order.erase(std::unique(order.begin(), order.end(), [](const Order& a, const Order& b) { return a.target == b.target; }),
                    order.end());
        std::vector<SnapOffer> to_brick;
        for (std::size_t i = 0; i < order.size();) {
          std::size_t j = i;
          to_brick.clear();
          for (; j < order.size() && order[j].brick == order[i].brick; ++j) to_brick.push_back(offered[order[j].index]);
          offers.post(order[i].brick, item, to_brick);
          i = j;
        }
      }
      Tally t;
      std::memcpy(&t, &count, sizeof(t));
      m.box("tally_windows").post(0, item, std::vector<Tally>{t});
    }
  }, progress, "tetrahedralize");
  {
    Counters c;
    const Tally t = m.sum("windows");
    std::memcpy(&c, &t, sizeof(c));
    st.tetrahedra = c.tetrahedra;
    st.kept_tetrahedra = c.kept;
    st.windows = c.windows;
    st.window_points = c.points;
    st.windows_regrown = c.regrown;
    st.windows_split = c.split;
    st.window_cells_rejected = c.rejected;
    st.window_voxels_in_cubes = c.in_cubes;
  }
  {
    std::lock_guard lock(m.cache_mutex);
    m.lru.clear();
    m.cached.clear();
    m.cached_bytes = 0;
  }
  release_freed_memory();
  m.forget({"survivors", "occupancy"});

  // --- Pass 2: snaps ---------------------------------------------------------------------------
  constexpr double kStages = 5;  // "extract" steps: snap, march, number, faces, write
  report(progress, "extract", 0, kStages);
  Impl::Pass snap_pass{"snap", outputs_of("snap")};
  Mailbox& snaps = m.box("snaps");
  {
    const std::vector<std::uint64_t> dests = offers.destinations();
    m.run_pass(snap_pass, dests, [&](std::size_t k) {
      std::vector<SnapOffer> o = offers.collect<SnapOffer>(dests[k]);
      std::sort(o.begin(), o.end(), [](const SnapOffer& p, const SnapOffer& q) {
        return p.target != q.target ? p.target < q.target
               : p.fraction_bits != q.fraction_bits ? p.fraction_bits < q.fraction_bits
                                                    : p.other < q.other;
      });
      std::vector<Snap> decided;
      for (std::size_t i = 0; i < o.size(); ++i) {
        if (i > 0 && o[i].target == o[i - 1].target) continue;
        Snap s{};
        s.key = o[i].target;
        for (int c = 0; c < 3; ++c) {
          s.position[c] = o[i].position[c];
          s.colour[c] = o[i].colour[c];
        }
        s.weight = o[i].weight;
        s.scale = o[i].scale;
        decided.push_back(s);
      }
      snaps.post(dests[k], dests[k], decided);
      m.box("tally_snap").post(0, dests[k], std::vector<Tally>{{{decided.size()}}});
    }, progress, nullptr);
  }
  m.forget({"offers"});
  st.snapped_voxels = m.sum("snap").v[0];

  // --- Pass 3: march ---------------------------------------------------------------------------
  report(progress, "extract", 1, kStages);
  Impl::Pass march_pass{"march", outputs_of("march")};
  Mailbox &requests = m.box("requests"), &piece_faces = m.box("piece_faces");
  {
    const std::vector<std::uint64_t> pieces = piece_cells.destinations();
    m.run_pass(march_pass, pieces, [&](std::size_t k) {
      const std::uint64_t X = pieces[k];
      const std::vector<SurfaceVoxel> pv = piece_voxels.collect<SurfaceVoxel>(X);
      const std::vector<Tet> cells = piece_cells.collect<Tet>(X);
      Voxels v;
      const std::size_t count = pv.size();
      v.key.resize(count);
      v.position.resize(count);
      v.distance.resize(count);
      v.weight.resize(count);
      v.scale.resize(count);
      v.colour.resize(count);
      std::vector<std::uint64_t> homes(count);
      for (std::size_t i = 0; i < count; ++i) {
        v.key[i] = pv[i].key;
        v.position[i] = m.root.position(pv[i].key);
        v.distance[i] = pv[i].distance;
        v.weight[i] = pv[i].weight;
        v.scale[i] = float(m.root.cell_size(pv[i].key.level()));
        v.colour[i] = pv[i].colour;
        homes[i] = m.brick_code_of_key(pv[i].key);
      }
      // 7.2: every snap is decided; apply those of this piece's voxels.
      std::vector<std::uint64_t> bricks_used = homes;
      std::sort(bricks_used.begin(), bricks_used.end());
      bricks_used.erase(std::unique(bricks_used.begin(), bricks_used.end()), bricks_used.end());
      for (std::uint64_t b : bricks_used) {
        const std::vector<Snap> table = snaps.collect<Snap>(b);
        if (table.empty()) continue;
        for (std::size_t i = 0; i < count; ++i) {
          if (homes[i] != b) continue;
          const auto it = std::lower_bound(table.begin(), table.end(), v.key[i].bits,
                                           [](const Snap& s, std::uint64_t key) { return s.key < key; });
          if (it == table.end() || it->key != v.key[i].bits) continue;
          v.position[i] = Eigen::Vector3d(it->position[0], it->position[1], it->position[2]);
          v.colour[i] = {it->colour[0], it->colour[1], it->colour[2]};
          v.weight[i] = it->weight;
          v.scale[i] = it->scale;
          v.distance[i] = 0;
        }
      }
      const FieldView field = v.view();
      std::vector<std::array<std::uint64_t, 3>> triangles;  // local MtVertex identities
      std::vector<std::uint8_t> zero;
      MtTriangle tri[2];
      for (const Tet& t : cells) {
        if (!emits_triangles(cell_distances(t, v.distance))) continue;
        const int made = march_tetrahedron(t, field, tri);
        for (int i = 0; i < made; ++i) {
          triangles.push_back({tri[i].v[0].id(), tri[i].v[1].id(), tri[i].v[2].id()});
          zero.push_back(tri[i].zero_face ? 1 : 0);
        }
      }
      if (triangles.empty()) return;
      // This piece's vertices in output order: by home code of the lower voxel, then identity
      // (local indices are in key order).
      std::vector<std::uint64_t> ids;
      ids.reserve(3 * triangles.size());
      for (const auto& t : triangles) ids.insert(ids.end(), t.begin(), t.end());
      std::sort(ids.begin(), ids.end());
      ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
      std::vector<std::uint64_t> home_code_of(count);
      for (std::size_t i = 0; i < count; ++i) home_code_of[i] = home_code(v.key[i]);
      std::vector<std::uint64_t> sorted_ids = ids;
      std::stable_sort(sorted_ids.begin(), sorted_ids.end(), [&](std::uint64_t p, std::uint64_t q) {
        return home_code_of[p >> 32] < home_code_of[q >> 32];
      });
      std::vector<std::uint32_t> local_of(ids.size());  // position in ids -> local vertex number
      for (std::size_t j = 0; j < sorted_ids.size(); ++j)
        local_of[std::size_t(std::lower_bound(ids.begin(), ids.end(), sorted_ids[j]) - ids.begin())] = std::uint32_t(j);
      std::vector<VertexRequest> asked(sorted_ids.size());
      for (std::size_t j = 0; j < sorted_ids.size(); ++j) {
        const MtVertex id = MtVertex::from_id(sorted_ids[j]);
        const Attributes at = id.a == id.b ? voxel_attributes(v, id.a) : crossing_attributes(v, id.a, id.b);
        VertexRequest& r = asked[j];
        r = VertexRequest{};
        r.a = v.key[id.a].bits;
        r.b = v.key[id.b].bits;
        r.src = X;
        r.local = std::uint32_t(j);
        const Eigen::Vector3f p = at.position.cast<float>();
        for (int c = 0; c < 3; ++c) {
          r.position[c] = p[c];
          r.colour[c] = to_byte(at.colour[c]);
        }
        r.confidence = at.weight;
        r.scale = at.scale;
      }
      for (std::size_t i = 0; i < asked.size();) {
        const std::uint64_t dest = homes[MtVertex::from_id(sorted_ids[i]).a];
        std::size_t j = i;
        while (j < asked.size() && homes[MtVertex::from_id(sorted_ids[j]).a] == dest) ++j;
        requests.post(dest, X, std::vector<VertexRequest>(asked.begin() + std::ptrdiff_t(i), asked.begin() + std::ptrdiff_t(j)));
        i = j;
      }
      std::vector<Face> faces(triangles.size());
      for (std::size_t f = 0; f < triangles.size(); ++f) {
        for (int c = 0; c < 3; ++c)
          faces[f].v[c] = local_of[std::size_t(std::lower_bound(ids.begin(), ids.end(), triangles[f][c]) - ids.begin())];
        faces[f].zero = zero[f];
      }
      piece_faces.post(X, X, faces);
    }, progress, nullptr);
  }
  m.forget({"piece_voxels", "piece_cells", "snaps"});

  // --- Pass 4: number each home brick's vertices -------------------------------------------------
  report(progress, "extract", 2, kStages);
  Impl::Pass number_pass{"number", outputs_of("number")};
  Mailbox &vertices = m.box("vertices"), &ranks = m.box("ranks");
  {
    const std::vector<std::uint64_t> homes = requests.destinations();
    m.run_pass(number_pass, homes, [&](std::size_t k) {
      const std::uint64_t H = homes[k];
      const std::ptrdiff_t h = m.ordinal(H);
      if (h < 0) throw std::logic_error("extract: a vertex's home brick holds no voxel");
      std::vector<VertexRequest> r = requests.collect<VertexRequest>(H);
      std::vector<std::uint64_t> code_of_a(r.size());
      for (std::size_t i = 0; i < r.size(); ++i) code_of_a[i] = home_code(VoxelKey{r[i].a});
      std::vector<std::uint32_t> order(r.size());
      std::iota(order.begin(), order.end(), 0u);
      std::sort(order.begin(), order.end(), [&](std::uint32_t p, std::uint32_t q) {
        const VertexRequest &x = r[p], &y = r[q];
        if (code_of_a[p] != code_of_a[q]) return code_of_a[p] < code_of_a[q];
        if (x.a != y.a) return x.a < y.a;
        if (x.b != y.b) return x.b < y.b;
        return x.src != y.src ? x.src < y.src : x.local < y.local;
      });
      std::vector<PlyVertex> numbered;
      std::vector<std::pair<std::uint64_t, Rank>> answers(r.size());  // (requester, answer)
      for (std::size_t i = 0; i < order.size(); ++i) {
        const VertexRequest& x = r[order[i]];
        if (i == 0 || x.a != r[order[i - 1]].a || x.b != r[order[i - 1]].b) {
          PlyVertex pv{};
          std::memcpy(pv.position, x.position, sizeof(pv.position));
          std::memcpy(pv.colour, x.colour, sizeof(pv.colour));
          pv.confidence = x.confidence;
          pv.scale = x.scale;
          numbered.push_back(pv);
        }
        answers[i] = {x.src, Rank{x.local, std::uint32_t(h), std::uint32_t(numbered.size() - 1)}};
      }
      vertices.post(H, H, numbered);
      std::stable_sort(answers.begin(), answers.end(), [](const auto& p, const auto& q) { return p.first < q.first; });
      std::vector<Rank> batch;
      for (std::size_t i = 0; i < answers.size();) {
        std::size_t j = i;
        batch.clear();
        for (; j < answers.size() && answers[j].first == answers[i].first; ++j) batch.push_back(answers[j].second);
        ranks.post(answers[i].first, H, batch);
        i = j;
      }
    }, progress, nullptr);
  }
  m.forget({"requests"});
  std::vector<std::uint64_t> base(nb + 1, 0);
  for (std::size_t i = 0; i < nb; ++i) base[i + 1] = base[i] + vertices.raw_bytes(m.bricks[i].code) / sizeof(PlyVertex);
  const std::uint64_t total_vertices = base[nb];
  if (total_vertices > std::uint64_t(std::numeric_limits<std::int32_t>::max()))
    throw InputError("extract: " + std::to_string(total_vertices) + " vertices; PLY int indices allow 2^31 - 1");

  // --- Pass 5: faces in global numbers, to the home of their smallest vertex -----------------------
  report(progress, "extract", 3, kStages);
  Impl::Pass faces_pass{"faces", outputs_of("faces")};
  Mailbox& homed_faces = m.box("homed_faces");
  {
    const std::vector<std::uint64_t> pieces = piece_faces.destinations();
    m.run_pass(faces_pass, pieces, [&](std::size_t k) {
      const std::uint64_t X = pieces[k];
      const std::vector<Rank> answers = ranks.collect<Rank>(X);
      std::vector<std::uint32_t> global(answers.size()), home(answers.size());
      for (const Rank& a : answers) {
        if (a.local >= global.size()) throw std::logic_error("extract: a vertex rank out of range");
        global[a.local] = std::uint32_t(base[a.home] + a.rank);
        home[a.local] = a.home;
      }
      std::vector<Face> faces = piece_faces.collect<Face>(X);
      std::vector<std::pair<std::uint32_t, Face>> routed(faces.size());  // (home ordinal, face)
      for (std::size_t f = 0; f < faces.size(); ++f) {
        Face g = faces[f];
        int first = 0;
        for (int c = 0; c < 3; ++c) {
          g.v[c] = global[faces[f].v[c]];
          if (g.v[c] < g.v[first]) first = c;
        }
        std::rotate(g.v, g.v + first, g.v + 3);  // smallest first, orientation kept
        routed[f] = {home[faces[f].v[first]], g};
      }
      std::stable_sort(routed.begin(), routed.end(), [](const auto& p, const auto& q) { return p.first < q.first; });
      std::vector<Face> batch;
      for (std::size_t i = 0; i < routed.size();) {
        std::size_t j = i;
        batch.clear();
        for (; j < routed.size() && routed[j].first == routed[i].first; ++j) batch.push_back(routed[j].second);
        homed_faces.post(m.bricks[routed[i].first].code, X, batch);
        i = j;
      }
    }, progress, nullptr);
  }
  m.forget({"ranks", "piece_faces"});

  // --- Pass 6: each home's faces sorted, interior zero faces cancelled ---------------------------
  Impl::Pass sort_pass{"sort", outputs_of("sort")};
  Mailbox& final_faces = m.box("final_faces");
  {
    const std::vector<std::uint64_t> homes = homed_faces.destinations();
    m.run_pass(sort_pass, homes, [&](std::size_t k) {
      std::vector<Face> faces = homed_faces.collect<Face>(homes[k]);
      // Zero faces: both copies of an interior one have the same vertex set.
      std::vector<std::pair<std::array<std::uint32_t, 3>, std::size_t>> by_set;
      for (std::size_t i = 0; i < faces.size(); ++i) {
        if (!faces[i].zero) continue;
        std::array<std::uint32_t, 3> s{faces[i].v[0], faces[i].v[1], faces[i].v[2]};
        std::sort(s.begin(), s.end());
        by_set.push_back({s, i});
      }
      std::sort(by_set.begin(), by_set.end());
      std::vector<std::uint8_t> cancelled(faces.size(), 0);
      std::uint64_t interior = 0;
      for (std::size_t i = 0; i + 1 < by_set.size(); ++i)
        if (by_set[i + 1].first == by_set[i].first) {
          cancelled[by_set[i].second] = cancelled[by_set[i + 1].second] = 1;
          ++interior;
          ++i;
        }
      std::vector<std::array<std::uint32_t, 3>> kept;
      kept.reserve(faces.size());
      for (std::size_t i = 0; i < faces.size(); ++i)
        if (!cancelled[i]) kept.push_back({faces[i].v[0], faces[i].v[1], faces[i].v[2]});
      std::sort(kept.begin(), kept.end());
      final_faces.post(homes[k], homes[k], kept);
      m.box("tally_sort").post(0, homes[k], std::vector<Tally>{{{interior}}});
    }, progress, nullptr);
  }
  m.forget({"homed_faces"});
  st.interior_zero_faces = m.sum("sort").v[0];

  // --- Pass 7: components, then the stream ---------------------------------------------------------
  report(progress, "extract", 4, kStages);
  const auto write_start = std::chrono::steady_clock::now();
  const std::size_t V = std::size_t(total_vertices);
  // remap[v]: output number of vertex v, or kGone. Vertices only cancelled zero faces used, and
  // those of small components, are dropped.
  constexpr std::uint32_t kGone = ~std::uint32_t{0};
  std::vector<std::uint32_t> remap(V, kGone);
  const std::size_t min_triangles = m.options.min_component_triangles;
  std::vector<std::uint32_t> parent;
  const auto find = [&](std::uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  std::vector<bool> big;  // by root
  if (min_triangles > 0) {
    parent.resize(V);
    std::iota(parent.begin(), parent.end(), 0u);
    for (const BrickInfo& b : m.bricks)
      for (const auto& f : final_faces.collect<std::array<std::uint32_t, 3>>(b.code)) {
        for (int c = 1; c < 3; ++c) {
          const std::uint32_t x = find(f[0]), y = find(f[c]);
          if (x != y) parent[std::max(x, y)] = std::min(x, y);
        }
      }
    std::vector<std::uint32_t>& size = remap;  // reused: triangles per root
    std::fill(size.begin(), size.end(), 0);
    for (const BrickInfo& b : m.bricks)
      for (const auto& f : final_faces.collect<std::array<std::uint32_t, 3>>(b.code)) ++size[find(f[0])];
    big.assign(V, false);
    for (std::size_t i = 0; i < V; ++i) {
      if (size[i] == 0) continue;
      if (size[i] >= min_triangles) big[i] = true;
      else {
        ++st.removed_components;
        st.removed_triangles += size[i];
      }
    }
    std::fill(remap.begin(), remap.end(), kGone);
  }
  std::size_t faces_out = 0;
  for (const BrickInfo& b : m.bricks)
    for (const auto& f : final_faces.collect<std::array<std::uint32_t, 3>>(b.code)) {
      if (min_triangles > 0 && !big[find(f[0])]) continue;
      ++faces_out;
      for (std::uint32_t x : f) remap[x] = 0;
    }
  std::vector<bool>().swap(big);
  std::vector<std::uint32_t>().swap(parent);
  std::uint32_t next = 0;
  for (auto& r : remap)
    if (r != kGone) r = next++;
  // Stopped while writing: the stream is abandoned (its temporary file goes); the passes before
  // are committed, so the resumed run writes again from here.
  const auto check_stop = [&] {
    if (m.stopping()) throw Interrupted("interrupted while writing the mesh");
  };
  check_stop();
  out.begin(next, faces_out);
  std::uint64_t at = 0;
  for (const BrickInfo& b : m.bricks) {
    check_stop();
    for (const PlyVertex& pv : vertices.collect<PlyVertex>(b.code)) {
      if (remap[at++] == kGone) continue;
      out.vertex(Eigen::Vector3f(pv.position[0], pv.position[1], pv.position[2]),
                 Rgb8{pv.colour[0], pv.colour[1], pv.colour[2]}, pv.confidence, pv.scale);
    }
  }
  // A face is kept iff its vertices are: components go whole.
  for (const BrickInfo& b : m.bricks) {
    check_stop();
    for (const auto& f : final_faces.collect<std::array<std::uint32_t, 3>>(b.code)) {
      if (remap[f[0]] == kGone) continue;
      out.face({remap[f[0]], remap[f[1]], remap[f[2]]});
    }
  }
  out.end();
  m.pass_seconds.emplace_back("write",
                              std::chrono::duration<double>(std::chrono::steady_clock::now() - write_start).count());
  st.pass_seconds = m.pass_seconds;
  st.triangles = faces_out;
  report(progress, "extract", kStages, kStages);
  st.resumed_items = m.resumed.load();
  if (stats) *stats = st;
}

}  // namespace sf
