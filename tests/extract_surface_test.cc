// extract_surface on synthetic fields: a sphere (closed, genus 0, outward), two octree levels
// meeting without holes, determinism across input order and thread count, and 7.1 keeping
// separate blobs apart.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <map>
#include <random>
#include <set>

#include "engine/extract/brick_extract.h"
#include "engine/extract/extract.h"
#include "storage/mailbox.h"

namespace sf {
namespace {

using Field = std::function<double(const Eigen::Vector3d&)>;    // signed distance, + outside
using Select = std::function<bool(const Eigen::Vector3d&)>;     // which positions get voxels

// All voxels of one level whose |distance| < band * cell size and that `select` accepts.
std::vector<SurfaceVoxel> band(const RootCube& root, int level, double band_cells, const Field& f,
                               const Select& select = nullptr) {
  std::vector<SurfaceVoxel> out;
  const std::uint32_t n = 1u << level;
  const double h = root.cell_size(level);
  for (std::uint32_t z = 0; z <= n; ++z)
    for (std::uint32_t y = 0; y <= n; ++y)
      for (std::uint32_t x = 0; x <= n; ++x) {
        const VoxelKey k = VoxelKey::make(level, x, y, z);
        const Eigen::Vector3d p = root.position(k);
        const double d = f(p);
        if (std::abs(d) >= band_cells * h || (select && !select(p))) continue;
        SurfaceVoxel v;
        v.key = k;
        v.distance = float(d);
        v.weight = float(1 + level);
        v.colour = {float(100 + 100 * p.x()), float(100 + 100 * p.y()), float(100 + 100 * p.z())};
        out.push_back(v);
      }
  return out;
}

// Removes coarser voxels that coincide with a finer one (section 6's last pass).
std::vector<SurfaceVoxel> remove_coinciding(std::vector<SurfaceVoxel> v) {
  std::set<std::uint64_t> keys;
  for (const SurfaceVoxel& s : v) keys.insert(s.key.bits);
  std::vector<SurfaceVoxel> out;
  for (const SurfaceVoxel& s : v) {
    if (!keys.count(s.key.finer().bits)) out.push_back(s);
  }
  return out;
}

RootCube test_root() {
  RootCube r;
  r.min = Eigen::Vector3d(-0.61, -0.57, -0.63);  // not a binary fraction: positions round
  r.size = 1.3;
  return r;
}

Field sphere(const Eigen::Vector3d& c, double r) {
  return [c, r](const Eigen::Vector3d& p) { return (p - c).norm() - r; };
}

Eigen::Vector3d corner(const Mesh& m, std::uint32_t i) { return m.vertices[i].cast<double>(); }

struct Topology {
  std::size_t boundary_edges = 0;     // directed edges without their reverse
  std::size_t duplicate_edges = 0;    // directed edges used twice (inconsistent or non-manifold)
  std::size_t non_manifold_vertices = 0;
  std::size_t components = 0;
  long euler = 0;                     // V - E + F over referenced vertices
  std::vector<std::pair<std::uint32_t, std::uint32_t>> boundary;
};

Topology topology(const Mesh& m) {
  Topology t;
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> directed;
  for (const auto& f : m.faces) {
    for (int k = 0; k < 3; ++k) ++directed[{f[k], f[(k + 1) % 3]}];
  }
  std::set<std::pair<std::uint32_t, std::uint32_t>> undirected;
  for (const auto& [e, count] : directed) {
    if (count > 1) ++t.duplicate_edges;
    if (!directed.count({e.second, e.first})) {
      ++t.boundary_edges;
      t.boundary.push_back(e);
    }
    undirected.insert({std::min(e.first, e.second), std::max(e.first, e.second)});
  }
  // Vertex manifoldness: the link of each vertex (edges a->b of its faces (v, a, b)) is one cycle
  // for an interior vertex, one path for a boundary vertex.
  std::map<std::uint32_t, std::map<std::uint32_t, std::uint32_t>> link;
  for (const auto& f : m.faces) {
    for (int k = 0; k < 3; ++k) link[f[k]][f[(k + 1) % 3]] = f[(k + 2) % 3];
  }
  for (const auto& [v, next] : link) {
    std::set<std::uint32_t> targets;
    for (const auto& [a, b] : next) targets.insert(b);
    std::uint32_t start = next.begin()->first;
    for (const auto& [a, b] : next) {
      if (!targets.count(a)) start = a;  // a path starts where nothing leads in
    }
    std::size_t steps = 0;
    std::uint32_t cur = start;
    while (next.count(cur) && steps <= next.size()) {
      cur = next.at(cur);
      ++steps;
      if (cur == start) break;
    }
    if (steps != next.size()) ++t.non_manifold_vertices;
  }
  // Components by shared vertices.
  std::vector<std::uint32_t> parent(m.vertices.size());
  for (std::uint32_t i = 0; i < parent.size(); ++i) parent[i] = i;
  std::function<std::uint32_t(std::uint32_t)> find = [&](std::uint32_t x) {
    return parent[x] == x ? x : parent[x] = find(parent[x]);
  };
  for (const auto& f : m.faces) {
    parent[find(f[1])] = find(f[0]);
    parent[find(f[2])] = find(f[0]);
  }
  std::set<std::uint32_t> roots;
  for (const auto& f : m.faces) roots.insert(find(f[0]));
  t.components = roots.size();
  t.euler = long(link.size()) - long(undirected.size()) + long(m.faces.size());
  return t;
}

double min_area(const Mesh& m) {
  double a = INFINITY;
  for (const auto& f : m.faces) {
    a = std::min(a, 0.5 * (corner(m, f[1]) - corner(m, f[0])).cross(corner(m, f[2]) - corner(m, f[0])).norm());
  }
  return a;
}

void expect_closed_sphere(const Mesh& m, const Eigen::Vector3d& c, double r, double tolerance) {
  ASSERT_FALSE(m.faces.empty());
  const Topology t = topology(m);
  EXPECT_EQ(t.boundary_edges, 0u);
  EXPECT_EQ(t.duplicate_edges, 0u);
  EXPECT_EQ(t.non_manifold_vertices, 0u);
  EXPECT_EQ(t.components, 1u);
  EXPECT_EQ(t.euler, 2);
  EXPECT_EQ(m.colours.size(), m.vertices.size());
  EXPECT_EQ(m.confidence.size(), m.vertices.size());
  EXPECT_EQ(m.scale.size(), m.vertices.size());
  double worst = 0;
  for (const auto& p : m.vertices) worst = std::max(worst, std::abs((p.cast<double>() - c).norm() - r));
  EXPECT_LT(worst, tolerance);
  std::size_t inward = 0;
  for (const auto& f : m.faces) {
    const Eigen::Vector3d n = (corner(m, f[1]) - corner(m, f[0])).cross(corner(m, f[2]) - corner(m, f[0]));
    const Eigen::Vector3d centroid = (corner(m, f[0]) + corner(m, f[1]) + corner(m, f[2])) / 3;
    if (n.dot(centroid - c) <= 0) ++inward;
  }
  EXPECT_EQ(inward, 0u) << "normals must point outward (toward positive distance)";
  EXPECT_GT(min_area(m), 0.0);
}

TEST(ExtractSurface, SphereIsClosedGenusZeroAndOutward) {
  const RootCube root = test_root();
  const Eigen::Vector3d c(0.02, -0.01, 0.03);
  const double r = 0.4;
  const int level = 6;  // h = 0.0203, r / h = 19.7
  const std::vector<SurfaceVoxel> voxels = band(root, level, 2.5, sphere(c, r));
  const double h = root.cell_size(level);
  for (double snap : {0.0, 0.2, 0.45}) {
    SCOPED_TRACE("snap " + std::to_string(snap));
    ExtractOptions o;
    o.snap_fraction = snap;
    ExtractStats st;
    const Mesh m = extract_surface(voxels, root, o, nullptr, &st);
    // Linear interpolation of |p| - r over edges up to sqrt(3) h long errs by about
    // 3 h^2 / (8 r) = 0.02 h; snapped voxels sit on crossings.
    expect_closed_sphere(m, c, r, 0.05 * h);
    EXPECT_EQ(st.voxels, voxels.size());
    EXPECT_EQ(st.triangles, m.faces.size());
    EXPECT_GT(st.tetrahedra, 5 * voxels.size());
    EXPECT_LE(st.kept_tetrahedra, st.tetrahedra);
    if (snap == 0) {
      EXPECT_EQ(st.snapped_voxels, 0u);
    } else {
      EXPECT_GT(st.snapped_voxels, 0u);
    }
    // Attributes: colour 100 + 100 * coordinate, scale = the cell size.
    for (std::size_t i = 0; i < m.vertices.size(); ++i) {
      EXPECT_NEAR(m.colours[i][0], 100 + 100 * m.vertices[i].x(), 0.51 + 100 * h);
      EXPECT_FLOAT_EQ(m.scale[i], float(h));
      EXPECT_FLOAT_EQ(m.confidence[i], float(1 + level));
    }
  }
}

TEST(ExtractSurface, SnappingRemovesSmallTriangles) {
  // Figure 7: snapping pulls voxels onto nearby crossings, so fewer, better-shaped triangles.
  const RootCube root = test_root();
  const std::vector<SurfaceVoxel> voxels = band(root, 6, 2.5, sphere({0, 0, 0}, 0.4));
  const auto quality = [](const Mesh& m, std::size_t* tiny) {
    // Count triangles whose shortest edge is under 10% of the cell size.
    *tiny = 0;
    for (const auto& f : m.faces) {
      double e = INFINITY;
      for (int k = 0; k < 3; ++k) e = std::min(e, (corner(m, f[k]) - corner(m, f[(k + 1) % 3])).norm());
      if (e < 0.1 * 1.3 / 64) ++*tiny;
    }
  };
  ExtractOptions off, on;
  off.snap_fraction = 0;
  on.snap_fraction = 0.2;
  const Mesh a = extract_surface(voxels, root, off, nullptr, nullptr);
  const Mesh b = extract_surface(voxels, root, on, nullptr, nullptr);
  std::size_t tiny_a, tiny_b;
  quality(a, &tiny_a);
  quality(b, &tiny_b);
  EXPECT_LT(b.faces.size(), a.faces.size());
  EXPECT_LT(tiny_b * 4, tiny_a) << tiny_a << " tiny triangles without snapping, " << tiny_b << " with";
}

TEST(ExtractSurface, TwoLevelSphereHasNoSeam) {
  // The coarse level (5) covers the whole sphere, the fine level (6) the half x >= 0; coarse
  // voxels that coincide with fine ones are removed, as section 6 does. Coarse voxels outside
  // the fine band stay, interleaved with the fine ones. The surface must stay closed.
  const RootCube root = test_root();
  const Eigen::Vector3d c(0.0, 0.0, 0.0);
  const double r = 0.4;
  std::vector<SurfaceVoxel> voxels = band(root, 5, 2.5, sphere(c, r));
  const std::vector<SurfaceVoxel> fine = band(root, 6, 2.5, sphere(c, r), [](const Eigen::Vector3d& p) {
    return p.x() >= 0;
  });
  voxels.insert(voxels.end(), fine.begin(), fine.end());
  const std::vector<SurfaceVoxel> kept = remove_coinciding(voxels);
  ASSERT_LT(kept.size(), voxels.size());
  ExtractStats st;
  const Mesh m = extract_surface(kept, root, ExtractOptions(), nullptr, &st);
  EXPECT_EQ(st.coincident_voxels, 0u);
  expect_closed_sphere(m, c, r, 0.05 * root.cell_size(5));
  // Both scales are present, and fine triangles are where the fine voxels are.
  std::size_t fine_vertices = 0, coarse_vertices = 0;
  for (float s : m.scale) (s < 0.75 * root.cell_size(5) ? fine_vertices : coarse_vertices)++;
  EXPECT_GT(fine_vertices, 1000u);
  EXPECT_GT(coarse_vertices, 200u);

  // Given with the coinciding coarse voxels, extract_surface drops them itself: same mesh.
  ExtractStats st2;
  const Mesh m2 = extract_surface(voxels, root, ExtractOptions(), nullptr, &st2);
  EXPECT_EQ(st2.coincident_voxels, voxels.size() - kept.size());
  EXPECT_EQ(m2.vertices, m.vertices);
  EXPECT_EQ(m2.faces, m.faces);
}

TEST(ExtractSurface, TwoLevelJumpOnAPlaneHasNoHoles) {
  // A tilted plane: level 4 everywhere, level 6 (two levels finer) on the half x >= 0.5. Boundary
  // edges may only appear along the outer border of the voxel band, never at the seam.
  RootCube root;  // [0, 1]^3
  const Eigen::Vector3d normal = Eigen::Vector3d(0.2, 0.3, 1.0).normalized();
  const Eigen::Vector3d origin(0.5, 0.5, 0.5);
  const Field plane = [&](const Eigen::Vector3d& p) { return (p - origin).dot(normal); };
  const double lo = 0.1, hi = 0.9;
  const Select inside = [&](const Eigen::Vector3d& p) {
    return p.x() >= lo && p.x() <= hi && p.y() >= lo && p.y() <= hi;
  };
  std::vector<SurfaceVoxel> voxels = band(root, 4, 2.5, plane, inside);
  const std::vector<SurfaceVoxel> fine = band(root, 6, 2.5, plane, [&](const Eigen::Vector3d& p) {
    return inside(p) && p.x() >= 0.5;
  });
  voxels.insert(voxels.end(), fine.begin(), fine.end());
  const Mesh m = extract_surface(voxels, root, ExtractOptions(), nullptr, nullptr);
  ASSERT_FALSE(m.faces.empty());
  const Topology t = topology(m);
  EXPECT_EQ(t.duplicate_edges, 0u);
  EXPECT_EQ(t.non_manifold_vertices, 0u);
  EXPECT_EQ(t.components, 1u);
  EXPECT_EQ(t.euler, 1);  // a disk
  const double margin = 1.5 * root.cell_size(4);
  for (const auto& [a, b] : t.boundary) {
    for (std::uint32_t v : {a, b}) {
      const Eigen::Vector3f p = m.vertices[v];
      const bool at_border = p.x() < lo + margin || p.x() > hi - margin || p.y() < lo + margin || p.y() > hi - margin;
      EXPECT_TRUE(at_border) << "boundary edge inside the band at " << p.transpose();
    }
  }
  // Normals toward positive distance (+normal).
  for (const auto& f : m.faces) {
    const Eigen::Vector3d n = (corner(m, f[1]) - corner(m, f[0])).cross(corner(m, f[2]) - corner(m, f[0]));
    EXPECT_GT(n.dot(normal), 0);
  }
}

TEST(ExtractSurface, ExactZerosStayClosed) {
  // Distances rounded to multiples of q cells: many voxels are exactly zero, up to whole shells
  // of them (q = 1). Every zero rule is exercised; the output (the boundary of {distance < 0})
  // must stay closed, consistently oriented and of genus 0, with and without snapping, on one
  // level and on two (the fine level on half the sphere, coinciding coarse voxels dropped).
  const RootCube root = test_root();
  const double r = 0.4;
  for (double q : {0.25, 1.0}) {
    const auto quantized = [&](int level) {
      const double step = q * root.cell_size(level);
      return [step, r](const Eigen::Vector3d& p) { return std::round((p.norm() - r) / step) * step; };
    };
    const std::vector<SurfaceVoxel> coarse = band(root, 5, 3.0, quantized(5));
    std::vector<SurfaceVoxel> both = coarse;
    const std::vector<SurfaceVoxel> fine = band(root, 6, 3.0, quantized(6), [](const Eigen::Vector3d& p) {
      return p.x() >= 0;
    });
    both.insert(both.end(), fine.begin(), fine.end());
    std::size_t zeros = 0;
    for (const SurfaceVoxel& v : both) zeros += v.distance == 0;
    EXPECT_GT(zeros, 500u);
    for (double snap : {0.0, 0.45}) {
      const std::array<const std::vector<SurfaceVoxel>*, 2> sets{&coarse, &both};
      for (const std::vector<SurfaceVoxel>* voxels : sets) {
        SCOPED_TRACE("q " + std::to_string(q) + " snap " + std::to_string(snap) + " levels " +
                     std::to_string(voxels == &coarse ? 1 : 2));
        ExtractOptions o;
        o.snap_fraction = snap;
        const Mesh m = extract_surface(*voxels, root, o, nullptr, nullptr);
        ASSERT_FALSE(m.faces.empty());
        const Topology t = topology(m);
        EXPECT_EQ(t.boundary_edges, 0u);
        EXPECT_EQ(t.duplicate_edges, 0u);
        EXPECT_EQ(t.non_manifold_vertices, 0u);
        EXPECT_EQ(t.components, 1u);
        EXPECT_EQ(t.euler, 2);
        EXPECT_GT(min_area(m), 0.0);
      }
    }
  }
}

template <class T>
bool same_bytes(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

bool same_mesh(const Mesh& a, const Mesh& b) {
  static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float));
  return same_bytes(a.vertices, b.vertices) && same_bytes(a.colours, b.colours) &&
         same_bytes(a.confidence, b.confidence) && same_bytes(a.scale, b.scale) && same_bytes(a.faces, b.faces);
}

TEST(ExtractSurface, DeterministicAcrossOrderAndThreads) {
  const RootCube root = test_root();
  std::vector<SurfaceVoxel> voxels = band(root, 5, 3.0, sphere({0.05, 0, 0}, 0.35));
  const std::vector<SurfaceVoxel> fine = band(root, 6, 2.5, sphere({0.05, 0, 0}, 0.35),
                                              [](const Eigen::Vector3d& p) { return p.z() > 0.1; });
  voxels.insert(voxels.end(), fine.begin(), fine.end());
  ExtractOptions o;
  o.min_component_triangles = 10;
  Mesh reference;
  {
    tbb::task_arena one(1);
    one.execute([&] { reference = extract_surface(voxels, root, o, nullptr, nullptr); });
  }
  ASSERT_FALSE(reference.faces.empty());
  std::mt19937 rng(3);
  for (int run = 0; run < 3; ++run) {
    std::shuffle(voxels.begin(), voxels.end(), rng);
    for (int threads : {1, 2}) {
      ExtractOptions parallel = o;
      parallel.parallel_min_voxels = 0;  // CGAL's parallel insertion whenever there are 2 threads
      Mesh m;
      tbb::task_arena arena(threads);
      arena.execute([&] { m = extract_surface(voxels, root, parallel, nullptr, nullptr); });
      EXPECT_TRUE(same_mesh(m, reference)) << "run " << run << ", " << threads << " threads";
    }
  }
}

TEST(ExtractSurface, BrickByBrickGivesTheGlobalMesh) {
  // Three levels with seams between them, brick boundaries through every region of detail.
  const RootCube root = test_root();
  std::vector<SurfaceVoxel> voxels = band(root, 4, 3.0, sphere({0.05, 0, 0}, 0.35));
  const std::vector<SurfaceVoxel> mid = band(root, 5, 3.0, sphere({0.05, 0, 0}, 0.35),
                                             [](const Eigen::Vector3d& p) { return p.z() > -0.1; });
  const std::vector<SurfaceVoxel> fine = band(root, 6, 2.5, sphere({0.05, 0, 0}, 0.35),
                                              [](const Eigen::Vector3d& p) { return p.z() > 0.1; });
  voxels.insert(voxels.end(), mid.begin(), mid.end());
  voxels.insert(voxels.end(), fine.begin(), fine.end());
  for (int n : {0, 2}) {
    ExtractOptions o;
    o.neighbourhood_n = n;
    ExtractStats global_stats;
    const Mesh reference = extract_surface(voxels, root, o, nullptr, &global_stats);
    ASSERT_GT(reference.faces.size(), 1000u);
    for (int brick_level : {0, 2, 3, 5}) {  // 5: bricks of 2 finest cells, far smaller than a ramp
      if (n == 2 && brick_level == 5) continue;  // 350 points per voxel: slow, and n = 0 covers it
      // Window groups of one brick, of a few bricks, and the default (here: all bricks at once).
      std::size_t points_one_brick = 0;
      for (std::size_t group : {std::size_t{0}, std::size_t{3000}, ExtractOptions{}.window_group_voxels}) {
        SCOPED_TRACE("n " + std::to_string(n) + ", brick level " + std::to_string(brick_level) + ", groups of " +
                     std::to_string(group) + " voxels");
        ExtractOptions by_brick = o;
        by_brick.brick_level = brick_level;
        by_brick.window_group_voxels = group;
        ExtractStats st;
        Mesh m;
        tbb::task_arena arena(2);
        arena.execute([&] { m = extract_surface(voxels, root, by_brick, nullptr, &st); });
        EXPECT_TRUE(same_mesh(m, reference));
        EXPECT_EQ(st.snapped_voxels, global_stats.snapped_voxels);
        EXPECT_GE(st.window_points + st.window_voxels_in_cubes, st.voxels);
        EXPECT_GT(st.window_voxels_in_cubes, st.voxels / 10);  // the empty cubes' cells were used
        if (group == 0) {
          EXPECT_EQ(st.windows == 1, brick_level == 0);
          points_one_brick = st.window_points + st.window_voxels_in_cubes;
        } else if (brick_level >= 2) {
          // Bricks grouped: less halo (and fewer duplicate levels) to triangulate.
          EXPECT_LT(st.window_points + st.window_voxels_in_cubes, points_one_brick);
        }
        if (group == ExtractOptions{}.window_group_voxels) {
          EXPECT_EQ(st.window_points + st.window_voxels_in_cubes, st.voxels);
        }
      }
    }
  }
}

TEST(ExtractSurface, WindowsSplitToFitTheMemoryBudgetGiveTheGlobalMesh) {
  // A budget of a few thousand points per window: windows are split in halves between their
  // owners, and their triangulations run one at a time. The mesh stays the global one. With small
  // window groups, both threads' groups hold cells counted in the budget between their windows:
  // they must still take turns, not wait on each other for ever.
  const RootCube root = test_root();
  std::vector<SurfaceVoxel> voxels = band(root, 4, 3.0, sphere({0.05, 0, 0}, 0.35));
  const std::vector<SurfaceVoxel> fine = band(root, 6, 2.5, sphere({0.05, 0, 0}, 0.35),
                                              [](const Eigen::Vector3d& p) { return p.z() > 0.1; });
  voxels.insert(voxels.end(), fine.begin(), fine.end());
  const ExtractOptions o;
  const Mesh reference = extract_surface(voxels, root, o, nullptr, nullptr);
  ASSERT_GT(reference.faces.size(), 1000u);
  for (int brick_level : {1, 2, 3}) {
    SCOPED_TRACE("brick level " + std::to_string(brick_level));
    ExtractOptions by_brick = o;
    if (brick_level == 3) by_brick.window_group_voxels = 2000;
    const ScratchFolder scratch("scalefuse-split-test");
    BrickExtraction bricks(scratch.path(), root, brick_level, by_brick, std::size_t{4} << 20);  // 3,200 points a window
    bricks.add(0, voxels);
    bricks.all_added();
    MeshCollector mesh;
    ExtractStats st;
    tbb::task_arena arena(2);
    arena.execute([&] { bricks.run(mesh, nullptr, &st); });
    EXPECT_TRUE(same_mesh(mesh.mesh, reference));
    EXPECT_GT(st.windows_split, 0u);
  }
}

TEST(ExtractSurface, BrickByBrickHandlesExactZerosAndComponentRemoval) {
  // Zero shells (zero faces, interior zero faces cancelled by two different bricks' cells) and
  // component removal across pieces: the same bytes as the global extraction.
  const RootCube root = test_root();
  const double r = 0.4;
  for (double q : {0.25, 1.0}) {
    const auto quantized = [&](int level) {
      const double step = q * root.cell_size(level);
      return [step, r](const Eigen::Vector3d& p) { return std::round((p.norm() - r) / step) * step; };
    };
    std::vector<SurfaceVoxel> voxels = band(root, 5, 3.0, quantized(5));
    const std::vector<SurfaceVoxel> fine = band(root, 6, 3.0, quantized(6), [](const Eigen::Vector3d& p) {
      return p.x() >= 0;
    });
    voxels.insert(voxels.end(), fine.begin(), fine.end());
    for (double snap : {0.0, 0.45}) {
      ExtractOptions o;
      o.snap_fraction = snap;
      ExtractStats global_stats;
      const Mesh reference = extract_surface(voxels, root, o, nullptr, &global_stats);
      ASSERT_FALSE(reference.faces.empty());
      for (int brick_level : {2, 4}) {
        SCOPED_TRACE("q " + std::to_string(q) + " snap " + std::to_string(snap) + " brick level " +
                     std::to_string(brick_level));
        ExtractOptions by_brick = o;
        by_brick.brick_level = brick_level;
        by_brick.window_group_voxels = brick_level == 2 ? 0 : 2000;
        ExtractStats st;
        const Mesh m = extract_surface(voxels, root, by_brick, nullptr, &st);
        EXPECT_TRUE(same_mesh(m, reference));
        EXPECT_EQ(st.interior_zero_faces, global_stats.interior_zero_faces);
        EXPECT_EQ(st.coincident_voxels, global_stats.coincident_voxels);
      }
    }
  }
  // Two blobs; the smaller is removed as a component. One blob spans several bricks.
  const Eigen::Vector3d a(-0.25, 0, 0), b(0.2, 0.02, 0);
  const Field two = [&](const Eigen::Vector3d& p) { return std::min((p - a).norm() - 0.12, (p - b).norm() - 0.08); };
  const std::vector<SurfaceVoxel> blobs = band(root, 6, 2.5, two);
  ExtractOptions o;
  ExtractStats whole;
  const std::size_t all = extract_surface(blobs, root, o, nullptr, &whole).faces.size();
  o.min_component_triangles = all / 2;
  ExtractStats global_stats;
  const Mesh reference = extract_surface(blobs, root, o, nullptr, &global_stats);
  ASSERT_EQ(global_stats.removed_components, 1u);
  for (int brick_level : {1, 3}) {
    SCOPED_TRACE("blobs, brick level " + std::to_string(brick_level));
    ExtractOptions by_brick = o;
    by_brick.brick_level = brick_level;
    by_brick.window_group_voxels = brick_level == 1 ? 0 : 2000;
    ExtractStats st;
    const Mesh m = extract_surface(blobs, root, by_brick, nullptr, &st);
    EXPECT_TRUE(same_mesh(m, reference));
    EXPECT_EQ(st.removed_components, 1u);
    EXPECT_EQ(st.removed_triangles, global_stats.removed_triangles);
  }
}

TEST(ExtractSurface, ProgressIsReported) {
  const RootCube root = test_root();
  const std::vector<SurfaceVoxel> voxels = band(root, 5, 2.5, sphere({0, 0, 0}, 0.3));
  std::map<std::string, std::pair<double, double>> last;
  const ProgressFn progress = [&](std::string_view stage, double done, double total) {
    EXPECT_LE(done, total);
    last[std::string(stage)] = {done, total};
  };
  extract_surface(voxels, root, ExtractOptions(), progress, nullptr);
  ASSERT_TRUE(last.count("tetrahedralize"));
  ASSERT_TRUE(last.count("extract"));
  EXPECT_EQ(last["tetrahedralize"].first, double(voxels.size()));
  EXPECT_EQ(last["extract"].first, last["extract"].second);
}

TEST(ExtractSurface, NeighbourhoodKeepsSeparateBlobsApart) {
  // Two spheres 0.2 apart (10 cells at level 6): the Delaunay complex joins them, 7.1 must cut
  // every tetrahedron between them, so no triangle bridges the gap.
  const RootCube root = test_root();
  const Eigen::Vector3d a(-0.25, 0, 0), b(0.2, 0.02, 0);
  const double ra = 0.12, rb = 0.08;
  const Field two = [&](const Eigen::Vector3d& p) { return std::min((p - a).norm() - ra, (p - b).norm() - rb); };
  const std::vector<SurfaceVoxel> voxels = band(root, 6, 2.5, two);
  ExtractStats st;
  const Mesh m = extract_surface(voxels, root, ExtractOptions(), nullptr, &st);
  EXPECT_LT(st.kept_tetrahedra, st.tetrahedra);
  std::size_t faces_a = 0, faces_b = 0;
  for (const auto& f : m.faces) {
    int near_a = 0;
    for (std::uint32_t v : f) near_a += (corner(m, v) - a).norm() < (corner(m, v) - b).norm();
    EXPECT_TRUE(near_a == 0 || near_a == 3) << "a triangle bridges the blobs";
    (near_a == 3 ? faces_a : faces_b)++;
  }
  const Topology t = topology(m);
  EXPECT_EQ(t.components, 2u);
  EXPECT_EQ(t.boundary_edges, 0u);
  EXPECT_EQ(t.euler, 4);  // two spheres

  // Component removal: dropping everything smaller than the big blob leaves the big blob.
  ExtractOptions o;
  o.min_component_triangles = std::max(faces_a, faces_b);
  ExtractStats st2;
  const Mesh big = extract_surface(voxels, root, o, nullptr, &st2);
  EXPECT_EQ(st2.removed_components, 1u);
  EXPECT_EQ(st2.removed_triangles, std::min(faces_a, faces_b));
  EXPECT_EQ(big.faces.size(), std::max(faces_a, faces_b));
  EXPECT_EQ(topology(big).euler, 2);
  for (const auto& p : big.vertices) EXPECT_LT((p.cast<double>() - a).norm(), ra + 0.05);
  // Unreferenced vertices are gone and indices still sorted by identity (ascending positions
  // of the key order cannot be checked here; indices must be dense).
  std::set<std::uint32_t> used;
  for (const auto& f : big.faces) used.insert(f.begin(), f.end());
  EXPECT_EQ(used.size(), big.vertices.size());
}

}  // namespace
}  // namespace sf
