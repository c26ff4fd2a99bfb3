// Section 7: Delaunay complex -> 7.1 neighbourhood filter -> 7.2 snapping + Marching Tetrahedra.
//
// Data flow (N voxels, ~6.5 N Delaunay cells):
//   prepare      validate, sort by key (voxel index = rank), drop coarser voxels that coincide
//                with a finer one
//   triangulate  CGAL (delaunay.cc) on the voxels' integer lattice coordinates at the finest
//                level present; one sweep over its cells (walked sequentially, filtered in
//                parallel batches) applies the 7.1 filter and keeps the cells that can ever emit
//                (those with a negative voxel) as 16-byte index quadruples; then the
//                triangulation is freed (it is the memory peak, ~550 bytes per voxel)
//   snap         per voxel, the closest crossing (ties: the lower other voxel) among the crossing
//                edges of kept cells, by a deterministic atomic minimum; all snaps are decided
//                on the original distances and applied at once, before any cell is marched
//   march        Marching Tetrahedra per kept cell (parallel), zero faces seen from both sides
//                cancelled
//   weld         output vertices = sorted unique identities; attributes interpolated per vertex
//   clean        optional removal of small connected components; faces rotated and sorted
#include "engine/extract/extract.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <mutex>
#include <numeric>
#include <sstream>
#include <string>

#include "engine/error.h"
#include "engine/extract/brick_extract.h"
#include "storage/mailbox.h"
#include "engine/extract/delaunay.h"
#include "engine/extract/marching_tets.h"
#include "engine/extract/voxel_set.h"

namespace sf {

using extract_detail::crossing_fraction;
using extract_detail::DelaunayTetrahedralization;
using extract_detail::FieldView;
using extract_detail::MtTriangle;
using extract_detail::MtVertex;
using extract_detail::Tet;
using extract_detail::Attributes;
using extract_detail::cell_distances;
using extract_detail::cell_kind;
using extract_detail::describe;
using extract_detail::CellKind;
using extract_detail::crossing_attributes;
using extract_detail::keep_cell;
using extract_detail::to_byte;
using extract_detail::voxel_attributes;
using extract_detail::Voxels;

void ExtractOptions::check() const {
  if (neighbourhood_n < 0) {
    throw InputError("extract: neighbourhood n must be >= 0, got " + std::to_string(neighbourhood_n));
  }
  if (!(snap_fraction >= 0 && snap_fraction < 0.5)) {
    std::ostringstream s;
    s << "extract: snap fraction must be in [0, 0.5), got " << snap_fraction << " (0 turns snapping off)";
    throw InputError(s.str());
  }
  if (mode != "global" && mode != "bricks" && mode != "auto")
    throw InputError("extract: mode must be global, bricks or auto, got '" + mode + "'");
  if (brick_level < -1 || brick_level > kMaxLevel) {
    throw InputError("extract: brick level must be -1 (global) or in [0, " + std::to_string(kMaxLevel) + "], got " +
                     std::to_string(brick_level));
  }
}

bool are_neighbours(VoxelKey a, VoxelKey b, int n) {
  if (a.level() > b.level()) std::swap(a, b);
  const int shift = b.level() - a.level();
  const std::int64_t reach = (std::int64_t{1} << shift) + n;
  const auto near = [&](std::uint32_t ca, std::uint32_t cb) {
    const std::int64_t d = std::int64_t(cb) - (std::int64_t(ca) << shift);
    return -reach <= d && d <= reach;
  };
  return near(a.x(), b.x()) && near(a.y(), b.y()) && near(a.z(), b.z());
}

namespace {

constexpr double kStages = 4;  // "extract" progress steps: snap, march, weld, clean

void validate(const SurfaceVoxel& v, std::size_t i) {
  const VoxelKey k = v.key;
  const auto fail = [&](const std::string& what) {
    throw InputError("extract: voxel #" + std::to_string(i) + " " + what);
  };
  if (!valid_voxel(k.level(), k.x(), k.y(), k.z()) || (k.bits >> 62) != 0) {
    fail("has an invalid key (bits 0x" + [&] {
      std::ostringstream s;
      s << std::hex << k.bits;
      return s.str();
    }() + ")");
  }
  if (const char* problem = extract_detail::value_problem(v)) fail("at " + describe(k) + " " + problem);
}

// Sorts by key, rejects duplicated keys, and drops every voxel that coincides with a finer one.
Voxels prepare(const std::vector<SurfaceVoxel>& in, const RootCube& root, ExtractStats* st) {
  if (in.size() >= std::numeric_limits<std::uint32_t>::max()) {
    throw InputError("extract: " + std::to_string(in.size()) + " voxels; at most 2^32 - 2 are supported");
  }
  for (std::size_t i = 0; i < in.size(); ++i) validate(in[i], i);

  std::vector<std::pair<std::uint64_t, std::uint32_t>> order(in.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, in.size()), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) order[i] = {in[i].key.bits, std::uint32_t(i)};
  });
  tbb::parallel_sort(order.begin(), order.end());
  for (std::size_t i = 1; i < order.size(); ++i) {
    if (order[i].first == order[i - 1].first) {
      throw InputError("extract: voxel " + describe(VoxelKey{order[i].first}) + " is given twice (#" +
                       std::to_string(order[i - 1].second) + " and #" + std::to_string(order[i].second) + ")");
    }
  }

  // A voxel coincides with the voxels its even coordinates reach by halving; keep the finest
  // (section 6 deletes the coarser duplicates; the fusion normally has done so already).
  std::vector<std::uint8_t> drop(order.size(), 0);
  if (!order.empty() && VoxelKey{order.front().first}.level() != VoxelKey{order.back().first}.level()) {
    const auto find = [&](VoxelKey k) {
      const auto it = std::lower_bound(order.begin(), order.end(), std::pair<std::uint64_t, std::uint32_t>{k.bits, 0});
      return (it != order.end() && it->first == k.bits) ? std::ptrdiff_t(it - order.begin()) : std::ptrdiff_t(-1);
    };
    for (const auto& entry : order) {
      VoxelKey k{entry.first};
      while (k.has_coarser_twin()) {
        k = k.coarser_twin();
        const std::ptrdiff_t j = find(k);
        if (j >= 0) drop[std::size_t(j)] = 1;
      }
    }
  }

  Voxels v;
  const std::size_t kept = order.size() - std::size_t(std::count(drop.begin(), drop.end(), 1));
  st->coincident_voxels = order.size() - kept;
  v.key.resize(kept);
  v.position.resize(kept);
  v.distance.resize(kept);
  v.weight.resize(kept);
  v.scale.resize(kept);
  v.colour.resize(kept);
  std::vector<std::uint32_t> source;
  source.reserve(kept);
  for (std::size_t i = 0; i < order.size(); ++i) {
    if (!drop[i]) source.push_back(order[i].second);
  }
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, kept), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const SurfaceVoxel& s = in[source[i]];
      v.key[i] = s.key;
      v.position[i] = root.position(s.key);
      v.distance[i] = s.distance;
      v.weight[i] = s.weight;
      v.scale[i] = float(root.cell_size(s.key.level()));
      v.colour[i] = s.colour;
    }
  });
  return v;
}

// The kept cells (7.1) that can emit, before or after snapping. Snapping only turns distances
// into 0, so a cell without a negative voxel never emits, and a cell without a positive one can
// only become the negative side of a zero face (1,3,0).
struct Candidates {
  std::vector<Tet> mixed;          // negative and positive voxels: crossings, snapping
  std::vector<Tet> negative_only;  // negative and zero voxels only
};

// Triangulates and applies 7.1 while walking the cells (in batches, each filtered in parallel);
// the triangulation is freed on return.
Candidates candidate_cells(const Voxels& v, const ExtractOptions& options, const ProgressFn& progress,
                           ExtractStats* st) {
  const bool parallel = v.size() >= options.parallel_min_voxels && tbb::this_task_arena::max_concurrency() > 1;
  // Integer coordinates at the finest level present: x * 2^(finest - level) <= 2^finest <= 2^18.
  int finest = 0;
  for (VoxelKey k : v.key) finest = std::max(finest, k.level());
  std::vector<extract_detail::LatticePoint> lattice(v.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, v.size()), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const VoxelKey k = v.key[i];
      const int shift = finest - k.level();
      lattice[i] = {std::int32_t(k.x()) << shift, std::int32_t(k.y()) << shift, std::int32_t(k.z()) << shift};
    }
  });
  const DelaunayTetrahedralization dt(lattice, parallel, progress);
  std::vector<extract_detail::LatticePoint>().swap(lattice);
  struct Local {
    Candidates c;
    std::size_t kept = 0;
  };
  tbb::enumerable_thread_specific<Local> locals;
  dt.for_each_cell_batch([&](const Tet* cells, std::size_t count) {
    st->tetrahedra += count;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 2048), [&](const tbb::blocked_range<std::size_t>& r) {
      Local& local = locals.local();
      for (std::size_t i = r.begin(); i != r.end(); ++i) {
        const Tet& t = cells[i];
        if (!keep_cell(t, v, options.neighbourhood_n)) continue;
        ++local.kept;
        const CellKind kind = cell_kind(cell_distances(t, v.distance));
        if (kind != CellKind::kNever) (kind == CellKind::kMixed ? local.c.mixed : local.c.negative_only).push_back(t);
      }
    });
  });
  Candidates out;
  for (Local& l : locals) {
    st->kept_tetrahedra += l.kept;
    out.mixed.insert(out.mixed.end(), l.c.mixed.begin(), l.c.mixed.end());
    out.negative_only.insert(out.negative_only.end(), l.c.negative_only.begin(), l.c.negative_only.end());
    l.c = Candidates();  // release as we go
  }
  return out;
}

// 7.2 snapping. Candidates are packed as (fraction as float bits, other voxel index): for
// non-negative floats the bit patterns order like the values, so one 64-bit minimum picks the
// closest crossing and, on a tie, the lower other voxel (= the lower key), whatever the order in
// which threads visit the cells.
std::size_t snap_voxels(Voxels& v, const std::vector<Tet>& mixed_cells, double snap_fraction) {
  if (snap_fraction <= 0 || v.size() == 0) return 0;
  constexpr std::uint64_t kNone = ~std::uint64_t{0};
  std::vector<std::atomic<std::uint64_t>> best(v.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, best.size()), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) best[i].store(kNone, std::memory_order_relaxed);
  });
  const auto offer = [&](std::uint32_t voxel, double fraction, std::uint32_t other) {
    const float f = float(fraction);
    std::uint32_t f_bits;
    static_assert(sizeof(f) == sizeof(f_bits));
    std::memcpy(&f_bits, &f, sizeof(f));
    const std::uint64_t packed = (std::uint64_t(f_bits) << 32) | other;
    std::uint64_t cur = best[voxel].load(std::memory_order_relaxed);
    while (packed < cur && !best[voxel].compare_exchange_weak(cur, packed, std::memory_order_relaxed)) {
    }
  };
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mixed_cells.size(), 1024), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t c = r.begin(); c != r.end(); ++c) {
      const Tet& t = mixed_cells[c];
      for (int i = 0; i < 4; ++i) {
        for (int j = i + 1; j < 4; ++j) {
          const std::uint32_t lo = std::min(t[i], t[j]), hi = std::max(t[i], t[j]);
          const float d_lo = v.distance[lo], d_hi = v.distance[hi];
          if (!((d_lo < 0 && d_hi > 0) || (d_lo > 0 && d_hi < 0))) continue;
          const double f = crossing_fraction(d_lo, d_hi);
          if (f < snap_fraction) offer(lo, f, hi);
          if (1.0 - f < snap_fraction) offer(hi, 1.0 - f, lo);
        }
      }
    }
  });

  // Decide everything on the original field, then apply.
  std::vector<std::uint32_t> snapped;
  for (std::size_t i = 0; i < best.size(); ++i) {
    if (best[i].load(std::memory_order_relaxed) != kNone) snapped.push_back(std::uint32_t(i));
  }
  std::vector<Attributes> moved(snapped.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, snapped.size()), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t k = r.begin(); k != r.end(); ++k) {
      const std::uint32_t a = snapped[k];
      const std::uint32_t b = std::uint32_t(best[a].load(std::memory_order_relaxed));
      moved[k] = crossing_attributes(v, std::min(a, b), std::max(a, b));
    }
  });
  for (std::size_t k = 0; k < snapped.size(); ++k) {
    const std::uint32_t a = snapped[k];
    v.position[a] = moved[k].position;
    v.colour[a] = moved[k].colour;
    v.weight[a] = moved[k].weight;
    v.scale[a] = moved[k].scale;
    v.distance[a] = 0;
  }
  return snapped.size();
}

using IdTriangle = std::array<std::uint64_t, 3>;

// Marching Tetrahedra over the kept cells, then the zero-face rule: a zero face emitted from
// both sides (negative on both) lies inside the solid and is dropped.
std::vector<IdTriangle> march(const Voxels& v, const Candidates& cells, ExtractStats* st) {
  struct Local {
    std::vector<IdTriangle> triangles;
    std::vector<IdTriangle> zero_faces;
  };
  tbb::enumerable_thread_specific<Local> locals;
  const FieldView field = v.view();
  for (const std::vector<Tet>* list : {&cells.mixed, &cells.negative_only}) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, list->size(), 1024), [&](const tbb::blocked_range<std::size_t>& r) {
      Local& local = locals.local();
      MtTriangle out[2];
      for (std::size_t c = r.begin(); c != r.end(); ++c) {
        const Tet& t = (*list)[c];
        if (!extract_detail::emits_triangles(cell_distances(t, v.distance))) continue;
        const int n = extract_detail::march_tetrahedron(t, field, out);
        for (int k = 0; k < n; ++k) {
          const IdTriangle tri{out[k].v[0].id(), out[k].v[1].id(), out[k].v[2].id()};
          (out[k].zero_face ? local.zero_faces : local.triangles).push_back(tri);
        }
      }
    });
  }
  std::vector<IdTriangle> triangles, zero_faces;
  for (Local& l : locals) {
    triangles.insert(triangles.end(), l.triangles.begin(), l.triangles.end());
    zero_faces.insert(zero_faces.end(), l.zero_faces.begin(), l.zero_faces.end());
  }
  // Pair up zero faces by their vertex set (a face has at most two cells).
  std::vector<std::pair<IdTriangle, std::size_t>> by_set(zero_faces.size());
  for (std::size_t i = 0; i < zero_faces.size(); ++i) {
    IdTriangle s = zero_faces[i];
    std::sort(s.begin(), s.end());
    by_set[i] = {s, i};
  }
  std::sort(by_set.begin(), by_set.end());
  for (std::size_t i = 0; i < by_set.size();) {
    if (i + 1 < by_set.size() && by_set[i + 1].first == by_set[i].first) {
      ++st->interior_zero_faces;
      i += 2;
    } else {
      triangles.push_back(zero_faces[by_set[i].second]);
      i += 1;
    }
  }
  return triangles;
}

// Output vertices = the unique identities in output order (voxel_set.h: by the Morton code of
// the lower voxel's position, then by identity); faces index them.
Mesh weld(const Voxels& v, const std::vector<IdTriangle>& triangles) {
  std::vector<std::uint64_t> ids(3 * triangles.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, triangles.size()), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      for (int k = 0; k < 3; ++k) ids[3 * i + k] = triangles[i][k];
    }
  });
  tbb::parallel_sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  ids.shrink_to_fit();

  // first[a] = position of the first identity whose lower voxel is >= a: a lookup scans the few
  // identities of one voxel.
  std::vector<std::uint32_t> first(v.size() + 1, 0);
  {
    std::size_t k = 0;
    for (std::size_t a = 0; a <= v.size(); ++a) {
      while (k < ids.size() && (ids[k] >> 32) < a) ++k;
      first[a] = std::uint32_t(k);
    }
  }
  // rank[p]: output index of ids[p]. Identities sorted by their number are already in key order
  // within one lower voxel, so the output order only regroups voxels by Morton code.
  std::vector<std::uint32_t> order(ids.size()), rank(ids.size());
  std::iota(order.begin(), order.end(), std::uint32_t{0});
  {
    std::vector<std::uint64_t> home(v.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, v.size()), [&](const tbb::blocked_range<std::size_t>& r) {
      for (std::size_t i = r.begin(); i != r.end(); ++i) home[i] = extract_detail::home_code(v.key[i]);
    });
    tbb::parallel_sort(order.begin(), order.end(), [&](std::uint32_t p, std::uint32_t q) {
      const std::uint64_t hp = home[ids[p] >> 32], hq = home[ids[q] >> 32];
      return hp != hq ? hp < hq : ids[p] < ids[q];
    });
  }
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, order.size()), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t j = r.begin(); j != r.end(); ++j) rank[order[j]] = std::uint32_t(j);
  });
  const auto index_of = [&](std::uint64_t id) {
    const std::size_t a = std::size_t(id >> 32);
    const auto begin = ids.begin() + first[a], end = ids.begin() + first[a + 1];
    return rank[std::size_t(std::lower_bound(begin, end, id) - ids.begin())];
  };

  Mesh mesh;
  mesh.faces.resize(triangles.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, triangles.size()), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      for (int k = 0; k < 3; ++k) mesh.faces[i][k] = index_of(triangles[i][k]);
    }
  });
  mesh.vertices.resize(ids.size());
  mesh.colours.resize(ids.size());
  mesh.confidence.resize(ids.size());
  mesh.scale.resize(ids.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, ids.size()), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const MtVertex id = MtVertex::from_id(ids[order[i]]);
      const Attributes a = id.a == id.b ? voxel_attributes(v, id.a) : crossing_attributes(v, id.a, id.b);
      mesh.vertices[i] = a.position.cast<float>();
      mesh.colours[i] = {to_byte(a.colour[0]), to_byte(a.colour[1]), to_byte(a.colour[2])};
      mesh.confidence[i] = a.weight;
      mesh.scale[i] = a.scale;
    }
  });
  return mesh;
}

// Removes connected components (by shared vertices) with fewer than min_triangles faces and the
// vertices only they used; vertex order (by identity) is kept.
void remove_small_components(Mesh& mesh, std::size_t min_triangles, ExtractStats* st) {
  const std::size_t nv = mesh.vertices.size();
  std::vector<std::uint32_t> parent(nv);
  std::iota(parent.begin(), parent.end(), std::uint32_t{0});
  const auto find = [&](std::uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  const auto unite = [&](std::uint32_t a, std::uint32_t b) {
    a = find(a);
    b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  };
  for (const auto& f : mesh.faces) {
    unite(f[0], f[1]);
    unite(f[0], f[2]);
  }
  std::vector<std::uint32_t> count(nv, 0);
  for (const auto& f : mesh.faces) ++count[find(f[0])];
  for (std::size_t i = 0; i < nv; ++i) {
    if (count[i] > 0 && count[i] < min_triangles) ++st->removed_components;
  }
  std::vector<std::array<std::uint32_t, 3>> faces;
  faces.reserve(mesh.faces.size());
  std::vector<std::uint8_t> used(nv, 0);
  for (const auto& f : mesh.faces) {
    if (count[find(f[0])] < min_triangles) {
      ++st->removed_triangles;
      continue;
    }
    faces.push_back(f);
    used[f[0]] = used[f[1]] = used[f[2]] = 1;
  }
  std::vector<std::uint32_t> remap(nv, 0);
  std::size_t m = 0;
  for (std::size_t i = 0; i < nv; ++i) {
    if (!used[i]) continue;
    remap[i] = std::uint32_t(m);
    mesh.vertices[m] = mesh.vertices[i];
    mesh.colours[m] = mesh.colours[i];
    mesh.confidence[m] = mesh.confidence[i];
    mesh.scale[m] = mesh.scale[i];
    ++m;
  }
  mesh.vertices.resize(m);
  mesh.colours.resize(m);
  mesh.confidence.resize(m);
  mesh.scale.resize(m);
  for (auto& f : faces) {
    for (auto& i : f) i = remap[i];
  }
  mesh.faces = std::move(faces);
}

// Rotates each face so that its smallest index comes first (orientation kept), then sorts.
void sort_faces(Mesh& mesh) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.faces.size()), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      auto& f = mesh.faces[i];
      std::rotate(f.begin(), std::min_element(f.begin(), f.end()), f.end());
    }
  });
  tbb::parallel_sort(mesh.faces.begin(), mesh.faces.end());
}

}  // namespace

Mesh extract_surface(const std::vector<SurfaceVoxel>& voxels, const RootCube& root, const ExtractOptions& options,
                     const ProgressFn& progress, ExtractStats* stats) {
  options.check();
  if (options.brick_level >= 0) {
    const ScratchFolder scratch("scalefuse-extract");
    BrickExtraction bricks(scratch.path(), root, options.brick_level, options, std::size_t{1} << 30);
    bricks.add(0, voxels);
    bricks.all_added();
    MeshCollector mesh;
    bricks.run(mesh, progress, stats);
    return std::move(mesh.mesh);
  }
  ExtractStats st;
  Voxels v = prepare(voxels, root, &st);
  st.voxels = v.size();

  Candidates cells = candidate_cells(v, options, progress, &st);
  report(progress, "extract", 0, kStages);
  st.snapped_voxels = snap_voxels(v, cells.mixed, options.snap_fraction);
  report(progress, "extract", 1, kStages);
  const std::vector<IdTriangle> triangles = march(v, cells, &st);
  cells = Candidates();
  report(progress, "extract", 2, kStages);
  Mesh mesh = weld(v, triangles);
  report(progress, "extract", 3, kStages);
  if (options.min_component_triangles > 0) remove_small_components(mesh, options.min_component_triangles, &st);
  sort_faces(mesh);
  report(progress, "extract", kStages, kStages);
  st.triangles = mesh.faces.size();
  if (stats) *stats = st;
  return mesh;
}

}  // namespace sf
