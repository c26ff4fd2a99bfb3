#include "engine/fusion.h"

#include <sys/resource.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <filesystem>
#include <chrono>
#include <memory>
#include <mutex>
#include <sstream>

#include "engine/error.h"
#include "engine/hsdf_math.h"
#include "engine/extract/brick_extract.h"
#include "scheduler/tile_plan.h"
#include "storage/mailbox.h"

namespace sf {

void OctreeOptions::check() const {
  if (!(padding >= 0 && padding <= 1)) throw InputError("octree.padding must be in [0, 1]");
  if (brick_level < -1 || brick_level > 10) throw InputError("octree.brick_level must be -1 (auto) or in 0..10");
  if (!(brick_size >= 0)) throw InputError("octree.brick_size must be >= 0 metres (0: from octree.brick_level)");
  parse_bbox(bbox);
}

void FusionOptions::check() const {
  input.check();
  triangulate.check();
  integrate.check();
  regularize.check();
  extract.check();
  octree.check();
}

void register_parameters(ParameterSet& s, FusionOptions& o) {
  s.add("input.format", &o.input.format, "", "auto | colmap | mve | rgbd | rangegrid");
  s.add("input.colmap_maps", &o.input.colmap_maps, "", "COLMAP depth maps to read: geometric | photometric");
  s.add("input.mve_depth", &o.input.mve_depth, "", "MVE depth embedding (distance along the ray)");
  s.add("input.mve_image", &o.input.mve_image, "", "MVE colour embedding");
  s.add("input.mve_confidence", &o.input.mve_confidence, "", "MVE confidence embedding");
  s.add("input.rgbd_depth_scale", &o.input.rgbd_depth_scale, "m/unit", "metres per depth-PNG unit");
  s.add("input.rgbd_use_colour", &o.input.rgbd_use_colour, "", "colour RGB-D meshes from *.color.png|jpg");
  s.add("input.frame_step", &o.input.frame_step, "maps", "fuse every n-th depth map (1 = all)");
  // Not input.*: skipping changes no successful job's result, so a job may resume with it turned on.
  s.add("job.skip_bad", &o.input.skip_bad, "", "skip depth maps that fail to read (listed in JOB/skipped.txt)");
  s.add("triangulate.rho", &o.triangulate.rho, "footprints", "depth discontinuity threshold ρ");
  s.add("integrate.lambda", &o.integrate.lambda, "", "sampling rate λ (equation 1)");
  s.add("integrate.gamma", &o.integrate.gamma, "cells", "ramp size factor γ: ramp = γ × cell size");
  s.add("integrate.coarser_levels", &o.integrate.coarser_levels, "levels", "extra insertion into coarser levels");
  s.add("integrate.coarse_reach", &o.integrate.coarse_reach, "own ramps",
        "coarser-level ramps reach at most this many own ramps; 0 = paper (unbounded)");
  s.add("integrate.behind", &o.integrate.behind, "ramps", "length of the ramp behind the surface, fraction of γ × cell");
  s.add("integrate.min_cosine", &o.integrate.min_cosine, "", "skip triangles seen more grazing than this");
  s.add("integrate.max_level", &o.integrate.max_level, "level", "deepest octree level");
  s.add("integrate.single_level", &o.integrate.single_level, "level",
        "-1 = off; else a single-level VRIP baseline inserting every triangle at this level only");
  s.add("regularize.tau0", &o.regularize.tau0, "weight", "saturation threshold τ0 (0: no blending)");
  s.add("regularize.tau1", &o.regularize.tau1, "weight", "confidence threshold τ1 (weaker voxels are deleted)");
  s.add("extract.neighbourhood_n", &o.extract.neighbourhood_n, "voxels", "n of the neighbourhood rule (7.1)");
  s.add("extract.snap_fraction", &o.extract.snap_fraction, "edge", "vertex snapping distance (7.2); 0 = off");
  s.add("extract.min_component_triangles", &o.extract.min_component_triangles, "triangles",
        "remove connected components smaller than this; 0 = keep all");
  s.add("extract.mode", &o.extract.mode, "",
        "global: one Delaunay tetrahedralization | bricks: per brick window (same mesh) | auto: bricks if global "
        "would exceed the memory limit");
  s.add("extract.window_group_voxels", &o.extract.window_group_voxels, "voxels",
        "brick by brick: windows cover octree cells of bricks with at most this many voxels; 0 = one brick");
  s.add("extract.parallel_min_voxels", &o.extract.parallel_min_voxels, "voxels",
        "use CGAL's parallel Delaunay insertion from this many voxels (with > 1 thread)");
  s.add("octree.bbox", &o.octree.bbox, "m", "clip box xmin,ymin,zmin,xmax,ymax,zmax; empty = data bounds");
  s.add("octree.padding", &o.octree.padding, "", "root cube margin, fraction of the data extent per side");
  s.add("octree.brick_level", &o.octree.brick_level, "level",
        "2^brick_level bricks per root axis; -1 = auto (finest level - 8, in 3..10)");
  s.add("octree.brick_size", &o.octree.brick_size, "m",
        "brick edge at most this (the brick level follows, in 0..10); 0 = use octree.brick_level");
}

std::optional<Eigen::AlignedBox3d> parse_bbox(const std::string& text) {
  if (text.empty()) return std::nullopt;
  const std::vector<double> v = parse_number_list(text, 6, "octree.bbox (xmin,ymin,zmin,xmax,ymax,zmax)");
  Eigen::AlignedBox3d box(Eigen::Vector3d(v[0], v[1], v[2]), Eigen::Vector3d(v[3], v[4], v[5]));
  if (!(box.min().array() < box.max().array()).all()) throw InputError("octree.bbox: min must be < max on every axis");
  return box;
}

RootCube root_cube_for(const Eigen::AlignedBox3d& b, double padding) {
  const double extent = std::max(b.sizes().maxCoeff(), 1e-6);
  const double size = extent * (1.0 + 2.0 * padding);
  RootCube r;
  r.size = size;
  r.min = b.center() - Eigen::Vector3d::Constant(size / 2);
  return r;
}

int auto_brick_level(const RootCube& root, double finest_footprint, const IntegrateOptions& integrate) {
  const int finest = integrate.single_level >= 0
                         ? integrate.single_level
                         : triangle_level(root.size, integrate.lambda, finest_footprint, integrate.max_level);
  return std::clamp(finest - 8, 3, 10);
}

// What shapes the regularized voxels and the brick extraction's passes (not the memory budget,
// thread count or extraction mode: the result does not depend on them).
std::string extraction_signature(const FusionOptions& o, int brick_level) {
  std::ostringstream s;
  s << std::hexfloat << "tau0 " << o.regularize.tau0 << " tau1 " << o.regularize.tau1 << " n "
    << o.extract.neighbourhood_n << " snap " << o.extract.snap_fraction << " components "
    << o.extract.min_component_triangles << " bricks " << brick_level << " window groups "
    << o.extract.window_group_voxels;
  return s.str();
}

std::vector<SurfaceVoxel> surface_voxels(const std::vector<std::pair<VoxelKey, VoxelData>>& brick) {
  std::vector<SurfaceVoxel> voxels(brick.size());
  for (std::size_t i = 0; i < brick.size(); ++i) {
    const auto& [k, v] = brick[i];
    SurfaceVoxel& s = voxels[i];
    s.key = k;
    s.distance = v.distance;
    s.weight = v.weight;
    for (int c = 0; c < 3; ++c) s.colour[c] = v.colour_share > 0 ? v.colour(c) : 200.f;
  }
  return voxels;
}

std::size_t peak_rss_bytes() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return std::size_t(u.ru_maxrss) * 1024;
}

namespace {

using Clock = std::chrono::steady_clock;


void clip_to_box(DepthFrame& f, const std::optional<Eigen::AlignedBox3d>& box) {
  if (!box) return;
  for (std::size_t i = 0; i < f.size(); ++i)
    if (f.valid[i] && !box->contains(f.position[i].cast<double>())) f.valid[i] = 0;
}

// Reads a depth map's identity for the job journal.
FrameIdentity identity_of(const FrameSource& source, std::size_t index, const DepthFrame& f) {
  FrameIdentity id;
  id.name = std::filesystem::absolute(source.frame_name(index)).string();
  std::error_code ec;
  const auto size = std::filesystem::file_size(id.name, ec);
  id.file_size = ec ? 0 : std::uint64_t(size);
  id.hash = f.content_hash();
  return id;
}

template <typename T>
void sort_unique(std::vector<T>& v) {
  std::sort(v.begin(), v.end());
  v.erase(std::unique(v.begin(), v.end()), v.end());
}

// What the first pass over the input learns: each depth map's identity (for a job), the bounds
// of the valid samples, their count, and the finest footprint (each depth map's 5th percentile,
// so a few stray near samples do not count), for octree.brick_level = auto.
struct InputScan {
  std::vector<FrameIdentity> identities;
  Eigen::AlignedBox3d bounds;
  std::size_t samples = 0;
  double finest_footprint = std::numeric_limits<double>::infinity();
};

InputScan scan_input(const FrameSource& source, const std::vector<std::size_t>& frames,
                     const std::optional<Eigen::AlignedBox3d>& clip, bool identities, const ProgressFn& progress) {
  InputScan scan;
  if (identities) scan.identities.resize(frames.size());
  std::mutex mutex;
  std::size_t scanned = 0;
  tbb::parallel_for(std::size_t(0), frames.size(), [&](std::size_t i) {
    DepthFrame f = source.load(frames[i]);
    if (identities) scan.identities[i] = identity_of(source, frames[i], f);
    clip_to_box(f, clip);
    Eigen::AlignedBox3d b;
    std::vector<float> footprints;
    footprints.reserve(f.size());
    for (std::size_t k = 0; k < f.size(); ++k)
      if (f.valid[k]) {
        b.extend(f.position[k].cast<double>());
        footprints.push_back(f.footprint[k]);
      }
    const std::size_t n = footprints.size();
    double fine = std::numeric_limits<double>::infinity();
    if (n) {
      const auto at = footprints.begin() + std::ptrdiff_t(n / 20);
      std::nth_element(footprints.begin(), at, footprints.end());
      fine = *at;
    }
    std::lock_guard lock(mutex);
    if (n) scan.bounds.extend(b);
    scan.finest_footprint = std::min(scan.finest_footprint, fine);
    scan.samples += n;
    report(progress, "bounds", double(++scanned), double(frames.size()));
  });
  return scan;
}

// The brick level of a new job (see OctreeOptions).
int choose_brick_level(const OctreeOptions& o, const IntegrateOptions& integrate, const RootCube& root,
                       double finest_footprint) {
  if (o.brick_level >= 0) return o.brick_level;
  if (o.brick_size > 0) return std::clamp(int(std::ceil(std::log2(root.size / o.brick_size))), 0, 10);
  return std::isfinite(finest_footprint) ? auto_brick_level(root, finest_footprint, integrate) : 4;
}

// Where one depth map can write (FrameReach), as integration sees it (clipped to the box).
FrameReach reach_of(const DepthFrame& f, const FusionOptions& options, const RootCube& root, int brick_level,
                    IntegrateScratch* scratch) {
  return frame_reach(f, triangulate(f, options.triangulate), root, options.integrate, brick_level, scratch);
}

// The reach pass's per-depth-map tables, handed from one depth map to the next: allocated afresh,
// their page faults were half of the plan's time (7-Scenes kitchen, bench/README.md session 18).
// A pool rather than one per thread, because a thread waiting in a depth map's inner parallel
// loop may start another depth map. The integrating stage then takes its tables from the same
// pool, so that they too are memory already faulted in (the plan's largest tables, kept by
// trim(1)), not as much again freshly zeroed.
class ScratchPool {
 public:
  // Frees all but the `keep` largest tables.
  void trim(std::size_t keep) {
    std::lock_guard lock(mutex_);
    std::sort(free_.begin(), free_.end(), [](const auto& a, const auto& b) { return a->bytes() > b->bytes(); });
    if (free_.size() > keep) free_.resize(keep);
  }
  std::unique_ptr<IntegrateScratch> take() {
    std::lock_guard lock(mutex_);
    if (free_.empty()) return std::make_unique<IntegrateScratch>();
    std::unique_ptr<IntegrateScratch> s = std::move(free_.back());
    free_.pop_back();
    return s;
  }
  void give_back(std::unique_ptr<IntegrateScratch> s) {
    std::lock_guard lock(mutex_);
    free_.push_back(std::move(s));
  }

 private:
  std::mutex mutex_;
  std::vector<std::unique_ptr<IntegrateScratch>> free_;
};

// The reach of depth maps [0, n) (load(i) gives the i-th as integration sees it), restricted to
// `region` when given: per depth map its bricks, and the surface cells of all, sorted and unique.
struct Reaches {
  std::vector<std::vector<std::uint64_t>> bricks;
  std::vector<VoxelKey> cells;
  std::vector<std::uint64_t> touched() const {  // every brick reached, sorted, unique
    std::vector<std::uint64_t> all;
    for (const auto& b : bricks) all.insert(all.end(), b.begin(), b.end());
    sort_unique(all);
    return all;
  }
};

template <typename LoadFrame>
Reaches gather_reaches(std::size_t n, LoadFrame&& load, const FusionOptions& options, const RootCube& root,
                       int brick_level, const BrickBox* region, const ProgressFn& progress, ScratchPool& scratches) {
  Reaches out;
  out.bricks.resize(n);
  std::size_t cells_unique = 0, planned = 0;
  std::mutex mutex;
  tbb::parallel_for(std::size_t(0), n, [&](std::size_t i) {
    std::unique_ptr<IntegrateScratch> scratch = scratches.take();
    FrameReach r = reach_of(load(i), options, root, brick_level, scratch.get());
    scratches.give_back(std::move(scratch));
    if (region) {  // a cluster tile's run: only its bricks matter
      const auto outside = [&](std::uint64_t id) { return !region->contains(BrickCoord::unpack(id)); };
      r.bricks.erase(std::remove_if(r.bricks.begin(), r.bricks.end(), outside), r.bricks.end());
      r.cells.erase(std::remove_if(r.cells.begin(), r.cells.end(),
                                   [&](VoxelKey k) { return !region->contains(brick_of(k, brick_level)); }),
                    r.cells.end());
    }
    out.bricks[i] = std::move(r.bricks);
    std::lock_guard lock(mutex);
    out.cells.insert(out.cells.end(), r.cells.begin(), r.cells.end());
    // Overlapping views share most cells: merge as they come, so the list stays near the number
    // of distinct cells rather than their sum over depth maps.
    if (out.cells.size() > 2 * cells_unique + (std::size_t{1} << 20)) {
      sort_unique(out.cells);
      cells_unique = out.cells.size();
    }
    report(progress, "plan", double(++planned), double(n));
  });
  sort_unique(out.cells);
  return out;
}

// Per tile, the positions i (in order) of the depth maps whose reach meets it, given as ids[i].
std::vector<std::vector<std::size_t>> frames_per_tile(const std::vector<BrickBox>& tiles, const Reaches& reach,
                                                      const std::vector<std::size_t>& ids) {
  std::vector<std::vector<std::size_t>> out(tiles.size());
  std::vector<char> meets(tiles.size());
  for (std::size_t i = 0; i < reach.bricks.size(); ++i) {
    std::fill(meets.begin(), meets.end(), 0);
    for (std::uint64_t id : reach.bricks[i]) {
      const std::size_t t = tile_of(tiles, BrickCoord::unpack(id));
      if (t == tiles.size()) throw std::logic_error("a brick a depth map reaches lies in no tile of the plan");
      meets[t] = 1;
    }
    for (std::size_t t = 0; t < tiles.size(); ++t)
      if (meets[t]) out[t].push_back(ids[i]);
  }
  return out;
}

// The plan of a sweep over depth maps [from, to) (scheduler/tile_plan.h): each depth map's reach
// and surface cells; unless `progress` carries the job's recorded plan, new tiles cut from the
// estimated field (recorded in `progress`); returns, per tile, the depth maps whose reach meets
// it, in input order.
template <typename LoadFrame>
std::vector<std::vector<std::size_t>> plan_sweep(std::size_t from, std::size_t to, LoadFrame&& load_frame,
                                                 const FusionOptions& options, const RootCube& root, const BrickMap& map,
                                                 const ProgressFn& progress_fn, IntegrationProgress& progress,
                                                 FusionStats& stats, const BrickBox* region,
                                                 std::vector<BrickBox>* reach_boxes, ScratchPool& scratches) {
  const int brick_level = map.brick_level();
  const Reaches reach = gather_reaches(
      to - from, [&](std::size_t i) { return load_frame(from + i); }, options, root, brick_level, region, progress_fn,
      scratches);
  if (!progress.sweeping()) {
    // 70% of the limit per tile: the estimate is within about 25% on the scenes measured, and the
    // depth maps in flight need room (the cache spills if a tile outgrows it anyway).
    const auto estimate =
        estimate_brick_bytes(reach.cells, brick_level, options.integrate, map.field_bytes(), reach.touched());
    stats.plan_estimate_bytes = 0;
    for (const auto& e : estimate) stats.plan_estimate_bytes += e.second;
    progress.tiles = cut_tiles(estimate, brick_level, 0.7 * double(map.memory_limit()), region);
    progress.tile = progress.tile_frames = progress.steps = 0;
  }
  reach_boxes->assign(to - from, BrickBox{});
  for (std::size_t i = 0; i < reach.bricks.size(); ++i) {
    BrickBox& box = (*reach_boxes)[i];
    for (const auto packed : reach.bricks[i]) box.extend(BrickCoord::unpack(packed));
  }
  std::vector<std::size_t> ids(to - from);
  for (std::size_t i = 0; i < ids.size(); ++i) ids[i] = from + i;
  return frames_per_tile(progress.tiles, reach, ids);
}

}  // namespace

FusionPlan plan_fusion(const FrameSource& source, const FusionOptions& options, std::size_t n_tiles,
                       const ProgressFn& progress) {
  options.check();
  if (n_tiles == 0) throw InputError("a plan needs at least one tile");
  FusionPlan plan;
  const std::size_t step = std::size_t(options.input.frame_step);
  for (std::size_t i = 0; i < source.size(); i += step) plan.frames.push_back(i);
  const auto clip = parse_bbox(options.octree.bbox);
  InputScan scan = scan_input(source, plan.frames, clip, true, progress);
  if (scan.samples == 0)
    throw InputError("the input holds no valid depth samples" + std::string(clip ? " inside octree.bbox" : ""));
  plan.identities = std::move(scan.identities);
  plan.samples = scan.samples;
  // As fuse() chooses them for a new job.
  plan.root = clip ? root_cube_for(*clip, 0.0) : root_cube_for(scan.bounds, options.octree.padding);
  plan.brick_level = choose_brick_level(options.octree, options.integrate, plan.root, scan.finest_footprint);

  // Each depth map's reach; the field's bytes per brick estimated from the surface cells (the
  // work of every later stage grows with them).
  ScratchPool scratches;
  const Reaches reach = gather_reaches(
      plan.frames.size(),
      [&](std::size_t i) {
        DepthFrame f = source.load(plan.frames[i]);
        clip_to_box(f, clip);
        return f;
      },
      options, plan.root, plan.brick_level, nullptr, progress, scratches);
  const auto estimate = estimate_brick_bytes(reach.cells, plan.brick_level, options.integrate, {}, reach.touched());
  plan.tiles = split_tiles(estimate, plan.brick_level, n_tiles);
  plan.work.assign(plan.tiles.size(), 0.0);
  for (const auto& [c, bytes] : estimate) plan.work[tile_of(plan.tiles, c)] += bytes;
  plan.tile_frames = frames_per_tile(plan.tiles, reach, plan.frames);
  return plan;
}

Mesh fuse(const FrameSource& source, const FusionOptions& options, const FusionHooks& hooks, FusionStats* stats_out,
          FusionJournal* journal) {
  options.check();
  FusionStats stats;
  const std::size_t step = std::size_t(options.input.frame_step);
  const auto clip = parse_bbox(options.octree.bbox);
  auto stage_start = Clock::now();
  auto end_stage = [&](const char* name) {
    const auto now = Clock::now();
    stats.times.push_back({name, std::chrono::duration<double>(now - stage_start).count()});
    stage_start = now;
  };
  // Following a folder that holds nothing yet: wait for its first depth map.
  if (hooks.follow && source.size() == 0 && !hooks.follow->wait_for_more(0))
    throw InputError("the followed input received no complete depth map before the feed ended");
  stats.format = source.format();
  // The depth maps to fuse, in input order (grows while following).
  std::vector<std::size_t> frames;
  std::size_t source_seen = 0;  // source indices [0, source_seen) are in `frames` or skipped by frame_step
  auto take_new_frames = [&] {
    const std::size_t n = source.size();
    for (; source_seen < n; ++source_seen)
      if (source_seen % step == 0) frames.push_back(source_seen);
  };
  if (hooks.frames) {  // a cluster tile's run: the plan's depth maps for the tile
    if (hooks.follow) throw std::logic_error("fuse: FusionHooks::frames and follow exclude each other");
    for (std::size_t i : *hooks.frames)
      if (i >= source.size()) throw InputError("the plan names depth map " + std::to_string(i) + " of an input of " +
                                               std::to_string(source.size()));
    frames = *hooks.frames;
    source_seen = source.size();
  } else {
    take_new_frames();
  }

  // Pass 1: bounds of the data, so the root cube is no larger than the data needs, and each depth
  // map's identity for the job.
  InputScan scan = scan_input(source, frames, clip, journal != nullptr, hooks.progress);
  std::vector<FrameIdentity>& identities = scan.identities;
  const std::size_t samples = scan.samples;
  const double finest_footprint = scan.finest_footprint;
  const Eigen::AlignedBox3d& bounds = scan.bounds;
  if (samples == 0 && !hooks.follow)
    throw InputError("the input holds no valid depth samples" + std::string(clip ? " inside octree.bbox" : ""));
  if (samples == 0 && !clip)
    throw InputError("the followed input's first depth maps hold no valid samples: give octree.bbox (--bbox)");
  stats.samples = samples;
  const std::optional<RootCube> job_root = journal ? journal->fixed_root() : std::nullopt;
  const RootCube root =
      job_root ? *job_root : (clip ? root_cube_for(*clip, 0.0) : root_cube_for(bounds, options.octree.padding));
  stats.root = root;
  // While following, later depth maps may reach past the root cube fixed now: clip them to it.
  const Eigen::AlignedBox3d root_box(root.min, root.min + Eigen::Vector3d::Constant(root.size));
  end_stage("bounds");

  // Pass 2: integration in sweeps (scheduler/tile_plan.h): one over the depth maps present, then
  // (following) one per growth of the source. A sweep plans tiles whose fields fit the memory
  // budget, then streams each tile's depth maps through read -> triangulate (parallel) ->
  // integrate into the tile's bricks (in order).
  std::optional<int> job_brick_level = journal ? journal->fixed_brick_level() : std::nullopt;
  const int brick_level =
      job_brick_level ? *job_brick_level : choose_brick_level(options.octree, options.integrate, root, finest_footprint);
  stats.brick_level = brick_level;
  BrickMap map(brick_level);
  IntegrationProgress progress = journal ? journal->begin(identities, root, map) : IntegrationProgress{};
  if (progress.sweep_end > frames.size()) throw std::logic_error("journal reports more depth maps than the input has");
  stats.resumed_at = progress.integrated + progress.steps;
  const std::size_t initial_frames = frames.size();
  std::size_t outside = 0, late_samples = 0;
  std::atomic<std::size_t> reads{0};
  // A depth map as integration sees it: clipped to the box, and (arrived while following) to the
  // root cube fixed at the start.
  struct LateSamples {
    std::size_t outside = 0, kept = 0;
  };
  auto load_frame = [&](std::size_t i, LateSamples* late) {
    DepthFrame f = source.load(frames[i]);
    ++reads;
    clip_to_box(f, clip);
    if (i >= initial_frames) {
      const std::size_t before = f.valid_count();
      clip_to_box(f, root_box);
      late->kept = f.valid_count();
      late->outside = before - late->kept;
    }
    return f;
  };
  struct Item {
    std::size_t index = 0;
    DepthFrame frame;
    std::vector<FrameTriangle> triangles;
    LateSamples late;
    std::unique_ptr<Item>* slot = nullptr;  // the pipeline slot that owns this item
  };
  std::size_t item_bytes_max = 0;  // the largest depth map in flight so far (serial stage only)
  auto item_bytes = [](const Item& item) {
    return item.frame.memory_bytes() + item.triangles.capacity() * sizeof(FrameTriangle);
  };
  IntegrateStats integ;
  ScratchPool scratches;  // the plan's tables, and the integrating stage's
  std::unique_ptr<IntegrateScratch> tables;  // the integrating stage's, reused depth map after depth map
  const std::size_t tokens = std::size_t(std::max(2, 2 * tbb::this_task_arena::max_concurrency()));
  const std::atomic<bool>* stop = hooks.follow ? nullptr : hooks.stop;
  bool stopped = false;
  double plan_seconds = 0;
  for (;;) {
    // A sweep: the one under way in the job, else one over every depth map not yet integrated.
    const std::size_t from = progress.integrated, to = progress.sweeping() ? progress.sweep_end : frames.size();
    if (from < to) {
      // Which depth maps reach which tile. Without a tile store (no job) the whole field is one tile.
      std::vector<std::vector<std::size_t>> tile_frames;
      std::vector<char> counted(to - from, 0);  // triangles counted once per depth map
      if (!map.spills()) {
        progress.tiles = {hooks.region ? *hooks.region : BrickBox::whole(brick_level)};
        tile_frames.resize(1);
        for (std::size_t i = from; i < to; ++i) tile_frames[0].push_back(i);
      } else {
        const auto plan_start = Clock::now();
        std::vector<BrickBox> reach_boxes;
        if (tables) scratches.give_back(std::move(tables));
        tile_frames = plan_sweep(
            from, to, [&](std::size_t i) {
              LateSamples late;
              return load_frame(i, &late);
            },
            options, root, map, hooks.progress, progress, stats, hooks.region, &reach_boxes, scratches);
        scratches.trim(1);
        if (journal) journal->reached(from, reach_boxes);
        plan_seconds += std::chrono::duration<double>(Clock::now() - plan_start).count();
      }
      if (!tables) tables = scratches.take();
      progress.sweep_end = to;
      stats.tiles = progress.tiles.size();
      std::size_t total_steps = 0;
      for (const auto& list : tile_frames) total_steps += list.size();
      const bool one_tile = progress.tiles.size() == 1;
      for (; progress.tile < progress.tiles.size() && !stopped; ++progress.tile, progress.tile_frames = 0) {
        const std::vector<std::size_t>& list = tile_frames[progress.tile];
        const BrickBox* region = one_tile ? hooks.region : &progress.tiles[progress.tile];
        std::size_t next = progress.tile_frames;
        // The pipeline's tokens are plain pointers into slots this loop owns: oneTBB 2021 does not
        // destroy objects still in flight when a stage throws (ASan saw whole depth maps leak on a
        // full disk), so ownership stays here. At most `tokens` items are alive, and item k's slot
        // is freed by the last stage before token k + tokens can be issued.
        std::vector<std::unique_ptr<Item>> slots(tokens);
        std::size_t issued = 0;
        tbb::parallel_pipeline(
            tokens,
            tbb::make_filter<void, Item*>(tbb::filter_mode::serial_in_order,
                                          [&](tbb::flow_control& fc) -> Item* {
                                            if (next >= list.size() || (stop && stop->load())) {
                                              fc.stop();
                                              return nullptr;
                                            }
                                            std::unique_ptr<Item>& slot = slots[issued++ % tokens];
                                            slot = std::make_unique<Item>();
                                            slot->index = list[next++];
                                            slot->slot = &slot;
                                            return slot.get();
                                          }) &
                tbb::make_filter<Item*, Item*>(tbb::filter_mode::parallel,
                                               [&](Item* item) {
                                                 item->frame = load_frame(item->index, &item->late);
                                                 item->triangles = triangulate(item->frame, options.triangulate);
                                                 return item;
                                               }) &
                tbb::make_filter<Item*, void>(tbb::filter_mode::serial_in_order, [&](Item* item) {
                  // Frees the slot however this stage ends.
                  const std::unique_ptr<Item> owned = std::move(*item->slot);
                  // Depth maps enter the field strictly in index order (equations 2-3 are
                  // order-sensitive in floating point).
                  map.next_epoch();
                  // The memory limit covers the depth maps in flight too: each holds a frame and its
                  // triangles, and integration builds tables about as large again for the one it runs.
                  item_bytes_max = std::max(item_bytes_max, item_bytes(*item));
                  map.set_reserve((tokens + 1) * item_bytes_max);
                  IntegrateStats s =
                      integrate_frame(item->frame, item->triangles, root, options.integrate, map, region, tables.get());
                  char& first_time = counted[item->index - from];
                  if (first_time == 0) {
                    outside += item->late.outside;
                    late_samples += item->late.kept;
                  } else {
                    s.triangles = 0;
                    std::fill(std::begin(s.triangles_per_level), std::end(s.triangles_per_level), 0);
                  }
                  first_time = 1;
                  integ.add(s);
                  ++progress.tile_frames;
                  ++progress.steps;
                  ++stats.sweep_steps;
                  if (journal) journal->step_done(progress, map);
                  report(hooks.progress, "integrate", double(progress.steps), double(total_steps));
                }));
        if (progress.tile_frames < list.size()) {
          stopped = true;
          break;
        }
        // The tile is complete; no later tile of the sweep touches its bricks.
        if (map.spills() && !one_tile) {
          map.spill_all();
          IntegrationProgress next = progress;
          ++next.tile;
          next.tile_frames = 0;
          if (journal) journal->tile_done(next, map);
        }
      }
      if (stopped) break;
      progress.integrated = to;
      progress.tiles.clear();
      progress.tile = progress.tile_frames = progress.steps = 0;
      continue;  // a sweep recorded by the job may end before the input does
    }
    if (!hooks.follow || !hooks.follow->wait_for_more(source.size())) break;
    const std::size_t grown_from = frames.size();
    take_new_frames();
    if (journal) {
      identities.resize(frames.size());
      tbb::parallel_for(grown_from, frames.size(), [&](std::size_t i) {
        identities[i] = identity_of(source, frames[i], source.load(frames[i]));
      });
      journal->inputs_added(identities, grown_from);
    }
  }
  if (stopped) {
    if (journal) journal->interrupted(progress, map);
    if (progress.tiles.size() == 1)
      throw Interrupted("interrupted after " + std::to_string(progress.whole_frames()) + " of " +
                        std::to_string(frames.size()) + " depth maps");
    throw Interrupted("interrupted in tile " + std::to_string(progress.tile + 1) + " of " +
                      std::to_string(progress.tiles.size()) + " (" + std::to_string(progress.integrated) + " of " +
                      std::to_string(frames.size()) + " depth maps in every tile)");
  }
  tables.reset();  // extraction has no use for them
  scratches.trim(0);
  stats.frame_reads = reads.load();
  for (const auto& [c, bytes] : map.field_bytes()) stats.field_bytes += bytes;
  stats.depth_maps = frames.size();
  stats.samples += late_samples;
  stats.samples_outside_root = outside;
  if (journal) journal->integrated(progress, map);
  stats.peak_rss_integrate_bytes = peak_rss_bytes();
  stats.spill = map.spill_stats();
  stats.triangles = integ.triangles;
  stats.contributions = integ.contributions;
  for (int l = 0; l <= kMaxLevel; ++l) stats.triangles_per_level[l] = integ.triangles_per_level[l];
  // The plan passes ran inside the integration's time: report them apart.
  stats.times.push_back({"plan", plan_seconds});
  end_stage("integrate");
  stats.times.back().seconds -= plan_seconds;
  if (hooks.integrated) hooks.integrated();
  if (hooks.stop_after_integration) {
    if (hooks.count_fused_voxels) stats.voxels_fused = map.live_voxels_per_level();  // brick by brick, within the budget
    stats.peak_rss_bytes = peak_rss_bytes();
    if (stats_out) *stats_out = stats;
    return Mesh{};
  }
  // Brick by brick: the raw field is never in memory at once. The survivors go to the brick
  // extraction's scratch files as each brick is regularized; the global path (when they are few
  // enough) reads them back. A job keeps a record of both, so that a killed run resumes brick by
  // brick: regularization skips the bricks already handed over, extraction the bricks each of
  // its passes finished.
  std::optional<ScratchFolder> temporary;
  if (hooks.scratch.empty()) temporary.emplace("scalefuse-extract");
  const std::filesystem::path scratch = hooks.scratch.empty() ? temporary->path() : hooks.scratch;
  const std::size_t limit = map.memory_limit();
  ExtractJournal* extract_journal =
      journal && !hooks.scratch.empty() ? journal->extraction(extraction_signature(options, map.brick_level()), scratch)
                                        : nullptr;
  BrickExtraction bricks(scratch, root, map.brick_level(), options.extract, limit > 0 ? limit : std::size_t{1} << 30,
                         extract_journal);
  // From here a stop request (a signal) ends the run at the next brick: the extraction's record
  // keeps what finished (the integration is checkpointed already).
  const std::atomic<bool>* extract_stop = hooks.stop;
  const auto stopping = [&] { return extract_stop && extract_stop->load(); };
  bricks.set_stop(extract_stop);
  if (!bricks.all_added_before()) {
    std::atomic<bool> stopped_here{false};
    stats.regularize = regularize_bricks(
        map, options.regularize, hooks.progress,
        [&](BrickCoord coord, std::vector<std::pair<VoxelKey, VoxelData>>&& brick) {
          bricks.add(coord.packed(), surface_voxels(brick));
        },
        [&](BrickCoord coord) {
          if (bricks.added_before(coord.packed())) return true;
          if (!stopping()) return false;
          stopped_here = true;
          return true;
        });
    if (stopped_here) {
      bricks.commit_added();
      throw Interrupted("interrupted in regularization");
    }
    bricks.all_added();
  }
  map.clear();  // release the field before the tetrahedralization
  for (int l = 0; l <= kMaxLevel; ++l) {
    stats.voxels_fused[l] = stats.regularize.voxels_before[l];
    stats.voxels_regularized[l] = stats.regularize.voxels_after[l];
  }
  end_stage("regularize");
  stats.peak_rss_regularize_bytes = peak_rss_bytes();
  const std::size_t survivors = bricks.size();
  if (survivors < 4) throw InputError("too few confident voxels to extract a surface (" + std::to_string(survivors) + ")");
  const bool too_big = limit > 0 && survivors * kDelaunayBytesPerVoxel > limit;
  const bool by_brick = options.extract.mode == "bricks" || (options.extract.mode == "auto" && too_big);
  MeshCollector collected;
  MeshStream& out = hooks.mesh_out ? *hooks.mesh_out : collected;
  if (hooks.on_regularized || !by_brick) {
    std::vector<SurfaceVoxel> voxels = bricks.voxels();
    std::sort(voxels.begin(), voxels.end(), [](const SurfaceVoxel& a, const SurfaceVoxel& b) { return a.key < b.key; });
    if (hooks.on_regularized) {
      hooks.on_regularized(voxels, root);
      end_stage("export");
    }
    if (!by_brick) {
      // One tetrahedralization cannot stop part way: the request is honoured before and after it.
      if (stopping()) throw Interrupted("interrupted before the extraction");
      ExtractOptions extract = options.extract;
      extract.brick_level = -1;
      const Mesh mesh = extract_surface(voxels, root, extract, hooks.progress, &stats.extract);
      std::vector<SurfaceVoxel>().swap(voxels);
      if (stopping()) throw Interrupted("interrupted before writing the mesh");
      stream_mesh(mesh, out);
    }
  }
  if (by_brick) bricks.run(out, hooks.progress, &stats.extract);
  end_stage("extract");
  stats.peak_rss_bytes = peak_rss_bytes();
  if (stats_out) *stats_out = stats;
  return std::move(collected.mesh);
}

}  // namespace sf
