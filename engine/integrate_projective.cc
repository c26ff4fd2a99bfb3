// Voxel-centric insertion of a perspective depth map (section 5), the fast path of integration.
//
// The prism enumeration (integrate.cc) pays a set-up per triangle and level; at coarser levels a
// triangle reaches a voxel or two, so that set-up dominates. Here the image is cut into tiles of
// kTile x kTile pixel quads. For each tile and level, the voxels that can receive anything lie in
// the tile's frustum between the nearest and farthest camera depth of its triangles, widened by
// their ramps (a voxel at ray distance d from a triangle differs from it in camera depth by at
// most |d|). Each such voxel is projected into the image; the pixel quad it falls in holds the
// (at most two) triangles that may own its line of sight, and ownership is decided by the same
// edge functions as in the prism path. A voxel belongs to the tile of its quad, so every voxel is
// evaluated once per level and depth map; ownership gives it at most one contribution, so tiles
// write their voxels concurrently without locks (groups of blocks are created under their brick's
// lock, blocks by a compare-and-swap in their group: storage/voxel_table.h).
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <functional>
#include <limits>
#include <memory>

#include "engine/integrate.h"
#include "engine/integrate_kernel.h"

namespace sf {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;
using namespace integrate_detail;

// Pixel quads per tile side. Smaller tiles have thinner slabs where a tile straddles a depth step
// (far views of a city: 2.9 candidates per contribution with 8, 1.67 with 4) for more items.
constexpr int kTile = 4;

// What the kernel reads of a triangle once it owns a voxel. Its ownership is not here: the quad
// holds it as a shape (below). One cache line, so that the owner costs one load.
// No member initializers (ScratchArray): prepare writes each field before anything reads it,
// `normal` and `P0` only where `ok`.
struct alignas(64) GridTriangle {
  Vector3d normal;     // unit, facing the sensor
  Eigen::Vector3f P0;  // the first vertex, as the frame stores it
  std::uint32_t idx[3];
  std::int8_t level;  // level of equation 1; -1: not inserted
  std::int8_t coarsest;
  bool ok;  // non-degenerate (inserted with contributions), in a quad this call evaluates
};

// A per-frame table whose elements prepare writes before anything reads them, kept from depth map
// to depth map. Unlike std::vector::resize, resize() keeps nothing: past the capacity it discards
// the contents and leaves the new elements unset, where a std::vector would write each one (a
// 640 x 480 depth map after a 160 x 120 one: 36 MB of triangle records set only to be set again).
template <typename T>
class ScratchArray {
 public:
  void resize(std::size_t n) {
    if (n > capacity_) {
      data_ = std::make_unique_for_overwrite<T[]>(n);
      capacity_ = n;
    }
    size_ = n;
  }
  T& operator[](std::size_t i) { return data_[i]; }
  const T& operator[](std::size_t i) const { return data_[i]; }
  const T* data() const { return data_.get(); }
  std::size_t size() const { return size_; }
  std::size_t capacity() const { return capacity_; }
  bool empty() const { return size_ == 0; }

 private:
  std::unique_ptr<T[]> data_;
  std::size_t size_ = 0, capacity_ = 0;
};

// A triangle of a pixel quad by its corners: vertex k at corner `(code >> 2k) & 3`, corners
// numbered 0 top left, 1 top right, 2 bottom left, 3 bottom right, which is also their samples'
// index order. Its ownership is set up once, in the quad at (0, 0): starts at 0.5 or 1.5,
// directions of -1, 0 or 1 per axis, opposite-vertex values of -1 or 1, all exact, so
// Ownership::owns moved by the quad's (column, row) gives the bits the triangle's own vertices
// would: the owner test needs only the quad, not the triangle's record.
struct QuadShapes {
  Ownership shape[64];  // by code; codes whose corners repeat are never used
  QuadShapes() {
    for (int code = 0; code < 64; ++code) {
      Eigen::Vector2f q[3];
      std::uint32_t idx[3];
      for (int k = 0; k < 3; ++k) {
        const int corner = (code >> (2 * k)) & 3;
        q[k] = Eigen::Vector2f(float(corner & 1) + 0.5f, float(corner >> 1) + 0.5f);
        idx[k] = std::uint32_t(corner);
      }
      if (idx[0] == idx[1] || idx[1] == idx[2] || idx[0] == idx[2] || !shape[code].init(q, idx)) shape[code] = Ownership{};
    }
  }
};

// Bounds of one tile's prisms at one level: camera depth, and offset along the tile's mean
// normal (for a tilted surface the depth range of a tile exceeds its ramp many times over, while
// its prisms stay within a slab about 2 ramps thick along the normal).
struct TileLevel {
  double zmin = std::numeric_limits<double>::infinity(), zmax = -std::numeric_limits<double>::infinity();
  double smin = std::numeric_limits<double>::infinity(), smax = -std::numeric_limits<double>::infinity();
  double ramp = 0;
};

// The triangles of one pixel quad. With two, `dx, dy` (each +-1) point from the second's vertex
// off the shared diagonal to the first's: a point q of the quad lies in the first iff
// (q - quad centre) . (dx, dy) > 0, a cheap guess that the exact edge-function test then confirms.
struct Quad {
  std::int32_t tri[2] = {-1, -1};
  std::int8_t dx = 0, dy = 0;
  // Per slot: the triangle's shape code (QuadShapes), plus kUsable once it can own voxels.
  std::uint8_t shape[2] = {0, 0};
  static constexpr std::uint8_t kUsable = 64;
  // kSplit if the quad is split along a diagonal into two usable triangles; then bits 0-1 hold
  // the diagonal's edge index in the first triangle's shape, and kPositive its side of it.
  std::uint8_t split = 0;
  static constexpr std::uint8_t kSplit = 8, kPositive = 4;
};

// floor() without a libm call (baseline x86-64 has no rounding instruction); |x| < 2^31.
inline int fast_floor(double x) {
  const int i = int(x);
  return i - (double(i) > x ? 1 : 0);
}

// Where the voxel at place t (x fastest) of a tile block lies in its group when the group is one
// block (coarse levels): block 0, place t (the counterpart of kTileToGroup).
constexpr std::array<std::uint8_t, 64> kSamePlace = [] {
  std::array<std::uint8_t, 64> t{};
  for (int q = 0; q < 64; ++q) t[q] = std::uint8_t(q);
  return t;
}();

// Per-task cache of recently written groups of blocks (direct mapped), so that the brick lock and
// the block index are consulted once per 4^3 region rather than once per voxel.
class BlockCache {
 public:
  // A cache lives in one task, so on one thread: its index picks the arena cursor blocks are
  // carved with (VoxelTable::make_part_shared).
  explicit BlockCache(BrickMap& map)
      : map_(map), thread_(unsigned(std::max(tbb::this_task_arena::current_thread_index(), 0))) {}
  // The group with origin `origin` (a tile block's: aligned_origin); `brick` is set to its brick.
  // The hit is the common case (95 % of lookups at igea's level 11) and stays inline.
  BlockGroup* group(VoxelKey origin, Brick** brick) {
    // A multiplicative hash's top bits (the table's 64-bit mix cost more than the rare
    // collisions this lets through).
    Entry& e = slots_[(origin.bits * 0x9e3779b97f4a7c15ull) >> (64 - kSlotBits)];
    if (__builtin_expect(!e.group || e.origin != origin, 0)) fetch(e, origin);
    *brick = e.brick;
    return e.group;
  }
  // Block `part` (edge 2^log) of `g`, a group of `brick`, made if absent.
  VoxelData* part(Brick& brick, BlockGroup& g, int part, int log) { return map_.part(brick, g, part, log, thread_); }

 private:
  struct Entry {
    VoxelKey origin;
    BlockGroup* group = nullptr;
    Brick* brick = nullptr;
  };
  [[gnu::noinline]] void fetch(Entry& e, VoxelKey origin) {
    // The brick too is mostly the one of the group before: its lookup (a shared lock and a
    // hash map) was a third of a group's fetch.
    const std::uint64_t brick_id = brick_of(origin, map_.brick_level()).packed();
    if (brick_id != brick_id_) {
      brick_ = &map_.brick(BrickCoord::unpack(brick_id));
      brick_id_ = brick_id;
    }
    e.group = map_.group(*brick_, origin);  // may throw (a damaged tile): the entry is set after
    e.brick = brick_;
    e.origin = origin;
  }
  static constexpr int kSlotBits = 8;
  static constexpr std::size_t kSlots = std::size_t{1} << kSlotBits;
  BrickMap& map_;
  const unsigned thread_;
  std::uint64_t brick_id_ = ~std::uint64_t{0};  // the brick of the last group fetched (no brick has this id)
  Brick* brick_ = nullptr;
  Entry slots_[kSlots];
};

struct HalfSpace {  // m . X >= k
  Vector3d m;
  double k;
};

// Sample i lies at row r, column c.
bool is_pixel_centre(const DepthFrame& f, std::uint32_t i, int r, int c) {
  const Eigen::Vector2f& p = f.image_pos[i];
  return p.x() == float(c) + 0.5f && p.y() == float(r) + 0.5f;
}

// Whether exactly the valid samples lie at their pixel centres (as fill_perspective_samples
// leaves them: an invalid sample's image position is zero). Then is_pixel_centre is the sample's
// validity, a byte, and prepare checks each frame's positions once instead of each triangle's
// three vertices' (every sample is a vertex of up to six triangles).
bool centred_where_valid(const DepthFrame& f) {
  if (f.image_pos.size() != f.size() || f.valid.size() != f.size()) return false;
  for (int r = 0; r < f.height; ++r) {
    const std::uint32_t row = std::uint32_t(r) * std::uint32_t(f.width);
    bool same = true;  // no early exit within a row, so that the loop has no unpredictable branch
    for (int c = 0; c < f.width; ++c) same &= is_pixel_centre(f, row + std::uint32_t(c), r, c) == (f.valid[row + c] != 0);
    if (!same) return false;
  }
  return true;
}

// The brick holding world position X (clamped to the grid).
BrickCoord brick_at(const RootCube& root, int brick_level, const Vector3d& X) {
  const double bs = root.cell_size(brick_level);
  const std::int64_t last = (std::int64_t{1} << brick_level) - 1;
  std::uint32_t c[3];
  for (int a = 0; a < 3; ++a)
    c[a] = std::uint32_t(std::clamp<std::int64_t>(std::int64_t(std::floor((X[a] - root.min[a]) / bs)), 0, last));
  return BrickCoord{c[0], c[1], c[2]};
}

constexpr int L = kMaxLevel + 1;  // levels a key allows

// A perspective depth map prepared for voxel-centric insertion: its pixel quads, triangles, and
// per (tile, level) the bounds of the prisms inserted there.
struct Prepared {
  const DepthFrame* frame = nullptr;
  int QW = 0, QH = 0, TX = 0, TY = 0;
  std::vector<Quad> quad;
  ScratchArray<GridTriangle> tris;
  QuadShapes shapes;
  // Per tile, the bounds at each level some triangle of the frame is inserted at: [level0,
  // level0 + levels), about 5 of the 19 a key allows (the table is written for every read of a
  // frame).
  std::vector<TileLevel> tile_levels;
  int level0 = 0, levels = 0;
  TileLevel& tile_level(int tile, int level) { return tile_levels[std::size_t(tile) * levels + (level - level0)]; }
  const TileLevel& tile_level(int tile, int level) const {
    return tile_levels[std::size_t(tile) * levels + (level - level0)];
  }
  std::vector<Vector3d> tile_normal;
  // Per sample (a vertex of up to six triangles, each in the bounds of up to four tiles): camera
  // depth and unit line of sight, computed once rather than per triangle and tile.
  ScratchArray<double> depth;
  ScratchArray<Vector3d> sight;
  ScratchArray<std::uint32_t> colour;  // per sample, packed_colour; empty if the frame has none
  double behind = 1;  // IntegrateOptions::behind
  double ramp[L][L];  // insertion_ramp by [level of the triangle][insertion level <= it]
  // What item_frustum needs of a tile's column (its u range) or row (v range), the same for every
  // level and for every tile of that column or row: the two side planes of its frustum in world
  // coordinates, and (u - cx) / fx at both ends and at the middle. Set per frame, so that an
  // item evaluates none of it.
  struct FrustumSide {
    HalfSpace side[2];  // low end, high end
    double ray[3];      // low end, high end, middle
  };
  std::vector<FrustumSide> column_side, row_side;
  Eigen::Matrix3d Rt;  // the sensor's rotation, transposed
  Vector3d centre;     // the sensor's centre
  IntegrateStats stats;  // triangles inserted, per level
};

// The corners of each quad triangle's shape code (its low six bits), one bit each: read from a
// table, as prepare asks for them several times per triangle.
constexpr std::array<std::uint8_t, 64> kCorners = [] {
  std::array<std::uint8_t, 64> t{};
  for (int code = 0; code < 64; ++code)
    for (int k = 0; k < 3; ++k) t[code] |= std::uint8_t(1u << ((code >> (2 * k)) & 3));
  return t;
}();
unsigned corners_of(std::uint8_t code) { return kCorners[code & 63]; }

// A quad's corners (bits 0 top left, 1 top right, 2 bottom left, 3 bottom right) as bits of a
// grid of vertices `row_width` to a row, the quad's top left corner at bit 0.
inline std::uint64_t corner_grid_bits(unsigned corners, int row_width) {
  return std::uint64_t(corners & 3) | (std::uint64_t(corners >> 2) << row_width);
}

// Quad::split for a quad whose triangles' usability is known.
std::uint8_t split_of(const Quad& qd, const QuadShapes& shapes) {
  if (!(qd.shape[0] & qd.shape[1] & Quad::kUsable)) return 0;
  const std::uint8_t code = qd.shape[0] & 63;
  const unsigned a = corners_of(code), b = corners_of(qd.shape[1] & 63), shared = a & b;
  if ((a | b) != 15 || (shared != 9 && shared != 6)) return 0;  // not halves of the quad
  for (int e = 0; e < 3; ++e) {  // edge e joins vertices e + 1 and e + 2
    const unsigned ends = 1u << ((code >> (2 * ((e + 1) % 3))) & 3) | 1u << ((code >> (2 * ((e + 2) % 3))) & 3);
    if (ends == shared)
      return std::uint8_t(Quad::kSplit | e | (shapes.shape[code].positive[e] ? Quad::kPositive : 0));
  }
  return 0;
}

// Pixel quad -> its triangles (two slots); false if any triangle is not within one quad, or any
// sample is off its pixel centre (the frame then goes to the prism path).
// With `region_box`, only the tiles whose triangles can reach that box get triangles and bounds
// (a frame read for one plan tile of a sweep touches a small part of it).
bool prepare(const DepthFrame& frame, const std::vector<FrameTriangle>& triangles, const RootCube& root,
             const IntegrateOptions& options, const Eigen::AlignedBox3d* region_box, Prepared* out) {
  const Sensor& sensor = frame.sensor;
  if (sensor.kind != Sensor::Kind::Perspective || frame.width < 2 || frame.height < 2) return false;
  Prepared& p = *out;
  p.stats = IntegrateStats{};
  p.frame = &frame;
  p.behind = options.behind;
  p.QW = frame.width - 1, p.QH = frame.height - 1;
  const int W = frame.width, QW = p.QW, QH = p.QH;
  p.quad.assign(std::size_t(QW) * std::size_t(QH), Quad{});
  const bool centred = centred_where_valid(frame);
  for (std::size_t t = 0; t < triangles.size(); ++t) {
    const FrameTriangle& tri = triangles[t];
    // One division per triangle (this loop runs for every read of a frame, and a sweep reads a
    // far view once per plan tile): a vertex of a triangle within one quad lies in the lowest
    // index's row or the next, so its row and column follow from its offset to that index.
    const std::uint32_t lowest = std::min({tri[0], tri[1], tri[2]});
    if (std::max({tri[0], tri[1], tri[2]}) >= frame.size()) return false;
    const int rl = int(lowest / std::uint32_t(W)), cl = int(lowest - std::uint32_t(rl) * std::uint32_t(W));
    int r0 = rl, c0 = cl, r1 = rl, c1 = cl;
    int rk[3], ck[3];
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t i = tri[k];
      const std::uint32_t along = std::uint32_t(cl) + (i - lowest);  // columns from the row's start
      if (along >= 2 * std::uint32_t(W)) return false;  // two rows or more below
      const int r = rl + int(along >= std::uint32_t(W));  // no branch: the rows alternate
      const int c = int(along) - (r - rl) * W;
      if (!(centred ? frame.valid[i] != 0 : is_pixel_centre(frame, i, r, c))) return false;
      c0 = std::min(c0, c), c1 = std::max(c1, c), r1 = std::max(r1, r);
      rk[k] = r, ck[k] = c;
    }
    if (r1 - r0 > 1 || c1 - c0 > 1 || r0 >= QH || c0 >= QW) return false;
    std::uint8_t shape = 0;
    for (int k = 0; k < 3; ++k) shape |= std::uint8_t(((rk[k] - r0) * 2 + (ck[k] - c0)) << (2 * k));
    Quad& qd = p.quad[std::size_t(r0) * QW + c0];
    if (qd.tri[0] < 0) {
      qd.tri[0] = std::int32_t(t);
      qd.shape[0] = shape;
    } else if (qd.tri[1] < 0) {
      qd.tri[1] = std::int32_t(t);
      qd.shape[1] = shape;
      // Each triangle's corner that the other lacks (its vertex 0 if none), from the shapes.
      auto lone = [&](std::uint8_t a, std::uint8_t b) {
        const unsigned only = corners_of(a) & ~corners_of(b);
        return only != 0 ? std::countr_zero(only) : int(a & 3);
      };
      const int a = lone(qd.shape[0], shape), b = lone(shape, qd.shape[0]);
      qd.dx = std::int8_t((a & 1) - (b & 1));
      qd.dy = std::int8_t((a >> 1) - (b >> 1));
    } else {
      return false;
    }
  }

  p.TX = (QW + kTile - 1) / kTile, p.TY = (QH + kTile - 1) / kTile;
  const int TX = p.TX, TY = p.TY;
  p.Rt = sensor.R.transpose();
  p.centre = sensor.centre();
  {
    // The sides of the quads [first, end) along image axis `axis` (focal length f, principal
    // point c), widened by a thousandth of a pixel: half-spaces a . x_cam >= 0 in the camera,
    // a = (f, -(lo - c)) and (-f, hi - c) in that axis and depth, moved to world coordinates.
    constexpr double pm = 1e-3;
    auto sides = [&](int first, int end, double f, double c, int axis) {
      Prepared::FrustumSide fs;
      const double lo = first + 0.5 - pm, hi = end + 0.5 + pm;
      Vector3d a[2] = {Vector3d::Zero(), Vector3d::Zero()};
      a[0][axis] = f, a[0][2] = c - lo;
      a[1][axis] = -f, a[1][2] = hi - c;
      for (int k = 0; k < 2; ++k) fs.side[k] = {p.Rt * a[k], -a[k].dot(sensor.t)};
      fs.ray[0] = (lo - c) / f, fs.ray[1] = (hi - c) / f, fs.ray[2] = (0.5 * (lo + hi) - c) / f;
      return fs;
    };
    p.column_side.resize(std::size_t(TX));
    p.row_side.resize(std::size_t(TY));
    for (int tx = 0; tx < TX; ++tx)
      p.column_side[tx] = sides(tx * kTile, std::min(QW, tx * kTile + kTile), sensor.fx, sensor.cx, 0);
    for (int ty = 0; ty < TY; ++ty)
      p.row_side[ty] = sides(ty * kTile, std::min(QH, ty * kTile + kTile), sensor.fy, sensor.cy, 1);
  }
  // The quads of a tile, plus the column to its left and the row above: a voxel on the tile's
  // left or top border may belong to a triangle there (see the owner lookup below).
  auto tile_quads = [&](int tile, int* qr0, int* qr1, int* qc0, int* qc1) {
    const int tx = tile % TX, ty = tile / TX;
    *qr0 = std::max(0, ty * kTile - 1), *qr1 = std::min(QH, (ty + 1) * kTile);
    *qc0 = std::max(0, tx * kTile - 1), *qc1 = std::min(QW, (tx + 1) * kTile);
  };
  for (int lt = 0; lt < L; ++lt)
    for (int l = 0; l <= lt; ++l) p.ramp[lt][l] = insertion_ramp(options, root, l, lt);
  std::vector<char> tile_active(std::size_t(TX) * TY, 1);
  std::vector<char> quad_needed;
  if (region_box) {
    // A voxel gets a contribution only within a ramp of its triangle: a tile whose vertices' box,
    // widened by its triangles' longest ramp, misses the region writes nothing there. The levels
    // are worked out here, only on the region (sweep) path, and again in the pass below, which
    // needs quad_needed first and writes each triangle's record once.
    tbb::parallel_for(0, TX * TY, [&](int tile) {
      int qr0, qr1, qc0, qc1;
      tile_quads(tile, &qr0, &qr1, &qc0, &qc1);
      Eigen::AlignedBox3d box;
      double reach = 0;
      for (int r = qr0; r < qr1; ++r)
        for (int c = qc0; c < qc1; ++c)
          for (std::int32_t t : p.quad[std::size_t(r) * QW + c].tri) {
            if (t < 0) continue;
            int lt = 0, coarsest = 0;
            if (!insertion_levels(frame, triangles[t].data(), root, options, &lt, &coarsest)) continue;
            reach = std::max(reach, p.ramp[lt][coarsest]);
            for (std::uint32_t i : triangles[t]) box.extend(frame.position[i].cast<double>());
          }
      const Vector3d pad = Vector3d::Constant(reach + 1e-6 * root.size);
      tile_active[tile] = !box.isEmpty() && Eigen::AlignedBox3d(box.min() - pad, box.max() + pad).intersects(*region_box);
    });
    quad_needed.assign(p.quad.size(), 0);
    for (int tile = 0; tile < TX * TY; ++tile) {
      if (!tile_active[tile]) continue;
      int qr0, qr1, qc0, qc1;
      tile_quads(tile, &qr0, &qr1, &qc0, &qc1);
      for (int r = qr0; r < qr1; ++r) std::fill_n(quad_needed.begin() + std::ptrdiff_t(r) * QW + qc0, qc1 - qc0, 1);
    }
  }

  // Every triangle's levels, counted in the statistics whether or not this call evaluates it,
  // and the geometry of those this call can evaluate, in one pass over the quads (each triangle
  // lies in exactly one): the table of 64-byte triangle records (600 k for a 640 x 480 frame) is
  // written by this pass alone, where a pass of its own over the triangles wrote it first. Each
  // element is written here, once: no zeroing pass over the whole table first. A triangle's
  // ownership is its quad's shape: its three corners are distinct pixel centres, so its edges
  // never degenerate.
  p.tris.resize(triangles.size());
  ScratchArray<GridTriangle>& tris = p.tris;
  const Vector3d& centre = p.centre;
  p.stats = tbb::parallel_reduce(
      tbb::blocked_range<int>(0, QH, 16), IntegrateStats{},
      [&](const tbb::blocked_range<int>& rows, IntegrateStats c) {
        for (int qi = rows.begin() * QW; qi != rows.end() * QW; ++qi) {
          const bool needed = quad_needed.empty() || quad_needed[std::size_t(qi)];
          Quad& qd = p.quad[std::size_t(qi)];
          for (int slot = 0; slot < 2; ++slot) {
            const std::int32_t t = qd.tri[slot];
            if (t < 0) continue;
            GridTriangle& g = tris[t];
            for (int k = 0; k < 3; ++k) g.idx[k] = triangles[t][k];
            g.ok = false;
            int lt = 0, coarsest = 0;
            if (!insertion_levels(frame, g.idx, root, options, &lt, &coarsest)) {
              g.level = -1;
              g.coarsest = 0;
              continue;
            }
            g.level = std::int8_t(lt);
            g.coarsest = std::int8_t(coarsest);
            ++c.triangles;
            ++c.triangles_per_level[lt];
            if (!needed) continue;  // normal and P0 are left unset: nothing reads them
            Vector3d P[3];
            for (int k = 0; k < 3; ++k) P[k] = frame.position[g.idx[k]].cast<double>();
            g.P0 = frame.position[g.idx[0]];
            g.ok = facing_normal(sensor, centre, P, &g.normal);
            if (g.ok) qd.shape[slot] |= Quad::kUsable;
          }
          if (needed) qd.split = split_of(qd, p.shapes);
        }
        return c;
      },
      [](IntegrateStats a, const IntegrateStats& b) {
        a.add(b);
        return a;
      });

  // Per tile and level: bounds of the prisms of the triangles inserted there.
  int lowest = L, highest = -1;  // levels of equation 1 inserted
  for (int l = 0; l < L; ++l)
    if (p.stats.triangles_per_level[l] > 0) lowest = std::min(lowest, l), highest = l;
  p.level0 = highest < 0                ? 0
             : options.single_level >= 0 ? options.single_level
                                         : std::max(0, lowest - options.coarser_levels);
  p.levels = highest < 0 ? 0 : highest - p.level0 + 1;
  p.tile_levels.assign(std::size_t(TX) * TY * std::size_t(p.levels), TileLevel{});
  p.tile_normal.assign(std::size_t(TX) * TY, Vector3d::Zero());
  const Eigen::Matrix3d& R = sensor.R;
  const int H = frame.height;
  p.depth.resize(frame.size());
  p.sight.resize(frame.size());
  p.colour.resize(frame.colour.empty() ? 0 : frame.size());
  tbb::parallel_for(tbb::blocked_range<int>(0, H, 16), [&](const tbb::blocked_range<int>& rows) {
    for (int r = rows.begin(); r != rows.end(); ++r)
      for (int c = 0; c < W; ++c) {
        if (!quad_needed.empty()) {  // a sample is a vertex of the quads up and left of it
          bool needed = false;
          for (int qr = std::max(r - 1, 0); qr <= std::min(r, QH - 1); ++qr)
            for (int qc = std::max(c - 1, 0); qc <= std::min(c, QW - 1); ++qc)
              needed = needed || quad_needed[std::size_t(qr) * QW + qc];
          if (!needed) continue;
        }
        const std::size_t i = std::size_t(r) * W + c;
        const Vector3d P = frame.position[i].cast<double>();
        p.depth[i] = R.row(2).dot(P) + sensor.t.z();
        p.sight[i] = (P - centre).normalized();
        if (!p.colour.empty()) p.colour[i] = packed_colour(frame.colour[i]);
      }
  });
  tbb::parallel_for(0, TX * TY, [&](int tile) {
    if (!tile_active[tile]) return;
    int qr0, qr1, qc0, qc1;
    tile_quads(tile, &qr0, &qr1, &qc0, &qc1);
    constexpr int kSide = kTile + 2;  // vertices per side: the tile's quads and the ones before
    const int vw = qc1 - qc0 + 1;
    // One pass over the tile's triangles: the sum of their normals, and per level of equation 1
    // the vertices of its triangles, a bit each (a vertex is shared by up to six triangles, so
    // the extents below take each vertex once: min and max do not depend on the order).
    static_assert(kSide * kSide <= 64, "a tile's vertices fit in one mask");
    static_assert(L <= 32, "levels_seen holds a bit per level");
    std::uint64_t used[L];
    int coarsest_of[L];
    std::uint32_t levels_seen = 0;  // bit lt: some triangle of level lt
    Vector3d n = Vector3d::Zero();
    for (int r = qr0; r < qr1; ++r)
      for (int c = qc0; c < qc1; ++c) {
        const Quad& qd = p.quad[std::size_t(r) * QW + c];
        for (int slot = 0; slot < 2; ++slot) {
          if (qd.tri[slot] < 0) continue;
          const GridTriangle& g = tris[qd.tri[slot]];
          if (!g.ok) continue;
          n += g.normal;
          if (!(levels_seen >> g.level & 1)) {
            used[g.level] = 0;
            coarsest_of[g.level] = g.coarsest;
            levels_seen |= 1u << g.level;
          }
          used[g.level] |= corner_grid_bits(corners_of(qd.shape[slot]), vw) << ((r - qr0) * vw + (c - qc0));
        }
      }
    if (!(n.norm() > 1e-6)) n = Vector3d::UnitZ();  // any direction is a valid bound
    n.normalize();
    p.tile_normal[tile] = n;
    // A voxel X at ray distance d in [-behind ramp, ramp] from a triangle (d > 0 towards the
    // sensor) lies at X = P - d dir, P on the triangle and dir its unit line of sight: its camera
    // depth is z(P) - d dir_z with 0 < dir_z <= 1, its offset along n is n.P - d n.dir. Per vertex
    // (once, though up to six of the tile's triangles share it): camera depth z, offset s along n
    // and, per unit ramp, the offsets below and above it. The slab of a level takes the least s
    // plus the least offset below (the greatest plus the greatest above) over all the triangles
    // of one level of equation 1 at once: looser than per triangle by the ramp times the spread of
    // the tile's lines of sight (a few pixels' angle), which the margins dwarf.
    double vz[kSide * kSide], vs[kSide * kSide], vbelow[kSide * kSide], vabove[kSide * kSide];
    for (int r = qr0; r <= qr1; ++r)
      for (int c = qc0; c <= qc1; ++c) {
        const std::size_t i = std::size_t(r) * W + c;
        const int v = (r - qr0) * vw + (c - qc0);
        const double sd = n.dot(p.sight[i]);
        vz[v] = p.depth[i];
        vs[v] = n.dot(frame.position[i].cast<double>());
        vbelow[v] = std::min(-sd, options.behind * sd);
        vabove[v] = std::max(-sd, options.behind * sd);
      }
    struct Extent {
      double zmin, zmax, smin, smax, below, above;
      int coarsest;  // the same for every triangle of one level of equation 1
    };
    Extent extent[L];
    for (int lt = 0; lt < L; ++lt) {
      if (!(levels_seen >> lt & 1)) continue;
      const double inf = std::numeric_limits<double>::infinity();
      Extent& e = extent[lt];
      e = Extent{inf, -inf, inf, -inf, inf, -inf, coarsest_of[lt]};
      for (std::uint64_t m = used[lt]; m != 0; m &= m - 1) {
        const int v = std::countr_zero(m);
        e.zmin = std::min(e.zmin, vz[v]);
        e.zmax = std::max(e.zmax, vz[v]);
        e.smin = std::min(e.smin, vs[v]);
        e.smax = std::max(e.smax, vs[v]);
        e.below = std::min(e.below, vbelow[v]);
        e.above = std::max(e.above, vabove[v]);
      }
    }
    for (int lt = 0; lt < L; ++lt) {
      if (!(levels_seen >> lt & 1)) continue;
      const Extent& e = extent[lt];
      for (int l = e.coarsest; l <= lt; ++l) {
        const double ramp = p.ramp[lt][l];
        TileLevel& t = p.tile_level(tile, l);
        t.zmin = std::min(t.zmin, e.zmin);
        t.zmax = std::max(t.zmax, e.zmax);
        t.ramp = std::max(t.ramp, ramp);
        t.smin = std::min(t.smin, e.smin + ramp * e.below);
        t.smax = std::max(t.smax, e.smax + ramp * e.above);
      }
    }
  });
  return true;
}

// The candidate voxels of one (tile, level) item: the tile's frustum slab as half-spaces, the
// index box that bounds it (per world axis), and the axis the columns march along.
struct ItemFrustum {
  HalfSpace planes[8];
  std::int64_t first[3], last[3];
  int ax = 0, bx = 1, cx = 2;
  int c0 = 0, c1 = 0, r0 = 0, r1 = 0;  // the tile's pixel quads [c0, c1) x [r0, r1)
  bool empty() const { return first[0] > last[0] || first[1] > last[1] || first[2] > last[2]; }
  void clip(const BrickBox& box, int level, int brick_level) {
    for (int a = 0; a < 3; ++a) {
      std::int64_t f, l;
      box.voxel_range(level, brick_level, a, &f, &l);
      first[a] = std::max(first[a], f);
      last[a] = std::min(last[a], l);
    }
  }
};

ItemFrustum item_frustum(const Prepared& p, const RootCube& root, int tile, int level) {
  const Sensor& sensor = p.frame->sensor;
  const Eigen::Matrix3d& Rt = p.Rt;
  ItemFrustum fr;
  const int tx = tile % p.TX, ty = tile / p.TX;
  fr.c0 = tx * kTile, fr.c1 = std::min(p.QW, fr.c0 + kTile), fr.r0 = ty * kTile, fr.r1 = std::min(p.QH, fr.r0 + kTile);
  const TileLevel& tl = p.tile_level(tile, level);
  const double h = root.cell_size(level);
  const double margin = 1e-3 * h;
  // The tile's frustum slab as half-spaces a . x_cam + b >= 0, moved to world coordinates: the
  // four sides from the frame's tables (Prepared::FrustumSide), the depth caps here.
  const Prepared::FrustumSide &cs = p.column_side[tx], &rs = p.row_side[ty];
  const double zlo = std::max(tl.zmin - tl.ramp - margin, 1e-9), zhi = tl.zmax + p.behind * tl.ramp + margin;
  for (int k = 0; k < 2; ++k) fr.planes[k] = cs.side[k], fr.planes[2 + k] = rs.side[k];
  const Vector3d a_depth[2] = {{0, 0, 1}, {0, 0, -1}};
  const double b_depth[2] = {-zlo, zhi};
  for (int k = 0; k < 2; ++k) fr.planes[4 + k] = {Rt * a_depth[k], -(a_depth[k].dot(sensor.t) + b_depth[k])};
  // Along the tile normal: the prisms lie within the hull of their corners P +- ramp dir,
  // up to the bulge of a perspective cap (ramp x (pixel angle)^2 / 8, far below the margin).
  const Vector3d& tn = p.tile_normal[tile];
  fr.planes[6] = {tn, tl.smin - margin};
  fr.planes[7] = {-tn, -tl.smax - margin};
  Vector3d lo = Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (int k = 0; k < 8; ++k) {
    const double ru = cs.ray[k & 1], rv = rs.ray[(k >> 1) & 1], z = (k & 4) ? zhi : zlo;
    const Vector3d xc(ru * z, rv * z, z);
    const Vector3d X = Rt * (xc - sensor.t);
    lo = lo.cwiseMin(X);
    hi = hi.cwiseMax(X);
  }
  // March along the world axis closest to the tile's central line of sight.
  const Vector3d ray = Rt * Vector3d(cs.ray[2], rs.ray[2], 1.0);
  ray.cwiseAbs().maxCoeff(&fr.ax);
  fr.bx = (fr.ax + 1) % 3, fr.cx = (fr.ax + 2) % 3;
  const std::int64_t n_cells = std::int64_t{1} << level;
  for (int a = 0; a < 3; ++a) {
    fr.first[a] = std::max<std::int64_t>(0, std::int64_t(std::ceil((lo[a] - margin - root.min[a]) / h)));
    fr.last[a] = std::min<std::int64_t>(n_cells, std::int64_t(std::floor((hi[a] + margin - root.min[a]) / h)));
  }
  return fr;
}

// Index boxes of up to this many columns go without the row prefilter (below).
constexpr std::int64_t kPrefilterColumns = 128;

// One half-space of an item's slab along a column (ib, ic) of its lattice: m . X - k =
// v0 + ib vb + ic vc + t ma, t the position along the column's axis.
struct ColumnPlane {
  double v0, vb, vc, ma, inv_ma;
  double inv_ma_h;  // inv_ma / h: the bound on t in cells, without a division per column
};

// Which columns of a lattice row can meet the slab. A column is not empty iff every lower bound
// on t (ma > 0) is below every upper bound (ma < 0), and each such pair condition is a half-plane
// in (ib, ic); so is a plane parallel to the columns. Per row that leaves an interval of ic. The
// interval is widened by `slack` and a column, so the exact per-column test, which stays, has the
// last word: this only skips the empty columns of the slab's bounding box (most of them, for a
// slab tilted against the lattice).
class RowPrefilter {
 public:
  // Set per item on an object kept by the task: a std::optional<RowPrefilter> per item had GCC
  // zero its 6.5 KB at every item, used or not (1.4 % of igea's instructions, as valgrind counts
  // a rep stos).
  void set(const ColumnPlane cp[8], double t_lo, double t_hi, double slack) {
    slack_ = slack;
    n_lo_ = n_hi_ = n_row_ = 0;
    // Bounds on t as affine forms alpha + beta ib + gamma ic, the lattice's own range first (its
    // pair with itself is a constant, true constraint and is left out).
    struct Bound {
      double alpha, beta, gamma;
    };
    Bound lower[9], upper[9];
    int nl = 0, nu = 0;
    lower[nl++] = {t_lo, 0, 0};
    upper[nu++] = {t_hi, 0, 0};
    for (int k = 0; k < 8; ++k) {
      const ColumnPlane& c = cp[k];
      if (c.ma == 0) {
        add(c.v0, c.vb, c.vc);
        continue;
      }
      const Bound b{-c.v0 * c.inv_ma, -c.vb * c.inv_ma, -c.vc * c.inv_ma};
      if (c.ma > 0)
        lower[nl++] = b;
      else
        upper[nu++] = b;
    }
    for (int i = 0; i < nl; ++i)
      for (int j = i == 0 ? 1 : 0; j < nu; ++j)
        add(upper[j].alpha - lower[i].alpha, upper[j].beta - lower[i].beta, upper[j].gamma - lower[i].gamma);
    pad();
  }
  // Narrows [*ic0, *ic1] to the columns of row ib that may meet the slab; false if none can.
  // floor is monotonic, so the tightest lower bound is floor of the greatest x, less one (and the
  // tightest upper one ceil of the least, plus one): one rounding per row, made only if it can
  // narrow (a libm call on baseline x86-64), and the bounds themselves two to a lane.
  bool clip_row(double ib, std::int64_t* ic0, std::int64_t* ic1) const {
    double lo = double(*ic0), hi = double(*ic1);
#if defined(__SSE2__) && defined(__x86_64__)
    const __m128d ibv = _mm_set1_pd(ib), zero = _mm_setzero_pd();
    __m128d negative = _mm_setzero_pd();
    for (int k = 0; k < n_row_; k += 2)
      negative = _mm_or_pd(negative, _mm_cmplt_pd(_mm_add_pd(_mm_load_pd(row_.a + k), _mm_mul_pd(_mm_load_pd(row_.b + k), ibv)), zero));
    if (_mm_movemask_pd(negative)) return false;
    __m128d most = _mm_set1_pd(-kInf), least = _mm_set1_pd(kInf);
    for (int k = 0; k < n_lo_; k += 2)
      most = _mm_max_pd(most, _mm_mul_pd(_mm_add_pd(_mm_load_pd(lo_.a + k), _mm_mul_pd(_mm_load_pd(lo_.b + k), ibv)),
                                         _mm_load_pd(lo_.r + k)));
    for (int k = 0; k < n_hi_; k += 2)
      least = _mm_min_pd(least, _mm_mul_pd(_mm_add_pd(_mm_load_pd(hi_.a + k), _mm_mul_pd(_mm_load_pd(hi_.b + k), ibv)),
                                           _mm_load_pd(hi_.r + k)));
    const double x_lo = _mm_cvtsd_f64(_mm_max_sd(most, _mm_unpackhi_pd(most, most)));
    const double x_hi = _mm_cvtsd_f64(_mm_min_sd(least, _mm_unpackhi_pd(least, least)));
#else
    for (int k = 0; k < n_row_; ++k)
      if (row_.a[k] + row_.b[k] * ib < 0) return false;
    double x_lo = -kInf, x_hi = kInf;
    for (int k = 0; k < n_lo_; ++k) x_lo = std::max(x_lo, (lo_.a[k] + lo_.b[k] * ib) * lo_.r[k]);
    for (int k = 0; k < n_hi_; ++k) x_hi = std::min(x_hi, (hi_.a[k] + hi_.b[k] * ib) * hi_.r[k]);
#endif
    if (x_lo - 1 > lo) lo = std::floor(x_lo) - 1;
    if (x_hi + 1 < hi) hi = std::ceil(x_hi) + 1;
    if (lo > hi) return false;
    *ic0 = std::int64_t(lo);
    *ic1 = std::int64_t(hi);
    return true;
  }

 private:
  static constexpr double kInf = std::numeric_limits<double>::infinity();
  static constexpr int kMax = 8 + 9 * 9 + 1;  // every pair, and a pad to an even count
  // a + b ib + c ic >= 0, loosened by the slack: ic >= (a + b ib) r (c > 0) or <= (c < 0), r = -1 / c;
  // in columns, two to a lane.
  struct HalfPlanes {
    alignas(16) double a[kMax];
    alignas(16) double b[kMax];
    alignas(16) double r[kMax];
    void push(int* n, double av, double bv, double rv) { a[*n] = av, b[*n] = bv, r[*n] = rv, ++*n; }
  };
  void add(double a, double b, double c) {
    const double loose = a + slack_ * (1.0 + std::abs(a)), r = c != 0 ? -1.0 / c : 0.0;
    if (c > 0)
      lo_.push(&n_lo_, loose, b, r);
    else if (c < 0)
      hi_.push(&n_hi_, loose, b, r);
    else
      row_.push(&n_row_, loose, b, r);
  }
  // Pads each list to an even count with a bound that never binds.
  void pad() {
    if (n_lo_ % 2) lo_.a[n_lo_] = -kInf, lo_.b[n_lo_] = 0, lo_.r[n_lo_] = 1;
    if (n_hi_ % 2) hi_.a[n_hi_] = kInf, hi_.b[n_hi_] = 0, hi_.r[n_hi_] = 1;
    if (n_row_ % 2) row_.a[n_row_] = 0, row_.b[n_row_] = 0, row_.r[n_row_] = 0;
  }
  HalfPlanes lo_, hi_, row_;
  int n_lo_ = 0, n_hi_ = 0, n_row_ = 0;
  double slack_ = 0;
};

// The range of t (cells along a column) that an item's slab leaves to column ic of a row: the
// highest of the lower bounds and the lowest of the upper ones, each alpha + ic beta (alpha per
// row, beta per item). Rounding moves a bound by some 1e-13 cells, far inside the planes' margins
// (1e-3 of a cell or a pixel), so the order of the sums is free and the planes go two to a lane.
class ColumnBounds {
 public:
  // The planes bounding t below (ma > 0) or above (ma < 0); none of `cp` may be parallel.
  void set_item(const ColumnPlane cp[8], const int lower[8], int n_lower, const int upper[8], int n_upper) {
    n_[0] = n_lower, n_[1] = n_upper;
    for (int j = 0; j < n_lower; ++j) plane_[0][j] = lower[j], beta_[0][j] = -cp[lower[j]].vc * cp[lower[j]].inv_ma_h;
    for (int j = 0; j < n_upper; ++j) plane_[1][j] = upper[j], beta_[1][j] = -cp[upper[j]].vc * cp[upper[j]].inv_ma_h;
    for (int side = 0; side < 2; ++side) {
      const double none = side == 0 ? -kInf : kInf;  // no bound: pads a pair
      for (int j = n_[side]; j < 8; ++j) plane_[side][j] = -1, alpha_[side][j] = none, beta_[side][j] = 0;
    }
  }
  // Each plane's share of the row, row_value = v0 + ib vb.
  void set_row(const ColumnPlane cp[8], const double row_value[8]) {
    for (int side = 0; side < 2; ++side)
      for (int j = 0; j < n_[side]; ++j)
        alpha_[side][j] = -row_value[plane_[side][j]] * cp[plane_[side][j]].inv_ma_h;
  }
  // [*tmin, *tmax] for column ic.
  void range(double ic, double* tmin, double* tmax) const {
#if defined(__SSE2__) && defined(__x86_64__)
    const __m128d icv = _mm_set1_pd(ic);
    __m128d lo = _mm_set1_pd(-kInf), hi = _mm_set1_pd(kInf);
    for (int j = 0; j < n_[0]; j += 2)
      lo = _mm_max_pd(lo, _mm_add_pd(_mm_load_pd(alpha_[0] + j), _mm_mul_pd(icv, _mm_load_pd(beta_[0] + j))));
    for (int j = 0; j < n_[1]; j += 2)
      hi = _mm_min_pd(hi, _mm_add_pd(_mm_load_pd(alpha_[1] + j), _mm_mul_pd(icv, _mm_load_pd(beta_[1] + j))));
    *tmin = _mm_cvtsd_f64(_mm_max_sd(lo, _mm_unpackhi_pd(lo, lo)));
    *tmax = _mm_cvtsd_f64(_mm_min_sd(hi, _mm_unpackhi_pd(hi, hi)));
#else
    double lo = -kInf, hi = kInf;
    for (int j = 0; j < n_[0]; ++j) lo = std::max(lo, alpha_[0][j] + ic * beta_[0][j]);
    for (int j = 0; j < n_[1]; ++j) hi = std::min(hi, alpha_[1][j] + ic * beta_[1][j]);
    *tmin = lo, *tmax = hi;
#endif
  }

 private:
  static constexpr double kInf = std::numeric_limits<double>::infinity();
  alignas(16) double alpha_[2][8];
  alignas(16) double beta_[2][8];
  int plane_[2][8];
  int n_[2] = {0, 0};
};

// A candidate voxel of a lattice row on its way through the kernel's phases.
struct Candidate {
  Vector3d X;                     // its centre
  Vector2d uv;                    // its projection in its pixel quad's coordinates, [0.5, 1.5) each
  double E[3];                    // the owner's edge functions at q
  const Ownership* shape;         // the owner's shape (moved by the quad's column and row)
  std::int32_t owner;             // the owner's index in Prepared::tris
  std::int32_t col, row;          // the pixel quad q falls in
  std::int32_t ia, ib, ic;        // lattice indices along the column's axis, the row's and the column's
  bool in;                        // projected in front of the sensor, into one of the item's tile's quads
  VoxelSample sample;
  VoxelData* voxel;               // where the sample goes
};

// The candidates of a work item, and which of them are still in after the owner and the sample
// phases (indices, so that no candidate is copied). Reused from item to item and never shrunk;
// its elements are written before they are read, so they are left uninitialized (growth used to
// value-initialize them: a memset of some 400 MB over igea's integration, in the tasks' fresh
// batches).
struct ItemBatch {
  std::unique_ptr<Candidate[]> cand;
  std::unique_ptr<std::uint32_t[]> owned, sampled;
  std::size_t capacity = 0;  // elements of each array
  // Room for at least n candidates, keeping the first `used`.
  void grow(std::size_t n, std::size_t used) {
    const std::size_t c = std::max<std::size_t>(2 * n, 256);
    std::unique_ptr<Candidate[]> more(new Candidate[c]);
    std::copy(cand.get(), cand.get() + used, more.get());
    cand = std::move(more);
    owned.reset(new std::uint32_t[c]);
    sampled.reset(new std::uint32_t[c]);
    capacity = c;
  }
};

// Phase 1 of the kernel for one column (ib, ic): the voxels ia in [i0, i1] (centre `base` moved by h ia
// along axis `ax`) join the batch from index n, voxel ia at n + ia - i0, marked `in` if their
// projection falls in the tile's quads [c0, c1) x [r0, r1); returns the new count. `terms` holds
// the column's fixed axes' camera terms. Every voxel takes a place, kept or not (of igea's 19.5 M
// projected voxels 0.1 % fall outside): the places of the next voxels are then known before this
// one's division and floors are done, rather than after them, and the stores of many columns
// are under way at once.
struct ColumnTile {
  int c0, c1, r0, r1;  // the tile's pixel quads
};
[[maybe_unused]] std::size_t project_column_scalar(const Sensor& sensor, double terms[3][3], const Vector3d& base,
                                                   int ax, double h, std::int64_t i0, std::int64_t i1, std::int64_t ib,
                                                   std::int64_t ic, ColumnTile t, ItemBatch& batch, std::size_t n) {
  for (std::int64_t ia = i0; ia <= i1; ++ia) {
    Candidate& cand = batch.cand[n++];
    cand.in = false;
    Vector3d X = base;
    X[ax] += h * double(ia);
    camera_terms(sensor.R, X, ax, terms);
    const Vector3d xs = camera_point(terms, sensor.t);
    if (!(xs.z() > 0)) continue;
    const Vector2d q = pixel_of(sensor, xs);
    const int col = fast_floor(q.x() - 0.5), row = fast_floor(q.y() - 0.5);
    if (!(col >= t.c0 && col < t.c1 && row >= t.r0 && row < t.r1)) continue;  // another tile's voxel
    cand.in = true;
    cand.X = X;
    cand.uv = Vector2d(q.x() - double(col), q.y() - double(row));  // exact: see Ownership::edge_local
    cand.col = col, cand.row = row;
    cand.ia = std::int32_t(ia), cand.ib = std::int32_t(ib), cand.ic = std::int32_t(ic);
  }
  return n;
}

#if defined(__SSE2__) && defined(__x86_64__)
// project_column_scalar two voxels at a time, one per lane: the same operations on each voxel in
// the same order (camera_point's sums grouped as there, with the column's own term in its place
// among the three), so the same bits, in about half the instructions. Both lanes are written to
// the batch, the second past the column's end where its count is odd, so the batch needs room for
// one more.
// What project_column_pairs needs of an item, in lanes: set once per item rather than once per
// column (an item has some 20 columns of 3 or 4 candidates each).
struct ColumnLanes {
  __m128d hv, r[3], tt[3], fx, fy, cx, cy;
  __m128i c0, c1, r0, r1;  // the tile's quads, the lower bounds less one
  ColumnLanes(const Sensor& sensor, int ax, double h, ColumnTile t) {
    hv = _mm_set1_pd(h);
    for (int i = 0; i < 3; ++i) r[i] = _mm_set1_pd(sensor.R(i, ax)), tt[i] = _mm_set1_pd(sensor.t[i]);
    fx = _mm_set1_pd(sensor.fx), fy = _mm_set1_pd(sensor.fy), cx = _mm_set1_pd(sensor.cx), cy = _mm_set1_pd(sensor.cy);
    c0 = _mm_set1_epi32(t.c0 - 1), c1 = _mm_set1_epi32(t.c1), r0 = _mm_set1_epi32(t.r0 - 1), r1 = _mm_set1_epi32(t.r1);
  }
};

template <int AX>
std::size_t project_column_pairs(const ColumnLanes& lanes, const double terms[3][3], const Vector3d& base,
                                 std::int64_t i0, std::int64_t i1, std::int64_t ib, std::int64_t ic, ItemBatch& batch,
                                 std::size_t n) {
  constexpr int B = (AX + 1) % 3, C = (AX + 2) % 3;
  // Per camera coordinate i: the lanes' term v = R(i, AX) X[AX], then s = v + k1, s = s + k2 (if
  // any), s = s + t_i, which is camera_point's grouping: rows 0 and 1 sum the terms 0, 1, 2 left
  // to right, row 2 sums terms 1 and 2 first.
  double k1[3], k2[3];
  bool has_k2[3];
  for (int i = 0; i < 2; ++i) {
    if (AX == 0) k1[i] = terms[1][i], k2[i] = terms[2][i], has_k2[i] = true;       // ((v + T1) + T2)
    if (AX == 1) k1[i] = terms[0][i], k2[i] = terms[2][i], has_k2[i] = true;       // ((T0 + v) + T2)
    if (AX == 2) k1[i] = terms[0][i] + terms[1][i], k2[i] = 0, has_k2[i] = false;  // ((T0 + T1) + v)
  }
  if (AX == 0) k1[2] = terms[1][2] + terms[2][2], k2[2] = 0, has_k2[2] = false;  // (v + (T1 + T2))
  if (AX == 1) k1[2] = terms[2][2], k2[2] = terms[0][2], has_k2[2] = true;       // (T0 + (v + T2))
  if (AX == 2) k1[2] = terms[1][2], k2[2] = terms[0][2], has_k2[2] = true;       // (T0 + (T1 + v))
  const __m128d base_a = _mm_set1_pd(base[AX]);
  __m128d kk1[3], kk2[3];
  for (int i = 0; i < 3; ++i) {
    kk1[i] = _mm_set1_pd(k1[i]);
    kk2[i] = _mm_set1_pd(k2[i]);
  }
  const __m128d hv = lanes.hv, fx = lanes.fx, fy = lanes.fy, cx = lanes.cx, cy = lanes.cy, one = _mm_set1_pd(1.0),
                half = _mm_set1_pd(0.5);
  const __m128d* const r = lanes.r;
  const __m128d* const tt = lanes.tt;
  const __m128i c0 = lanes.c0, c1 = lanes.c1, r0 = lanes.r0, r1 = lanes.r1;
  // fast_floor per lane: truncate, and one less where that rounded up.
  auto floor_lanes = [](__m128d x) {
    const __m128i i = _mm_cvttpd_epi32(x);  // lanes 0, 1
    const __m128d up = _mm_cmpgt_pd(_mm_cvtepi32_pd(i), x);
    return _mm_add_epi32(i, _mm_shuffle_epi32(_mm_castpd_si128(up), _MM_SHUFFLE(3, 3, 2, 0)));
  };
  for (std::int64_t ia = i0; ia <= i1; ia += 2) {
    const __m128d xa = _mm_add_pd(base_a, _mm_mul_pd(hv, _mm_set_pd(double(ia + 1), double(ia))));
    __m128d xs[3];
    for (int i = 0; i < 3; ++i) {
      __m128d s = _mm_add_pd(_mm_mul_pd(r[i], xa), kk1[i]);
      if (has_k2[i]) s = _mm_add_pd(s, kk2[i]);
      xs[i] = _mm_add_pd(s, tt[i]);
    }
    const int in_front = _mm_movemask_pd(_mm_cmpgt_pd(xs[2], _mm_setzero_pd()));
    const __m128d iz = _mm_div_pd(one, xs[2]);
    const __m128d qx = _mm_add_pd(_mm_mul_pd(_mm_mul_pd(fx, xs[0]), iz), cx);
    const __m128d qy = _mm_add_pd(_mm_mul_pd(_mm_mul_pd(fy, xs[1]), iz), cy);
    const __m128i col = floor_lanes(_mm_sub_pd(qx, half)), row = floor_lanes(_mm_sub_pd(qy, half));
    const __m128i in_tile = _mm_and_si128(_mm_and_si128(_mm_cmpgt_epi32(col, c0), _mm_cmpgt_epi32(c1, col)),
                                          _mm_and_si128(_mm_cmpgt_epi32(row, r0), _mm_cmpgt_epi32(r1, row)));
    const int last = ia + 1 <= i1 ? 3 : 1;  // the second lane is past the column's end
    const int keep = in_front & _mm_movemask_ps(_mm_castsi128_ps(in_tile)) & last;
    const __m128i colrow = _mm_unpacklo_epi32(col, row);  // col0 row0 col1 row1
    // The projection in its quad's coordinates, as the scalar path computes it (exact).
    const __m128d u = _mm_sub_pd(qx, _mm_cvtepi32_pd(col)), v = _mm_sub_pd(qy, _mm_cvtepi32_pd(row));
    for (int lane = 0; lane < 2; ++lane) {
      Candidate& cand = batch.cand[n + std::size_t(ia - i0 + lane)];
      const __m128d x = lane == 0 ? xa : _mm_unpackhi_pd(xa, xa);
      cand.X[AX] = _mm_cvtsd_f64(x);
      cand.X[B] = base[B];
      cand.X[C] = base[C];
      _mm_storeu_pd(cand.uv.data(), lane == 0 ? _mm_unpacklo_pd(u, v) : _mm_unpackhi_pd(u, v));
      _mm_storel_epi64(reinterpret_cast<__m128i*>(&cand.col), lane == 0 ? colrow : _mm_srli_si128(colrow, 8));
      cand.ia = std::int32_t(ia + lane), cand.ib = std::int32_t(ib), cand.ic = std::int32_t(ic);
      cand.in = keep >> lane & 1;
    }
  }
  return n + std::size_t(i1 - i0 + 1);
}
#endif

#if defined(__SSE2__) && defined(__x86_64__)
struct ColumnProjector {
  ColumnLanes lanes;
  int ax;
  ColumnProjector(const Sensor& sensor, int ax, double h, ColumnTile t) : lanes(sensor, ax, h, t), ax(ax) {}
  std::size_t operator()(double terms[3][3], const Vector3d& base, std::int64_t i0, std::int64_t i1, std::int64_t ib,
                         std::int64_t ic, ItemBatch& batch, std::size_t n) const {
    if (ax == 0) return project_column_pairs<0>(lanes, terms, base, i0, i1, ib, ic, batch, n);
    if (ax == 1) return project_column_pairs<1>(lanes, terms, base, i0, i1, ib, ic, batch, n);
    return project_column_pairs<2>(lanes, terms, base, i0, i1, ib, ic, batch, n);
  }
};
#else
struct ColumnProjector {
  const Sensor& sensor;
  int ax;
  double h;
  ColumnTile t;
  ColumnProjector(const Sensor& sensor, int ax, double h, ColumnTile t) : sensor(sensor), ax(ax), h(h), t(t) {}
  std::size_t operator()(double terms[3][3], const Vector3d& base, std::int64_t i0, std::int64_t i1, std::int64_t ib,
                         std::int64_t ic, ItemBatch& batch, std::size_t n) const {
    return project_column_scalar(sensor, terms, base, ax, h, i0, i1, ib, ic, t, batch, n);
  }
};
#endif

// Phase 3 of the kernel for the owned candidates of a row: distance, weight and colour
// (voxel_sample); the candidates that get a contribution are listed in `batch.sampled`, their
// count returned.
[[maybe_unused]] std::size_t sample_candidates_scalar(const Prepared& p, const DepthFrame& frame, int level, const Vector3d& centre,
                                     const IntegrateOptions& options, const std::uint32_t* packed, ItemBatch& batch,
                                     std::size_t owned) {
  std::size_t sampled = 0;
  for (std::size_t j = 0; j < owned; ++j) {
    const std::uint32_t k = batch.owned[j];
    Candidate& cand = batch.cand[k];
    const GridTriangle& g = p.tris[cand.owner];
    if (level < g.coarsest || level > g.level) continue;
    const double ramp = p.ramp[g.level][level];
    const double plane = g.normal.dot(g.P0.cast<double>() - cand.X);
    if (beyond_ramp(plane, ramp, options)) continue;
    const double cosine = sight_cosine(g.normal, cand.X - centre);
    if (!voxel_sample(frame, g.idx, *cand.shape, cand.E, plane, cosine, ramp, options, &cand.sample, packed)) continue;
    batch.sampled[sampled++] = k;
  }
  return sampled;
}

#if defined(__SSE2__) && defined(__x86_64__)
// sample_candidates_scalar two candidates at a time, one per lane: every test of beyond_ramp,
// sight_cosine and voxel_sample as a mask, on the same operations in the same order (Eigen sums
// a 3-vector's dot product and squared norm left to right), so the same bits. A candidate's
// distance, weight and confidence are a chain of a square root and three divisions; two lanes
// halve them, and the masks replace four branches per candidate that a voxel near the ramp's
// ends or a triangle's edge makes unpredictable.
std::size_t sample_candidates_pairs(const Prepared& p, const DepthFrame& frame, int level, const Vector3d& centre,
                                    const IntegrateOptions& options, const std::uint32_t* packed, ItemBatch& batch,
                                    std::size_t owned) {
  const bool has_confidence = !frame.confidence.empty();
  const __m128d zero = _mm_setzero_pd(), one = _mm_set1_pd(1.0), behind = _mm_set1_pd(options.behind),
                min_cosine = _mm_set1_pd(options.min_cosine), sign = _mm_set1_pd(-0.0);
  const __m128d cx = _mm_set1_pd(centre.x()), cy = _mm_set1_pd(centre.y()), cz = _mm_set1_pd(centre.z());
  const auto pair = [](double a, double b) { return _mm_set_pd(b, a); };  // a in lane 0
  std::size_t sampled = 0;
  for (std::size_t j = 0; j < owned; j += 2) {
    const bool two = j + 1 < owned;
    const std::uint32_t k[2] = {batch.owned[j], two ? batch.owned[j + 1] : batch.owned[j]};
    Candidate* c[2] = {&batch.cand[k[0]], &batch.cand[k[1]]};
    const GridTriangle* g[2] = {&p.tris[c[0]->owner], &p.tris[c[1]->owner]};
    bool level_ok[2];
    double ramp_of[2];
    for (int l = 0; l < 2; ++l) {
      level_ok[l] = !(level < g[l]->coarsest || level > g[l]->level);
      ramp_of[l] = level_ok[l] ? p.ramp[g[l]->level][level] : 1.0;
    }
    const __m128d nx = pair(g[0]->normal.x(), g[1]->normal.x()), ny = pair(g[0]->normal.y(), g[1]->normal.y()),
                  nz = pair(g[0]->normal.z(), g[1]->normal.z());
    const __m128d X = pair(c[0]->X.x(), c[1]->X.x()), Y = pair(c[0]->X.y(), c[1]->X.y()),
                  Z = pair(c[0]->X.z(), c[1]->X.z());
    const __m128d ramp = pair(ramp_of[0], ramp_of[1]);
    // plane = normal . (P0 - X), P0 widened from float (exact).
    const __m128d px = _mm_sub_pd(pair(g[0]->P0.x(), g[1]->P0.x()), X),
                  py = _mm_sub_pd(pair(g[0]->P0.y(), g[1]->P0.y()), Y),
                  pz = _mm_sub_pd(pair(g[0]->P0.z(), g[1]->P0.z()), Z);
    const __m128d plane = _mm_add_pd(_mm_add_pd(_mm_mul_pd(nx, px), _mm_mul_pd(ny, py)), _mm_mul_pd(nz, pz));
    // beyond_ramp: in front beyond ramp * behind, or behind beyond ramp.
    const __m128d in_front = _mm_cmpgt_pd(plane, zero);
    const __m128d beyond = _mm_or_pd(_mm_and_pd(in_front, _mm_cmpgt_pd(plane, _mm_mul_pd(ramp, behind))),
                                     _mm_andnot_pd(in_front, _mm_cmpgt_pd(_mm_xor_pd(plane, sign), ramp)));
    // sight_cosine: normal . D / sqrt(D . D), D = X - centre.
    const __m128d dx = _mm_sub_pd(X, cx), dy = _mm_sub_pd(Y, cy), dz = _mm_sub_pd(Z, cz);
    const __m128d squared = _mm_add_pd(_mm_add_pd(_mm_mul_pd(dx, dx), _mm_mul_pd(dy, dy)), _mm_mul_pd(dz, dz));
    const __m128d dot = _mm_add_pd(_mm_add_pd(_mm_mul_pd(nx, dx), _mm_mul_pd(ny, dy)), _mm_mul_pd(nz, dz));
    const __m128d cosine = _mm_div_pd(dot, _mm_sqrt_pd(squared));
    const __m128d minus_cosine = _mm_xor_pd(cosine, sign);
    // voxel_sample: facing enough, within the ramp (shortened behind the surface), weight > 0.
    const __m128d facing = _mm_cmpge_pd(minus_cosine, min_cosine);
    const __m128d distance = _mm_div_pd(plane, cosine);
    const __m128d behind_surface = _mm_cmplt_pd(distance, zero);
    const __m128d ramp_here =
        _mm_or_pd(_mm_and_pd(behind_surface, _mm_mul_pd(ramp, behind)), _mm_andnot_pd(behind_surface, ramp));
    const __m128d magnitude = _mm_andnot_pd(sign, distance);
    const __m128d within = _mm_cmple_pd(magnitude, ramp_here);
    double bary[2][3];
    for (int l = 0; l < 2; ++l) c[l]->shape->bary(c[l]->E, bary[l]);
    __m128d conf = one;
    if (has_confidence) {
      const float* cf = frame.confidence.data();
      const std::uint32_t* i0 = g[0]->idx;
      const std::uint32_t* i1 = g[1]->idx;
      conf = _mm_add_pd(_mm_add_pd(_mm_mul_pd(pair(bary[0][0], bary[1][0]), pair(cf[i0[0]], cf[i1[0]])),
                                   _mm_mul_pd(pair(bary[0][1], bary[1][1]), pair(cf[i0[1]], cf[i1[1]]))),
                        _mm_mul_pd(pair(bary[0][2], bary[1][2]), pair(cf[i0[2]], cf[i1[2]])));
    }
    // tent_weight: max(0, 1 - |distance| / ramp); maxpd gives the second operand for a NaN, as
    // std::max(0.0, x) does.
    const __m128d tent = _mm_max_pd(_mm_sub_pd(one, _mm_div_pd(magnitude, ramp_here)), zero);
    const __m128d weight = _mm_mul_pd(_mm_mul_pd(minus_cosine, tent), conf);
    const __m128d positive = _mm_cmpgt_pd(weight, zero);
    const int accept = _mm_movemask_pd(_mm_andnot_pd(beyond, _mm_and_pd(_mm_and_pd(facing, within), positive))) &
                       (int(level_ok[0]) | (int(level_ok[1] && two) << 1));
    // Both lanes' samples are written and listed, and the count moves past those accepted: a
    // branch on acceptance (84 % of owned candidates on igea) waited on the chain above, and its
    // mispredictions made the pairs run one after another. A rejected lane's sample is never read;
    // an odd count's second lane is the first candidate again, with the same sample.
    const __m128 distance_f = _mm_cvtpd_ps(distance), weight_f = _mm_cvtpd_ps(weight);
    alignas(16) float df[4], wf[4];
    _mm_store_ps(df, distance_f);
    _mm_store_ps(wf, weight_f);
    sample_colour_pair(g[0]->idx, g[1]->idx, bary[0], bary[1], packed, &c[0]->sample, &c[1]->sample);
    for (int l = 0; l < 2; ++l) {
      VoxelSample& s = c[l]->sample;
      s.distance = df[l];
      s.weight = wf[l];
      batch.sampled[sampled] = k[l];
      sampled += std::size_t(accept >> l & 1);
    }
  }
  return sampled;
}
#endif

#if defined(__SSE2__) && defined(__x86_64__) && defined(__GNUC__)
// The sample phase's four lanes read four doubles at a time from a candidate's X and E, its
// owner's normal and its shape's inv_opp (the fourth lane discarded), and four floats from the
// owner's P0; they write a sample's distance and weight as one 8-byte word, and its colour bytes
// and has_colour as one 4-byte word.
static_assert(offsetof(VoxelSample, weight) == offsetof(VoxelSample, distance) + 4);
static_assert(offsetof(VoxelSample, has_colour) == offsetof(VoxelSample, colour) + 3);
static_assert(sizeof(Candidate) >= offsetof(Candidate, X) + 32 &&
              offsetof(Candidate, shape) == offsetof(Candidate, E) + 24);
static_assert(offsetof(GridTriangle, P0) == offsetof(GridTriangle, normal) + 24 &&
              offsetof(GridTriangle, idx) == offsetof(GridTriangle, P0) + 12);
static_assert(sizeof(Ownership) >= offsetof(Ownership, inv_opp) + 32);
// Rows (x, y, z, anything) of four records to lanes x, y, z.
__attribute__((target("avx2"))) inline void transpose3(__m256d r0, __m256d r1, __m256d r2, __m256d r3, __m256d* x,
                                                       __m256d* y, __m256d* z) {
  const __m256d t0 = _mm256_unpacklo_pd(r0, r1), t1 = _mm256_unpackhi_pd(r0, r1);
  const __m256d t2 = _mm256_unpacklo_pd(r2, r3), t3 = _mm256_unpackhi_pd(r2, r3);
  *x = _mm256_permute2f128_pd(t0, t2, 0x20);
  *y = _mm256_permute2f128_pd(t1, t3, 0x20);
  *z = _mm256_permute2f128_pd(t0, t2, 0x31);
}

// sample_candidates_pairs four candidates at a time, in AVX2's four double lanes where the CPU has
// them (integrate_frame_projective asks): the same operations in the same order, so the same bits
// for every accepted candidate (no multiply and add is fused: AVX2 without FMA, and the build's
// -ffp-contract=off). The candidates' centres and edge functions, the owners' normals and first
// vertices and their shapes' inverse opposite values are read a record row at a time and
// transposed into lanes, rather than put together lane by lane; barycentric coordinates,
// confidence and colour are worked out in the lanes too.
__attribute__((target("avx2"))) std::size_t sample_candidates_quads(const Prepared& p, const DepthFrame& frame,
                                                                     int level, const Vector3d& centre,
                                                                     const IntegrateOptions& options,
                                                                     const std::uint32_t* packed, ItemBatch& batch,
                                                                     std::size_t owned) {
  const bool has_confidence = !frame.confidence.empty();
  const __m256d zero = _mm256_setzero_pd(), one = _mm256_set1_pd(1.0), behind = _mm256_set1_pd(options.behind),
                min_cosine = _mm256_set1_pd(options.min_cosine), sign = _mm256_set1_pd(-0.0);
  const __m256d cx = _mm256_set1_pd(centre.x()), cy = _mm256_set1_pd(centre.y()), cz = _mm256_set1_pd(centre.z());
  std::size_t sampled = 0;
  for (std::size_t j = 0; j < owned; j += 4) {
    const int lanes = int(std::min<std::size_t>(4, owned - j));
    std::uint32_t k[4];
    const Candidate* c[4];
    const GridTriangle* g[4];
    alignas(32) double ramp_of[4];
    int level_ok = 0;
    for (int l = 0; l < 4; ++l) {
      k[l] = batch.owned[j + std::size_t(std::min(l, lanes - 1))];  // past the end: the last again
      c[l] = &batch.cand[k[l]];
      g[l] = &p.tris[c[l]->owner];
      const bool ok = !(level < g[l]->coarsest || level > g[l]->level);
      level_ok |= int(ok && l < lanes) << l;
      ramp_of[l] = ok ? p.ramp[g[l]->level][level] : 1.0;
    }
    __m256d X, Y, Z, nx, ny, nz;
    transpose3(_mm256_loadu_pd(c[0]->X.data()), _mm256_loadu_pd(c[1]->X.data()), _mm256_loadu_pd(c[2]->X.data()),
               _mm256_loadu_pd(c[3]->X.data()), &X, &Y, &Z);
    transpose3(_mm256_loadu_pd(g[0]->normal.data()), _mm256_loadu_pd(g[1]->normal.data()),
               _mm256_loadu_pd(g[2]->normal.data()), _mm256_loadu_pd(g[3]->normal.data()), &nx, &ny, &nz);
    __m128 q0 = _mm_loadu_ps(g[0]->P0.data()), q1 = _mm_loadu_ps(g[1]->P0.data()), q2 = _mm_loadu_ps(g[2]->P0.data()),
           q3 = _mm_loadu_ps(g[3]->P0.data());
    _MM_TRANSPOSE4_PS(q0, q1, q2, q3);  // q0, q1, q2: the first vertices' x, y, z
    const __m256d ramp = _mm256_load_pd(ramp_of);
    // plane = normal . (P0 - X), P0 widened from float (exact).
    const __m256d px = _mm256_sub_pd(_mm256_cvtps_pd(q0), X), py = _mm256_sub_pd(_mm256_cvtps_pd(q1), Y),
                  pz = _mm256_sub_pd(_mm256_cvtps_pd(q2), Z);
    const __m256d plane =
        _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(nx, px), _mm256_mul_pd(ny, py)), _mm256_mul_pd(nz, pz));
    const __m256d in_front = _mm256_cmp_pd(plane, zero, _CMP_GT_OQ);
    const __m256d beyond =
        _mm256_or_pd(_mm256_and_pd(in_front, _mm256_cmp_pd(plane, _mm256_mul_pd(ramp, behind), _CMP_GT_OQ)),
                     _mm256_andnot_pd(in_front, _mm256_cmp_pd(_mm256_xor_pd(plane, sign), ramp, _CMP_GT_OQ)));
    const __m256d dx = _mm256_sub_pd(X, cx), dy = _mm256_sub_pd(Y, cy), dz = _mm256_sub_pd(Z, cz);
    const __m256d squared =
        _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)), _mm256_mul_pd(dz, dz));
    const __m256d dot = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(nx, dx), _mm256_mul_pd(ny, dy)), _mm256_mul_pd(nz, dz));
    const __m256d cosine = _mm256_div_pd(dot, _mm256_sqrt_pd(squared));
    const __m256d minus_cosine = _mm256_xor_pd(cosine, sign);
    const __m256d facing = _mm256_cmp_pd(minus_cosine, min_cosine, _CMP_GE_OQ);
    const __m256d distance = _mm256_div_pd(plane, cosine);
    const __m256d behind_surface = _mm256_cmp_pd(distance, zero, _CMP_LT_OQ);
    const __m256d ramp_here = _mm256_or_pd(_mm256_and_pd(behind_surface, _mm256_mul_pd(ramp, behind)),
                                           _mm256_andnot_pd(behind_surface, ramp));
    const __m256d magnitude = _mm256_andnot_pd(sign, distance);
    const __m256d within = _mm256_cmp_pd(magnitude, ramp_here, _CMP_LE_OQ);
    // Ownership::bary in lanes: the edge functions times the owners' inverse opposite values.
    __m256d E[3], inv[3], bary[3];
    transpose3(_mm256_loadu_pd(c[0]->E), _mm256_loadu_pd(c[1]->E), _mm256_loadu_pd(c[2]->E), _mm256_loadu_pd(c[3]->E),
               &E[0], &E[1], &E[2]);
    transpose3(_mm256_loadu_pd(c[0]->shape->inv_opp), _mm256_loadu_pd(c[1]->shape->inv_opp),
               _mm256_loadu_pd(c[2]->shape->inv_opp), _mm256_loadu_pd(c[3]->shape->inv_opp), &inv[0], &inv[1], &inv[2]);
    for (int v = 0; v < 3; ++v) bary[v] = _mm256_mul_pd(E[v], inv[v]);
    __m256d conf = one;
    if (has_confidence) {
      const float* cf = frame.confidence.data();
      __m256d term[3];
      for (int v = 0; v < 3; ++v)
        term[v] = _mm256_mul_pd(bary[v],
                                _mm256_set_pd(cf[g[3]->idx[v]], cf[g[2]->idx[v]], cf[g[1]->idx[v]], cf[g[0]->idx[v]]));
      conf = _mm256_add_pd(_mm256_add_pd(term[0], term[1]), term[2]);
    }
    const __m256d tent = _mm256_max_pd(_mm256_sub_pd(one, _mm256_div_pd(magnitude, ramp_here)), zero);
    const __m256d weight = _mm256_mul_pd(_mm256_mul_pd(minus_cosine, tent), conf);
    const __m256d positive = _mm256_cmp_pd(weight, zero, _CMP_GT_OQ);
    const int accept =
        _mm256_movemask_pd(_mm256_andnot_pd(beyond, _mm256_and_pd(_mm256_and_pd(facing, within), positive))) & level_ok;
    // Each lane's colour and has_colour as one word (sample_colour_pair's bytes).
    __m128i colour = _mm_setzero_si128();
    if (packed) {
      __m128i vertex[3];
      for (int v = 0; v < 3; ++v)
        vertex[v] = _mm_set_epi32(int(packed[g[3]->idx[v]]), int(packed[g[2]->idx[v]]), int(packed[g[1]->idx[v]]),
                                  int(packed[g[0]->idx[v]]));
      colour = _mm_or_si128(interpolate_colour_quad(bary, vertex), _mm_set1_epi32(1 << 24));
    }
    // Distance and weight side by side per lane: (d0 w0 d1 w1), (d2 w2 d3 w3).
    const __m128 df = _mm256_cvtpd_ps(distance), wf = _mm256_cvtpd_ps(weight);
    alignas(16) float dw[8];
    alignas(16) std::uint32_t word[4];
    _mm_store_ps(dw, _mm_unpacklo_ps(df, wf));
    _mm_store_ps(dw + 4, _mm_unpackhi_ps(df, wf));
    _mm_store_si128(reinterpret_cast<__m128i*>(word), colour);
    for (int l = 0; l < 4; ++l) {
      VoxelSample& s = batch.cand[k[l]].sample;
      char* const bytes = reinterpret_cast<char*>(&s);
      std::memcpy(bytes + offsetof(VoxelSample, distance), dw + 2 * l, 8);  // distance, weight
      std::memcpy(bytes + offsetof(VoxelSample, colour), word + l, 4);     // colour, has_colour
      batch.sampled[sampled] = k[l];
      sampled += std::size_t(accept >> l & 1);
    }
  }
  return sampled;
}

bool cpu_has_avx2() { return __builtin_cpu_supports("avx2"); }
#else
bool cpu_has_avx2() { return false; }
#endif

std::size_t sample_candidates(const Prepared& p, const DepthFrame& frame, int level, const Vector3d& centre,
                              const IntegrateOptions& options, const std::uint32_t* packed, ItemBatch& batch,
                              std::size_t owned, bool wide_lanes) {
#if defined(__SSE2__) && defined(__x86_64__) && defined(__GNUC__)
  if (wide_lanes) return sample_candidates_quads(p, frame, level, centre, options, packed, batch, owned);
#endif
#if defined(__SSE2__) && defined(__x86_64__)
  return sample_candidates_pairs(p, frame, level, centre, options, packed, batch, owned);
#else
  return sample_candidates_scalar(p, frame, level, centre, options, packed, batch, owned);
#endif
}

bool has_prisms(const Prepared& p, int tile, int level) {
  const TileLevel& tl = p.tile_level(tile, level);
  return tl.zmin <= tl.zmax;
}

// The kernel on one work item: the candidate voxels of `fr`, its tile's frustum slab at `level`
// (clipped to the region integrated), projected, owned, sampled and written in phases. Returns the
// contributions made.
std::size_t integrate_item(const Prepared& p, const ItemFrustum& fr, int level, const RootCube& root,
                           const IntegrateOptions& options, int brick_level, bool wide_lanes, BlockCache& cache,
                           ItemBatch& batch, RowPrefilter& prefilter) {
  const DepthFrame& frame = *p.frame;
  const Sensor& sensor = frame.sensor;
  const Eigen::Matrix3d& R = sensor.R;
  const std::vector<Quad>& quad = p.quad;
  const int QW = p.QW;
  const ScratchArray<GridTriangle>& tris = p.tris;
  const QuadShapes& shapes = p.shapes;
  const Vector3d& centre = p.centre;
  const std::uint32_t* packed = p.colour.empty() ? nullptr : p.colour.data();

  const int c0 = fr.c0, c1 = fr.c1, r0 = fr.r0, r1 = fr.r1;
  const int ax = fr.ax, bx = fr.bx, cx = fr.cx;
  const std::int64_t a0 = fr.first[ax], a1 = fr.last[ax];
  const double h = root.cell_size(level);
  // Each half-space, along a column (ib, ic): m . X - k = v0 + ib vb + ic vc + (a - root.min) ma.
  // The planes carry margins far above the rounding of this affine form.
  ColumnPlane cp[8];
  for (int k = 0; k < 8; ++k) {
    const HalfSpace& hs = fr.planes[k];
    const double inv_ma = hs.m[ax] != 0 ? 1.0 / hs.m[ax] : 0.0;
    cp[k] = {hs.m.dot(root.min) - hs.k, hs.m[bx] * h, hs.m[cx] * h, hs.m[ax], inv_ma, inv_ma / h};
  }
  // The prefilter pays its set-up (every pair of a lower and an upper bound) only where the
  // index box has columns enough to skip: most items' boxes are a few voxels across, and
  // their empty columns cost less than the set-up (bench/README.md, session 39).
  const std::int64_t box_columns = (fr.last[bx] - fr.first[bx] + 1) * (fr.last[cx] - fr.first[cx] + 1);
  const bool use_prefilter = box_columns > kPrefilterColumns;
  if (use_prefilter) prefilter.set(cp, double(a0 - 1) * h, double(a1 + 1) * h, 1e-6 * h);
  // The planes by their part in a column's clip: parallel to it, bounding t below, above.
  int parallel[8], lower[8], upper[8], n_parallel = 0, n_lower = 0, n_upper = 0;
  for (int k = 0; k < 8; ++k) {
    if (cp[k].ma == 0)
      parallel[n_parallel++] = k;
    else if (cp[k].ma > 0)
      lower[n_lower++] = k;
    else
      upper[n_upper++] = k;
  }
  ColumnBounds bounds;
  bounds.set_item(cp, lower, n_lower, upper, n_upper);
  const ColumnProjector project(sensor, ax, h, ColumnTile{c0, c1, r0, r1});
  // Groups of this level: 2^glog voxels per axis, as blocks of 2^log (VoxelTable). Phase 4
  // below finds a voxel's place in its group's tile block by these offsets (x fastest), and
  // its block and place there by `place`: kTileToGroup where a group is eight blocks, else
  // the same place.
  const int log = block_log(level, brick_level), glog = tile_block_log(level, brick_level);
  const std::uint32_t in_group = (1u << glog) - 1;
  const int shift_a = ax * glog, shift_b = bx * glog, shift_c = cx * glog;
  // A voxel's group origin: its key with the low glog bits of each index cleared (phase 4).
  const std::uint64_t level_bits = VoxelKey::level_bits(level);
  const std::uint32_t aligned = ~in_group;
  const int key_a = VoxelKey::coord_shift(ax), key_b = VoxelKey::coord_shift(bx), key_c = VoxelKey::coord_shift(cx);
  const std::uint8_t* const place = glog > log ? kTileToGroup.data() : kSamePlace.data();
  std::size_t n = 0;  // candidates in the batch
  for (std::int64_t ib = fr.first[bx]; ib <= fr.last[bx]; ++ib) {
    std::int64_t ic0 = fr.first[cx], ic1 = fr.last[cx];
    if (use_prefilter && !prefilter.clip_row(double(ib), &ic0, &ic1)) continue;
    double row_value[8];  // each plane's v0 + ib vb, the row's share of its affine form
    for (int k = 0; k < 8; ++k) row_value[k] = cp[k].v0 + double(ib) * cp[k].vb;
    bounds.set_row(cp, row_value);
    Vector3d base;  // the column's centre at ia = 0
    base[ax] = root.min[ax];
    base[bx] = root.min[bx] + h * double(ib);
    double terms[3][3];  // R(i, a) X[a]: the column's fixed axes here, its own per voxel
    camera_terms(R, base, bx, terms);
    // The item's candidates go through the kernel in phases, each a loop over all of them:
    // projection (row by row, here), owner, sample, voxel, write. A candidate's work is one
    // long chain of dependent steps (a division, a floor, the quad, the shape, the owner's
    // record, a square root, two more divisions, the voxel), longer than the core's window
    // of instructions, so done candidate by candidate the chains ran one after another; in
    // loops over many candidates the chains overlap, and the owners' records and the voxels
    // asked for ahead of use (phases 2 and 4) arrive while others are worked on. Each voxel
    // gets the same arithmetic either way, and at most one contribution per depth map, so
    // the field is the same.
    for (std::int64_t ic = ic0; ic <= ic1; ++ic) {
      bool empty = false;
      for (int j = 0; j < n_parallel && !empty; ++j)
        empty = row_value[parallel[j]] + double(ic) * cp[parallel[j]].vc < 0;
      if (empty) continue;
      double tmin, tmax;  // cells along the column
      bounds.range(double(ic), &tmin, &tmax);
      if (tmin > tmax) continue;
      tmin = std::max(tmin, double(a0 - 1));  // finite before the integer casts
      tmax = std::min(tmax, double(a1 + 1));
      const std::int64_t i0 = std::max<std::int64_t>(a0, -fast_floor(-tmin));  // ceil
      const std::int64_t i1 = std::min<std::int64_t>(a1, fast_floor(tmax));
      if (i1 < i0) continue;
      base[cx] = root.min[cx] + h * double(ic);
      camera_terms(R, base, cx, terms);
      // Room for every voxel of the column and one more (project_column_pairs).
      if (n + std::size_t(i1 - i0 + 2) > batch.capacity) batch.grow(n + std::size_t(i1 - i0 + 2), n);
      // Phase 1: project; mark the voxels whose quad is this tile's.
      n = project(terms, base, i0, i1, ib, ic, batch, n);
    }
  }
  // Phase 2: the owner, one of the quad's triangles (chosen by the diagonal's side if the
  // quad is split in two, else the likelier tried first), or, on the quad's left or top
  // border, one of the neighbouring quads' (edge functions give a shared edge to one side
  // only). Trying the previous voxel's owner first, as this once did, saves nothing: it
  // owns the next only a third of the time (a step along a column moves the projection up
  // to 0.8 pixel), and the extra test and its unpredictable branch cost more
  // (bench/README.md, session 31).
  std::size_t owned = 0;
  for (std::uint32_t k = 0; k < n; ++k) {
    Candidate& cand = batch.cand[k];
    if (!cand.in) continue;
    const int col = cand.col, row = cand.row;
    const double U = cand.uv.x(), V = cand.uv.y();
    auto try_triangle = [&](const Quad& qd, int slot, double u, double v) {
      const std::uint8_t code = qd.shape[slot];
      if (!(code & Quad::kUsable)) return false;
      const Ownership& s = shapes.shape[code & 63];
      if (!s.owns_local(u, v, cand.E)) return false;
      cand.owner = qd.tri[slot];
      cand.shape = &s;
      return true;
    };
    // The quad d columns left and e rows up of q's own, where q's coordinates are one more.
    auto try_quad = [&](int d, int e, bool first_guess) {
      const int qr = row - e, qc = col - d;
      if (qr < 0 || qc < 0) return false;
      const Quad& qd = quad[std::size_t(qr) * QW + qc];
      const int first = first_guess ? 0 : 1;
      const double u = U + double(d), v = V + double(e);
      return try_triangle(qd, first, u, v) || try_triangle(qd, 1 - first, u, v);
    };
    const Quad& here = quad[std::size_t(row) * QW + col];
    if ((here.split & Quad::kSplit) && U > 0.5 && V > 0.5) {
      // Off the quad's left and top borders, q lies strictly inside both triangles' quad
      // sides, so the side of the shared diagonal alone picks the owner (the two evaluate
      // it to the same bits, each owning one side of it) and its other two edge tests pass.
      const Ownership& first = shapes.shape[here.shape[0] & 63];
      const double diagonal = first.edge_local(here.split & 3, U, V);
      const int slot = (diagonal >= 0) == bool(here.split & Quad::kPositive) ? 0 : 1;
      const Ownership& s = shapes.shape[here.shape[slot] & 63];
      s.edges_local(U, V, cand.E);
      cand.owner = here.tri[slot];
      cand.shape = &s;
    } else if (!try_quad(0, 0, (U - 1.0) * here.dx + (V - 1.0) * here.dy >= 0)) {
      const bool left = U == 0.5, top = V == 0.5;
      if (!((left && try_quad(1, 0, true)) || (top && try_quad(0, 1, true)) ||
            (left && top && try_quad(1, 1, true))))
        continue;
    }
    __builtin_prefetch(&tris[cand.owner]);  // read in the next phase
    batch.owned[owned++] = k;
  }
  // Phase 3: distance, weight and colour.
  const std::size_t sampled = sample_candidates(p, frame, level, centre, options, packed, batch, owned, wide_lanes);
  // Phase 4: the voxels, each asked for ahead of its write. A voxel's group (a 4^3 region of
  // 2^3 blocks, voxel_table.h) is its key with the low glog bits of each index cleared,
  // put together here from the lattice indices, and its block is one of the group's parts,
  // read without a lock. Each voxel asks the block cache, which mostly holds its group:
  // checking first whether the group was the previous voxel's (a column crosses a group
  // every 2^glog voxels, a new one every 2.2 candidates at igea's level 11) cost a
  // mispredicted branch at half the groups, more than the cache's hash and compare
  // (bench/README.md, session 47).
  for (std::size_t j = 0; j < sampled; ++j) {
    Candidate& cand = batch.cand[batch.sampled[j]];
    const std::uint32_t ia = std::uint32_t(cand.ia), ib = std::uint32_t(cand.ib), ic = std::uint32_t(cand.ic);
    const VoxelKey origin{level_bits | std::uint64_t(ia & aligned) << key_a | std::uint64_t(ib & aligned) << key_b |
                          std::uint64_t(ic & aligned) << key_c};
    Brick* brick;
    BlockGroup* const group = cache.group(origin, &brick);
    const unsigned q = place[((ib & in_group) << shift_b) | ((ic & in_group) << shift_c) | ((ia & in_group) << shift_a)];
    VoxelData* voxels = group->part[q >> 3].load(std::memory_order_acquire);
    if (!voxels) voxels = cache.part(*brick, *group, int(q >> 3), log);
    cand.voxel = voxels + (q & 7);
    __builtin_prefetch(cand.voxel, 1);
  }
  // Phase 5: the writes, four at a time where the depth map has colour (the voxels of an
  // item are distinct: each gets at most one contribution).
  std::size_t j = 0;
  if (!frame.colour.empty()) {
    for (; j + 4 <= sampled; j += 4) {
      VoxelData* voxels[4];
      float distance[4], weight[4];
      const std::uint8_t* colour[4];
      for (int lane = 0; lane < 4; ++lane) {
        const Candidate& cand = batch.cand[batch.sampled[j + lane]];
        voxels[lane] = cand.voxel;
        distance[lane] = cand.sample.distance;
        weight[lane] = cand.sample.weight;
        colour[lane] = cand.sample.colour;
      }
      accumulate4(voxels, distance, weight, colour);
    }
  }
  for (; j < sampled; ++j) {
    const Candidate& cand = batch.cand[batch.sampled[j]];
    const VoxelSample& v = cand.sample;
    accumulate(*cand.voxel, v.distance, v.weight, v.has_colour ? v.colour : nullptr);
  }
  return sampled;
}

}  // namespace

struct IntegrateScratch::Tables {
  Prepared prepared;
};
IntegrateScratch::IntegrateScratch() : tables(std::make_unique<Tables>()), wide_lanes(cpu_has_avx2()) {}
IntegrateScratch::~IntegrateScratch() = default;
std::size_t IntegrateScratch::bytes() const {
  const Prepared& p = tables->prepared;
  return p.quad.capacity() * sizeof(Quad) + p.tris.capacity() * sizeof(GridTriangle) +
         p.tile_levels.capacity() * sizeof(TileLevel) + p.tile_normal.capacity() * sizeof(Vector3d) +
         p.depth.capacity() * sizeof(double) + p.sight.capacity() * sizeof(Vector3d) +
         p.colour.capacity() * sizeof(std::uint32_t) +
         (p.column_side.capacity() + p.row_side.capacity()) * sizeof(Prepared::FrustumSide);
}

bool integrate_frame_projective(const DepthFrame& frame, const std::vector<FrameTriangle>& triangles,
                                const RootCube& root, const IntegrateOptions& options, BrickMap& map,
                                IntegrateStats* stats_out, const BrickBox* region, IntegrateScratch* scratch) {
  Prepared local;
  Prepared& p = scratch ? scratch->tables->prepared : local;
  Eigen::AlignedBox3d region_box;
  if (region) region_box = world_box(*region, root, map.brick_level());
  if (!prepare(frame, triangles, root, options, region ? &region_box : nullptr, &p)) return false;
  const Sensor& sensor = frame.sensor;
  const int TX = p.TX, TY = p.TY;
  const Eigen::Matrix3d& R = sensor.R;
  IntegrateStats stats = p.stats;
  const bool wide_lanes = scratch ? scratch->wide_lanes : cpu_has_avx2();
  // Work items (tile, level), ordered by the brick around their middle ("home"), so that items
  // run brick region by brick region.
  const Eigen::Matrix3d Rt = R.transpose();
  const int brick_level = map.brick_level();
  struct Item {
    std::uint64_t home;
    int tile, level;
  };
  std::vector<Item> items;
  for (int tile = 0; tile < TX * TY; ++tile)
    for (int l = p.level0; l < p.level0 + p.levels; ++l) {
      if (!has_prisms(p, tile, l)) continue;
      const TileLevel& tl = p.tile_level(tile, l);
      const double u = (tile % TX) * kTile + 0.5 * kTile + 0.5, v = (tile / TX) * kTile + 0.5 * kTile + 0.5;
      const double z = 0.5 * (tl.zmin + tl.zmax);
      const Vector3d xc((u - sensor.cx) / sensor.fx * z, (v - sensor.cy) / sensor.fy * z, z);
      const Vector3d X = Rt * (xc - sensor.t);
      items.push_back({brick_at(root, brick_level, X).packed(), tile, l});
    }
  std::sort(items.begin(), items.end(), [](const Item& a, const Item& b) {
    return a.home != b.home ? a.home < b.home : (a.tile != b.tile ? a.tile < b.tile : a.level < b.level);
  });
  // When bricks can spill, run the items in chunks of a few home bricks and let the map spill
  // between chunks: a depth map that sees the whole scene (a far view) then never needs all its
  // bricks in memory at once. Chunk boundaries are safe points: no block pointer is live there.
  constexpr std::size_t kHomeBricksPerChunk = 8;
  std::vector<std::size_t> chunk_ends;
  if (map.spills()) {
    std::size_t homes = 0;
    for (std::size_t i = 0; i < items.size(); ++i) {
      if (i > 0 && items[i].home != items[i - 1].home && ++homes % kHomeBricksPerChunk == 0) chunk_ends.push_back(i);
    }
  }
  chunk_ends.push_back(items.size());

  std::atomic<std::size_t> contributions{0};
  std::size_t chunk_begin = 0;
  for (std::size_t chunk_end : chunk_ends) {
    if (map.spills()) map.next_epoch();
    const tbb::blocked_range<std::size_t> chunk(chunk_begin, chunk_end, 1);
    tbb::parallel_for(chunk, [&](const tbb::blocked_range<std::size_t>& range) {
      std::size_t local = 0;
      BlockCache cache(map);
      ItemBatch batch;  // one work item's candidate voxels, reused item after item
      RowPrefilter prefilter;  // set for the items whose index box is wide (below)
      for (std::size_t it = range.begin(); it != range.end(); ++it) {
        const int level = items[it].level, tile = items[it].tile;
        ItemFrustum fr = item_frustum(p, root, tile, level);
        if (region) fr.clip(*region, level, brick_level);
        if (fr.empty()) continue;
        local += integrate_item(p, fr, level, root, options, brick_level, wide_lanes, cache, batch, prefilter);
      }
      contributions.fetch_add(local, std::memory_order_relaxed);
    });
    chunk_begin = chunk_end;
    if (map.spills()) map.enforce_limit();
  }
  stats.contributions = contributions;
  *stats_out = stats;
  return true;
}


namespace {

// The surface cells of a triangle with vertex P inserted at levels [coarsest, level] (FrameReach).
// `last` holds the cell last added per level: neighbouring triangles mostly share their cells,
// and leaving the repeats out keeps the sort that follows short.
void add_cells(const Vector3d& P, int level, int coarsest, const RootCube& root, std::vector<VoxelKey>& cells,
               VoxelKey last[L]) {
  for (int l = coarsest; l <= level; ++l) {
    const int cl = std::max(l - 3, 0);
    const double h = root.cell_size(cl);
    const std::int64_t n = std::int64_t{1} << cl;
    std::uint32_t c[3];
    for (int a = 0; a < 3; ++a)
      c[a] = std::uint32_t(std::clamp<std::int64_t>(std::int64_t(std::floor((P[a] - root.min[a]) / h)), 0, n - 1)
                           << (l - cl));
    const VoxelKey cell = VoxelKey::make(l, c[0], c[1], c[2]);
    if (cell != last[l]) cells.push_back(cell);
    last[l] = cell;
  }
}

template <typename T>
void sort_unique(std::vector<T>& v) {
  std::sort(v.begin(), v.end());
  v.erase(std::unique(v.begin(), v.end()), v.end());
}

}  // namespace

FrameReach frame_reach(const DepthFrame& frame, const std::vector<FrameTriangle>& triangles, const RootCube& root,
                       const IntegrateOptions& options, int brick_level, IntegrateScratch* scratch) {
  FrameReach reach;
  VoxelKey last_cell[L];
  std::fill_n(last_cell, L, VoxelKey{~std::uint64_t{0}});  // no valid key has all bits set
  auto add_bricks = [&](BrickCoord lo, BrickCoord hi) {  // inclusive
    for (std::uint32_t z = lo.z; z <= hi.z; ++z)
      for (std::uint32_t y = lo.y; y <= hi.y; ++y)
        for (std::uint32_t x = lo.x; x <= hi.x; ++x) reach.bricks.push_back(BrickCoord{x, y, z}.packed());
  };
  const double bs = root.cell_size(brick_level);
  Prepared local;
  Prepared& p = scratch ? scratch->tables->prepared : local;
  if (prepare(frame, triangles, root, options, nullptr, &p)) {
    // The bricks of every item's candidate box: integration evaluates no voxel outside them.
    for (int tile = 0; tile < p.TX * p.TY; ++tile)
      for (int l = p.level0; l < p.level0 + p.levels; ++l) {
        if (!has_prisms(p, tile, l)) continue;
        const ItemFrustum fr = item_frustum(p, root, tile, l);
        if (fr.empty()) continue;
        const auto corner = [&](const std::int64_t* c) {
          return brick_of(VoxelKey::make(l, std::uint32_t(c[0]), std::uint32_t(c[1]), std::uint32_t(c[2])), brick_level);
        };
        const BrickCoord lo = corner(fr.first), hi = corner(fr.last);
        if (lo.packed() == hi.packed()) {
          reach.bricks.push_back(lo.packed());
          continue;
        }
        // The box of a tilted or far tile's slab spans many bricks the slab misses: keep those
        // whose closed box (a little widened) meets every half-space of the slab.
        for (std::uint32_t z = lo.z; z <= hi.z; ++z)
          for (std::uint32_t y = lo.y; y <= hi.y; ++y)
            for (std::uint32_t x = lo.x; x <= hi.x; ++x) {
              const Vector3d centre = root.min + bs * (Vector3d(x, y, z) + Vector3d::Constant(0.5));
              const double half = 0.5 * bs + 1e-6 * bs;
              bool meets = true;
              for (const HalfSpace& hs : fr.planes)
                if (hs.m.dot(centre) + half * hs.m.cwiseAbs().sum() < hs.k) {
                  meets = false;
                  break;
                }
              if (meets) reach.bricks.push_back(BrickCoord{x, y, z}.packed());
            }
      }
    // Surface cells from every other row and column of quads: a level-(l - 3) cell spans about 8
    // pixels of a triangle inserted at its own level l, more at coarser l.
    for (int r = 0; r < p.QH; r += 2)
      for (int c = 0; c < p.QW; c += 2)
        for (std::int32_t t : p.quad[std::size_t(r) * p.QW + c].tri)
          if (t >= 0 && p.tris[t].ok)
            add_cells(frame.position[p.tris[t].idx[0]].cast<double>(), p.tris[t].level, p.tris[t].coarsest, root,
                      reach.cells, last_cell);
  } else {
    // Any sensor: per triangle, the bricks of its bounding box widened by its longest ramp (a
    // voxel gets a contribution only within a ramp of its triangle).
    for (const FrameTriangle& tri : triangles) {
      int lt = 0, coarsest = 0;
      if (!insertion_levels(frame, tri.data(), root, options, &lt, &coarsest)) continue;
      Eigen::AlignedBox3d box;
      for (std::uint32_t i : tri) box.extend(frame.position[i].cast<double>());
      const double pad = insertion_ramp(options, root, coarsest, lt) + 1e-6 * bs;
      const BrickCoord lo = brick_at(root, brick_level, box.min() - Vector3d::Constant(pad)),
                       hi = brick_at(root, brick_level, box.max() + Vector3d::Constant(pad));
      if (lo.packed() == hi.packed()) {
        if (reach.bricks.empty() || reach.bricks.back() != lo.packed()) reach.bricks.push_back(lo.packed());
      } else {
        add_bricks(lo, hi);
      }
      add_cells(frame.position[tri[0]].cast<double>(), lt, coarsest, root, reach.cells, last_cell);
    }
  }
  sort_unique(reach.bricks);
  sort_unique(reach.cells);
  return reach;
}

}  // namespace sf
