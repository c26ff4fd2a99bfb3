// Section 7.2 on single tetrahedra: every sign pattern, snapping, the zero-face rule; and the
// 7.1 neighbourhood relation, with hand-worked cases.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <map>
#include <set>

#include "engine/error.h"
#include "engine/extract/extract.h"
#include "engine/extract/marching_tets.h"

namespace sf {
namespace {

using extract_detail::FieldView;
using extract_detail::march_tetrahedron;
using extract_detail::MtTriangle;
using extract_detail::MtVertex;

// ---- 7.1 neighbourhood ------------------------------------------------------------------------

TEST(ExtractNeighbours, SameLevel) {
  // Same level: reach 2^0 + n per axis. n = 2: an offset of 3 is a neighbour, 4 is not.
  const VoxelKey a = VoxelKey::make(4, 8, 8, 8);
  EXPECT_TRUE(are_neighbours(a, VoxelKey::make(4, 11, 8, 8), 2));
  EXPECT_TRUE(are_neighbours(a, VoxelKey::make(4, 5, 5, 11), 2));
  EXPECT_FALSE(are_neighbours(a, VoxelKey::make(4, 12, 8, 8), 2));
  EXPECT_FALSE(are_neighbours(a, VoxelKey::make(4, 8, 4, 8), 2));
  EXPECT_FALSE(are_neighbours(a, VoxelKey::make(4, 9, 9, 12), 2));  // one axis too far is enough
  // n = 0: the 27-neighbourhood.
  EXPECT_TRUE(are_neighbours(a, VoxelKey::make(4, 9, 7, 9), 0));
  EXPECT_FALSE(are_neighbours(a, VoxelKey::make(4, 10, 8, 8), 0));
  EXPECT_TRUE(are_neighbours(a, a, 0));
}

TEST(ExtractNeighbours, AcrossLevels) {
  // A at level 3, (2, 3, 4) sits at (8, 12, 16) of level 5 (factor 4); reach 4 + n = 6 there.
  const VoxelKey a = VoxelKey::make(3, 2, 3, 4);
  EXPECT_TRUE(are_neighbours(a, VoxelKey::make(5, 14, 12, 16), 2));   // +6
  EXPECT_TRUE(are_neighbours(a, VoxelKey::make(5, 2, 6, 10), 2));     // -6 on every axis
  EXPECT_FALSE(are_neighbours(a, VoxelKey::make(5, 15, 12, 16), 2));  // +7
  EXPECT_FALSE(are_neighbours(a, VoxelKey::make(5, 8, 5, 16), 2));    // -7 on y
  EXPECT_TRUE(are_neighbours(VoxelKey::make(5, 14, 12, 16), a, 2));   // symmetric
  EXPECT_FALSE(are_neighbours(VoxelKey::make(5, 15, 12, 16), a, 2));
  // One level apart (factor 2): reach 2 + n. Figure 5 in 3D with n = 1: the fine voxels within
  // the coarse voxel's 27-cube (offsets -2..2) plus one ring (offset 3).
  const VoxelKey c = VoxelKey::make(2, 1, 1, 1);  // = (2, 2, 2) at level 3
  EXPECT_TRUE(are_neighbours(c, VoxelKey::make(3, 5, 2, 2), 1));
  EXPECT_TRUE(are_neighbours(c, VoxelKey::make(3, 0, 0, 0), 1));
  EXPECT_FALSE(are_neighbours(c, VoxelKey::make(3, 6, 2, 2), 1));
  // The coarser voxel's own reach does not grow with n at its level: two coarse voxels 3 apart
  // are not neighbours with n = 1 (reach 2), although the fine ring reaches that far in metres.
  EXPECT_FALSE(are_neighbours(c, VoxelKey::make(2, 4, 1, 1), 1));
  EXPECT_TRUE(are_neighbours(c, VoxelKey::make(2, 3, 1, 1), 1));
  // Coinciding voxels of different levels are neighbours.
  EXPECT_TRUE(are_neighbours(c, c.finer(), 0));
  // Far level gap: level 0 voxel (1,1,1) sits at (2^10, ...) of level 10; reach 2^10 + n.
  const VoxelKey root_corner = VoxelKey::make(0, 1, 1, 1);
  EXPECT_TRUE(are_neighbours(root_corner, VoxelKey::make(10, 0, 0, 0), 0));
  EXPECT_TRUE(are_neighbours(root_corner, VoxelKey::make(10, 1024, 512, 1), 0));
}

TEST(ExtractOptionsCheck, RejectsBadValues) {
  ExtractOptions o;
  EXPECT_NO_THROW(o.check());
  o.neighbourhood_n = -1;
  EXPECT_THROW(o.check(), InputError);
  o = ExtractOptions();
  o.snap_fraction = 0.5;
  EXPECT_THROW(o.check(), InputError);
  o.snap_fraction = -0.01;
  EXPECT_THROW(o.check(), InputError);
  o.snap_fraction = 0.0;
  EXPECT_NO_THROW(o.check());
  o.snap_fraction = 0.49;
  EXPECT_NO_THROW(o.check());
}

// ---- Marching Tetrahedra on one tetrahedron ---------------------------------------------------

// A positively oriented tetrahedron: v0 at the origin, v1..v3 on the axes (det = 1 > 0).
struct OneTet {
  std::array<Eigen::Vector3d, 4> p{Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0, 1, 0),
                                   Eigen::Vector3d(0, 0, 1)};
  std::array<float, 4> d{};
  FieldView view() const { return FieldView{p.data(), d.data()}; }
};

// Expected number of triangles for (negative, zero, positive) counts.
int expected_triangles(int neg, int zero, int pos) {
  if (neg == 0 || (pos == 0 && zero != 3)) return 0;  // positive side only, all zero, or touching
  if (pos == 0) return 1;                             // (1,3,0): the zero face
  if (zero == 0) return (neg == 2) ? 2 : 1;           // (1,0,3) (3,0,1) one, (2,0,2) two
  if (zero == 3) return 0;                            // impossible with neg, pos > 0
  return zero <= 2 ? 1 : 0;                           // (1,1,2) (2,1,1) (1,2,1); (2,2,0).. handled above
}

double area(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  return 0.5 * (b - a).cross(c - a).norm();
}

// The field is linear inside a tetrahedron: f(x) = d0 + g . (x - p0).
Eigen::Vector3d gradient(const OneTet& t) {
  Eigen::Matrix3d m;
  for (int i = 0; i < 3; ++i) m.row(i) = (t.p[i + 1] - t.p[0]).transpose();
  const Eigen::Vector3d rhs(t.d[1] - t.d[0], t.d[2] - t.d[0], t.d[3] - t.d[0]);
  return m.fullPivLu().solve(rhs);
}

TEST(ExtractMarching, EverySignPattern) {
  // Magnitudes differ per vertex so that crossings are not at edge midpoints.
  const std::array<float, 4> magnitude{0.25f, 0.5f, 1.0f, 2.0f};
  for (int code = 0; code < 81; ++code) {
    OneTet t;
    int neg = 0, zero = 0, pos = 0;
    for (int i = 0, c = code; i < 4; ++i, c /= 3) {
      const int s = c % 3 - 1;  // -1, 0, +1
      t.d[i] = float(s) * magnitude[i];
      (s < 0 ? neg : s == 0 ? zero : pos)++;
    }
    SCOPED_TRACE("pattern " + std::to_string(code) + " d = " + std::to_string(t.d[0]) + " " +
                 std::to_string(t.d[1]) + " " + std::to_string(t.d[2]) + " " + std::to_string(t.d[3]));
    MtTriangle out[2];
    const int n = march_tetrahedron({0, 1, 2, 3}, t.view(), out);
    EXPECT_EQ(n, expected_triangles(neg, zero, pos));
    EXPECT_EQ(n > 0, extract_detail::emits_triangles(t.d));
    const Eigen::Vector3d g = gradient(t);
    std::set<std::uint64_t> seen;
    for (int k = 0; k < n; ++k) {
      const MtTriangle& tri = out[k];
      EXPECT_EQ(tri.zero_face, zero == 3);
      std::array<Eigen::Vector3d, 3> q;
      for (int j = 0; j < 3; ++j) {
        const MtVertex v = tri.v[j];
        ASSERT_LE(v.a, v.b);
        ASSERT_LT(v.b, 4u);
        if (v.a == v.b) {
          EXPECT_EQ(t.d[v.a], 0.0f) << "a voxel vertex must be a zero voxel";
        } else {
          EXPECT_LT(double(t.d[v.a]) * double(t.d[v.b]), 0.0) << "a crossing needs opposite signs";
        }
        q[j] = extract_detail::vertex_position(t.view(), v);
        // Every vertex lies on the zero set of the linear field.
        EXPECT_NEAR(t.d[0] + g.dot(q[j] - t.p[0]), 0.0, 1e-12);
      }
      EXPECT_FALSE(tri.v[0] == tri.v[1] || tri.v[1] == tri.v[2] || tri.v[0] == tri.v[2]);
      EXPECT_GT(area(q[0], q[1], q[2]), 1e-3) << "no zero-area triangles";
      // Orientation: the normal points toward positive distance.
      const Eigen::Vector3d normal = (q[1] - q[0]).cross(q[2] - q[0]);
      EXPECT_GT(normal.dot(g), 0.0);
      // The two triangles of a quad share exactly one edge, and together cover 4 vertices.
      for (const MtVertex& v : tri.v) seen.insert(v.id());
    }
    if (n == 2) {
      EXPECT_EQ(seen.size(), 4u);
    }
  }
}

TEST(ExtractMarching, CrossingInterpolation) {
  // (1,0,3): d0 = -1, d1 = 3 -> crossing at 1/4 of v0->v1; d2 = 1 -> 1/2; d3 = 9 -> 1/10.
  OneTet t;
  t.d = {-1, 3, 1, 9};
  MtTriangle out[2];
  ASSERT_EQ(march_tetrahedron({0, 1, 2, 3}, t.view(), out), 1);
  std::map<std::uint64_t, Eigen::Vector3d> expect{{MtVertex::edge(0, 1).id(), {0.25, 0, 0}},
                                                  {MtVertex::edge(0, 2).id(), {0, 0.5, 0}},
                                                  {MtVertex::edge(0, 3).id(), {0, 0, 0.1}}};
  for (const MtVertex& v : out[0].v) {
    ASSERT_TRUE(expect.count(v.id()));
    EXPECT_TRUE(extract_detail::vertex_position(t.view(), v).isApprox(expect[v.id()], 1e-12));
  }
  // The fraction is computed from the lower index whichever end the caller names.
  EXPECT_EQ(extract_detail::crossing_fraction(-1.0f, 3.0f), 0.25);
}

TEST(ExtractMarching, IndependentOfVertexOrder) {
  // Every positively oriented vertex order of the same tetrahedron (odd permutations get two
  // vertices swapped back) must give the same triangles, up to rotation.
  OneTet t;
  t.d = {-0.3f, 0.7f, -0.9f, 0.4f};  // (2,0,2): the quad, whose diagonal must not depend on order
  const auto canonical = [](MtTriangle tri) {
    std::array<std::uint64_t, 3> id{tri.v[0].id(), tri.v[1].id(), tri.v[2].id()};
    std::rotate(id.begin(), std::min_element(id.begin(), id.end()), id.end());
    return id;
  };
  std::set<std::array<std::uint64_t, 3>> reference;
  MtTriangle out[2];
  ASSERT_EQ(march_tetrahedron({0, 1, 2, 3}, t.view(), out), 2);
  for (int k = 0; k < 2; ++k) reference.insert(canonical(out[k]));
  std::array<std::uint32_t, 4> perm{0, 1, 2, 3};
  do {
    int inversions = 0;
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j) inversions += perm[i] > perm[j];
    std::array<std::uint32_t, 4> tet = perm;
    if (inversions % 2) std::swap(tet[0], tet[1]);
    ASSERT_EQ(march_tetrahedron(tet, t.view(), out), 2);
    std::set<std::array<std::uint64_t, 3>> got{canonical(out[0]), canonical(out[1])};
    EXPECT_EQ(got, reference);
  } while (std::next_permutation(perm.begin(), perm.end()));
}

// ---- End to end on one tetrahedron: 4 voxels -> exactly one Delaunay cell --------------------

RootCube unit_root() {
  RootCube r;
  r.min = Eigen::Vector3d(0, 0, 0);
  r.size = 1.0;
  return r;
}

std::vector<SurfaceVoxel> corner_voxels(const std::array<float, 4>& d) {
  // Level 2 (cell 0.25): (0,0,0) (1,0,0) (0,1,0) (0,0,1), positively oriented in this order.
  const std::array<VoxelKey, 4> k{VoxelKey::make(2, 0, 0, 0), VoxelKey::make(2, 1, 0, 0), VoxelKey::make(2, 0, 1, 0),
                                  VoxelKey::make(2, 0, 0, 1)};
  std::vector<SurfaceVoxel> v(4);
  for (int i = 0; i < 4; ++i) {
    v[i].key = k[i];
    v[i].distance = d[i];
    v[i].weight = float(i + 1);
    v[i].colour = {float(40 * i), 255.0f - float(40 * i), 100.0f};
  }
  return v;
}

TEST(ExtractSurfaceOneTet, EverySignPatternEndToEnd) {
  const std::array<float, 4> magnitude{0.25f, 0.5f, 1.0f, 2.0f};
  ExtractOptions o;
  o.snap_fraction = 0;  // patterns as given
  for (int code = 0; code < 81; ++code) {
    std::array<float, 4> d;
    int neg = 0, zero = 0, pos = 0;
    for (int i = 0, c = code; i < 4; ++i, c /= 3) {
      const int s = c % 3 - 1;
      d[i] = float(s) * magnitude[i];
      (s < 0 ? neg : s == 0 ? zero : pos)++;
    }
    SCOPED_TRACE("pattern " + std::to_string(code));
    ExtractStats st;
    const Mesh m = extract_surface(corner_voxels(d), unit_root(), o, nullptr, &st);
    EXPECT_EQ(st.tetrahedra, 1u);
    EXPECT_EQ(st.kept_tetrahedra, 1u);
    EXPECT_EQ(int(m.faces.size()), expected_triangles(neg, zero, pos));
    EXPECT_EQ(m.colours.size(), m.vertices.size());
    EXPECT_EQ(m.confidence.size(), m.vertices.size());
    EXPECT_EQ(m.scale.size(), m.vertices.size());
    for (const auto& f : m.faces) {
      const Eigen::Vector3d a = m.vertices[f[0]].cast<double>(), b = m.vertices[f[1]].cast<double>(),
                            c = m.vertices[f[2]].cast<double>();
      EXPECT_GT(area(a, b, c), 1e-4);
      EXPECT_LT(f[0], f[1]);  // rotated: smallest index first
      EXPECT_LT(f[0], f[2]);
    }
    for (float s : m.scale) EXPECT_FLOAT_EQ(s, 0.25f);
  }
}

TEST(ExtractSurfaceOneTet, AttributesAreInterpolated) {
  // (1,0,3): d = (-1, 3, 1, 1) -> crossings at 1/4, 1/2, 1/2 from v0.
  std::vector<SurfaceVoxel> v = corner_voxels({-1, 3, 1, 1});
  ExtractOptions o;
  o.snap_fraction = 0;
  const Mesh m = extract_surface(v, unit_root(), o, nullptr, nullptr);
  ASSERT_EQ(m.faces.size(), 1u);
  ASSERT_EQ(m.vertices.size(), 3u);
  // Vertices sorted by identity: (v0,v1) (v0,v2) (v0,v3) with v0..v3 in key order (z, y, x):
  // key order is (0,0,0) < (1,0,0) < (0,1,0) < (0,0,1), the input order here.
  EXPECT_TRUE(m.vertices[0].isApprox(Eigen::Vector3f(0.0625f, 0, 0)));
  EXPECT_TRUE(m.vertices[1].isApprox(Eigen::Vector3f(0, 0.125f, 0)));
  EXPECT_TRUE(m.vertices[2].isApprox(Eigen::Vector3f(0, 0, 0.125f)));
  // weight 1 -> 2 at t = 1/4: 1.25; colour (0,255,100) -> (40,215,100) at 1/4: (10, 245, 100).
  EXPECT_FLOAT_EQ(m.confidence[0], 1.25f);
  EXPECT_EQ(m.colours[0], (Rgb8{10, 245, 100}));
  // weight 1 -> 3 at 1/2: 2; colour -> (80,175,100) at 1/2: (40, 215, 100).
  EXPECT_FLOAT_EQ(m.confidence[1], 2.0f);
  EXPECT_EQ(m.colours[1], (Rgb8{40, 215, 100}));
  // Orientation: the normal points away from the negative corner (toward +x+y+z).
  const Eigen::Vector3f n = (m.vertices[m.faces[0][1]] - m.vertices[m.faces[0][0]])
                                .cross(m.vertices[m.faces[0][2]] - m.vertices[m.faces[0][0]]);
  EXPECT_GT(n.dot(Eigen::Vector3f(1, 1, 1)), 0);
}

// ---- Snapping ----------------------------------------------------------------------------------

TEST(ExtractSnapping, MovesOnlyCloseCrossings) {
  // d = (-0.1, 0.9, 0.5, -1): crossings v0-v1 at 0.1 and v0-v2 at 0.1/0.6 = 0.17 from v0;
  // v2-v3 at 0.33 from v2, v1-v3 at 0.47 from v1. With snap 0.2 only v0 moves, onto the closer
  // crossing: 0.1 of the way to v1 = (0.025, 0, 0), weight 1 -> 2 at 0.1 = 1.1. The pattern turns
  // from (2,0,2) (a quad) into (1,1,2): one triangle (v0, X(v1,v3), X(v2,v3)).
  ExtractOptions o;
  o.snap_fraction = 0.2;
  ExtractStats st;
  Mesh m = extract_surface(corner_voxels({-0.1f, 0.9f, 0.5f, -1}), unit_root(), o, nullptr, &st);
  EXPECT_EQ(st.snapped_voxels, 1u);
  ASSERT_EQ(m.faces.size(), 1u);
  ASSERT_EQ(m.vertices.size(), 3u);
  EXPECT_TRUE(m.vertices[0].isApprox(Eigen::Vector3f(0.025f, 0, 0))) << m.vertices[0].transpose();
  EXPECT_FLOAT_EQ(m.confidence[0], 1.1f);

  // The crossing at 0.3 instead (d0 = -0.3, d1 = 0.7; v0-v2 at 0.375, v2-v3 0.33, v1-v3 0.41):
  // nothing within 0.2 -> the quad, two triangles on four crossings.
  m = extract_surface(corner_voxels({-0.3f, 0.7f, 0.5f, -1}), unit_root(), o, nullptr, &st);
  EXPECT_EQ(st.snapped_voxels, 0u);
  EXPECT_EQ(m.faces.size(), 2u);
  EXPECT_EQ(m.vertices.size(), 4u);

  // Snapping off: the 0.1 crossing stays a crossing.
  o.snap_fraction = 0;
  m = extract_surface(corner_voxels({-0.1f, 0.9f, 0.5f, -1}), unit_root(), o, nullptr, &st);
  EXPECT_EQ(st.snapped_voxels, 0u);
  EXPECT_EQ(m.faces.size(), 2u);
  EXPECT_EQ(m.vertices.size(), 4u);
}

TEST(ExtractSnapping, ClosestCrossingWins) {
  // v0 = -0.1 has crossings toward v1 (+0.9: at 0.1) and v2 (+1.9: at 0.05): it snaps onto the
  // closer one, on edge v0-v2. All three crossings of v0 are close, so after snapping the
  // tetrahedron is (0,+,+,+) -> nothing to emit.
  ExtractOptions o;
  o.snap_fraction = 0.2;
  ExtractStats st;
  const Mesh m = extract_surface(corner_voxels({-0.1f, 0.9f, 1.9f, 0.9f}), unit_root(), o, nullptr, &st);
  EXPECT_EQ(st.snapped_voxels, 1u);
  EXPECT_TRUE(m.faces.empty());
  // With v3 = -1 (its crossings are at 0.53 and 0.34 from it: no snap) the snapped tetrahedron
  // is (1 negative, 1 zero, 2 positive): one triangle, and its zero vertex shows where v0 went:
  // 0.05 of the way to v2 = (0, 0.0125, 0).
  const Mesh m2 = extract_surface(corner_voxels({-0.1f, 0.9f, 1.9f, -1.0f}), unit_root(), o, nullptr, &st);
  EXPECT_EQ(st.snapped_voxels, 1u);
  ASSERT_EQ(m2.faces.size(), 1u);
  bool found = false;
  for (const auto& p : m2.vertices) found |= p.isApprox(Eigen::Vector3f(0, 0.0125f, 0), 1e-5f);
  EXPECT_TRUE(found);
}

// ---- The zero-face rule across two tetrahedra -------------------------------------------------

// A triangular bipyramid: the zero face A B C at z = 6 (level 4), apexes P above and Q below,
// far enough that the Delaunay complex is exactly the two tetrahedra A B C P and A B C Q.
std::vector<SurfaceVoxel> bipyramid(float p, float q) {
  const std::array<VoxelKey, 5> k{VoxelKey::make(4, 0, 0, 6), VoxelKey::make(4, 4, 1, 6), VoxelKey::make(4, 1, 4, 6),
                                  VoxelKey::make(4, 2, 2, 10), VoxelKey::make(4, 2, 2, 2)};
  const std::array<float, 5> d{0, 0, 0, p, q};
  std::vector<SurfaceVoxel> v(5);
  for (int i = 0; i < 5; ++i) {
    v[i].key = k[i];
    v[i].distance = d[i];
  }
  return v;
}

TEST(ExtractZeroFaces, EmittedOnceFromTheNegativeSide) {
  ExtractOptions o;
  o.neighbourhood_n = 8;  // keep both tetrahedra (apexes are 4 voxels from the face)
  o.snap_fraction = 0;
  ExtractStats st;
  struct Case {
    float p, q;
    std::size_t faces;
  };
  // + above, - below: one face (from below), normal up (+z).
  // - on both sides: inside the solid, no face.   + on both sides: touching from outside, none.
  // 0 above (all-zero tetrahedron), - below: one face.   - above, missing below: see next test.
  for (const Case& c : {Case{1, -1, 1}, Case{-1, 1, 1}, Case{-1, -1, 0}, Case{1, 1, 0}, Case{0, -1, 1}, Case{0, 1, 0}}) {
    SCOPED_TRACE("p = " + std::to_string(c.p) + " q = " + std::to_string(c.q));
    const Mesh m = extract_surface(bipyramid(c.p, c.q), unit_root(), o, nullptr, &st);
    EXPECT_EQ(st.tetrahedra, 2u);
    EXPECT_EQ(st.kept_tetrahedra, 2u);
    ASSERT_EQ(m.faces.size(), c.faces);
    EXPECT_EQ(st.interior_zero_faces, (c.p < 0 && c.q < 0) ? 1u : 0u);
    if (c.faces == 1) {
      const auto& f = m.faces[0];
      const Eigen::Vector3f n = (m.vertices[f[1]] - m.vertices[f[0]]).cross(m.vertices[f[2]] - m.vertices[f[0]]);
      // Toward the positive apex, or away from the negative one.
      const float toward_p = (c.p > 0 || c.q < 0) ? 1.0f : -1.0f;
      EXPECT_GT(n.z() * toward_p, 0) << n.transpose();
    }
  }
}

TEST(ExtractZeroFaces, PrunedNeighbourCountsAsMissing) {
  // With n = 2 (reach 3) the apexes, 4 voxels above and below the face, are not neighbours of
  // its corners: 7.1 deletes both tetrahedra and nothing is emitted.
  ExtractOptions o;
  o.snap_fraction = 0;
  o.neighbourhood_n = 2;
  ExtractStats st;
  const Mesh m = extract_surface(bipyramid(-1, -1), unit_root(), o, nullptr, &st);
  EXPECT_EQ(st.kept_tetrahedra, 0u);
  EXPECT_TRUE(m.faces.empty());
}

// ---- Input checks ------------------------------------------------------------------------------

TEST(ExtractInput, RejectsBadVoxels) {
  std::vector<SurfaceVoxel> v = corner_voxels({-1, 1, 1, 1});
  v[1].key = v[0].key;
  EXPECT_THROW(extract_surface(v, unit_root(), ExtractOptions(), nullptr, nullptr), InputError);
  v = corner_voxels({-1, 1, 1, 1});
  v[2].distance = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(extract_surface(v, unit_root(), ExtractOptions(), nullptr, nullptr), InputError);
  v = corner_voxels({-1, 1, 1, 1});
  v[3].key = VoxelKey::make(2, 5, 0, 0);  // coordinate beyond 2^2
  EXPECT_THROW(extract_surface(v, unit_root(), ExtractOptions(), nullptr, nullptr), InputError);
  ExtractOptions bad;
  bad.snap_fraction = 0.7;
  EXPECT_THROW(extract_surface(corner_voxels({-1, 1, 1, 1}), unit_root(), bad, nullptr, nullptr), InputError);
}

TEST(ExtractInput, EmptyAndDegenerateInputs) {
  ExtractStats st;
  Mesh m = extract_surface({}, unit_root(), ExtractOptions(), nullptr, &st);
  EXPECT_TRUE(m.vertices.empty());
  EXPECT_TRUE(m.faces.empty());
  // Four coplanar voxels: no tetrahedron.
  std::vector<SurfaceVoxel> v = corner_voxels({-1, 1, 1, 1});
  v[3].key = VoxelKey::make(2, 1, 1, 0);
  m = extract_surface(v, unit_root(), ExtractOptions(), nullptr, &st);
  EXPECT_EQ(st.tetrahedra, 0u);
  EXPECT_TRUE(m.faces.empty());
}

TEST(ExtractInput, CoincidingVoxelsKeepTheFinest) {
  // v0 (level 2, (0,0,0)) given again at level 3 as (0,0,0) with another distance: the level-3
  // voxel wins, so the pattern is decided by its distance.
  std::vector<SurfaceVoxel> v = corner_voxels({1, 1, 1, 1});
  SurfaceVoxel fine = v[0];
  fine.key = v[0].key.finer();
  fine.distance = -1;
  v.push_back(fine);
  ExtractOptions o;
  o.snap_fraction = 0;
  ExtractStats st;
  const Mesh m = extract_surface(v, unit_root(), o, nullptr, &st);
  EXPECT_EQ(st.coincident_voxels, 1u);
  EXPECT_EQ(st.voxels, 4u);
  EXPECT_EQ(m.faces.size(), 1u);
  for (float s : m.scale) EXPECT_GT(s, 0.125f - 1e-6f);  // interpolated between 0.125 and 0.25
}

}  // namespace
}  // namespace sf
