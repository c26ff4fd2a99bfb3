// CGAL Delaunay tetrahedralization behind extract_detail::DelaunayTetrahedralization.
//
// Kernel: Exact_predicates_inexact_constructions (the triangulation only evaluates predicates, it
// never constructs points), with its two hot predicates replaced by exact integer versions for
// lattice input. The vertex info is the point index.
#ifndef CGAL_LINKED_WITH_TBB
#define CGAL_LINKED_WITH_TBB 1  // Parallel_tag needs it; the library links oneTBB (and tbbmalloc).
#endif
#include "engine/extract/delaunay.h"

#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Delaunay_triangulation_cell_base_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Spatial_sort_traits_adapter_3.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>
#include <CGAL/property_map.h>
#include <CGAL/spatial_sort.h>

#include <algorithm>
#include <numeric>
#include <stdexcept>
#include <string>
#include <utility>

namespace sf::extract_detail {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Int128 = __int128;

template <class T>
int sign(T v) {
  return (v > 0) - (v < 0);
}

// Coordinates of lattice points are integers in [0, 2^18], stored exactly in doubles.
struct Delta {
  std::int64_t x, y, z;
  Delta(const Point& a, const Point& b)
      : x(std::int64_t(a.x()) - std::int64_t(b.x())),
        y(std::int64_t(a.y()) - std::int64_t(b.y())),
        z(std::int64_t(a.z()) - std::int64_t(b.z())) {}
};

// |u|, |v| <= 2^18: a 2x2 minor stays below 2^37, a 3x3 determinant below 2^57.
inline std::int64_t minor_xy(const Delta& u, const Delta& v) { return u.x * v.y - u.y * v.x; }
inline std::int64_t det3(const Delta& u, const Delta& v, const Delta& w) {
  return u.z * minor_xy(v, w) - v.z * minor_xy(u, w) + w.z * minor_xy(u, v);
}

// Epick with exact integer Orientation_3 and Side_of_oriented_sphere_3 for lattice points. The
// determinants are the ones of CGAL's orientationC3 and side_of_oriented_sphereC3, so the signs
// (and the symbolic perturbation that Delaunay_triangulation_3 builds on them) are exactly CGAL's.
struct LatticeTraits : Kernel {
  struct Orientation_3 : Kernel::Orientation_3 {
    using Kernel::Orientation_3::operator();
    CGAL::Orientation operator()(const Point& p, const Point& q, const Point& r, const Point& s) const {
      return CGAL::Orientation(sign(det3(Delta(q, p), Delta(r, p), Delta(s, p))));
    }
  };
  // Never ON_ORIENTED_BOUNDARY: a zero determinant is decided here by the symbolic perturbation
  // Delaunay_triangulation_3::side_of_oriented_sphere applies to it (with perturb = true, the only
  // way insertion calls it, always with p, q, r, s positively oriented). On a lattice nearly every
  // in-sphere test of neighbouring cells is cospherical; CGAL's generic perturbation sorts the five
  // points through the traits each time, here the two largest are picked by packed coordinates.
  // Same decisions, so the same triangulation.
  struct Side_of_oriented_sphere_3 {
    using result_type = CGAL::Oriented_side;
    CGAL::Oriented_side operator()(const Point& p, const Point& q, const Point& r, const Point& s,
                                   const Point& t) const {
      // det(P, R, Q, S) with rows (dx, dy, dz, |d|^2) relative to t, expanded along the lifted
      // column: |d|^2 < 2^38 times a 3x3 determinant < 2^57, four terms: below 2^97. The four 3x3
      // determinants share their six xy minors.
      const Delta a(p, t), b(r, t), c(q, t), d(s, t);
      const std::int64_t ab = minor_xy(a, b), ac = minor_xy(a, c), ad = minor_xy(a, d), bc = minor_xy(b, c),
                         bd = minor_xy(b, d), cd = minor_xy(c, d);
      const auto lift = [](const Delta& u) { return u.x * u.x + u.y * u.y + u.z * u.z; };
      const Int128 det = -Int128(lift(a)) * (b.z * cd - c.z * bd + d.z * bc) +
                         Int128(lift(b)) * (a.z * cd - c.z * ad + d.z * ac) -
                         Int128(lift(c)) * (a.z * bd - b.z * ad + d.z * ab) +
                         Int128(lift(d)) * (a.z * bc - b.z * ac + c.z * ab);
      if (det != 0) return CGAL::Oriented_side(sign(det));
      return perturbed(p, q, r, s, t);
    }
    // CGAL's rule: of the five points in lexicographic order, the largest, then the second
    // largest, decides: t itself gives the negative side, a cell vertex the orientation of the
    // cell with that vertex replaced by t, unless that is coplanar.
    static CGAL::Oriented_side perturbed(const Point& p0, const Point& p1, const Point& p2, const Point& p3,
                                         const Point& t) {
      const Point* points[5] = {&p0, &p1, &p2, &p3, &t};
      std::uint64_t key[5];
      for (int i = 0; i < 5; ++i)  // coordinates are integers in [0, 2^18]: 20 bits each
        key[i] = std::uint64_t(points[i]->x()) << 40 | std::uint64_t(points[i]->y()) << 20 |
                 std::uint64_t(points[i]->z());
      int first = 0;
      for (int i = 1; i < 5; ++i)
        if (key[i] > key[first]) first = i;
      int second = first == 0 ? 1 : 0;
      for (int i = 0; i < 5; ++i)
        if (i != first && key[i] > key[second]) second = i;
      for (const int k : {first, second}) {
        if (k == 4) return CGAL::ON_NEGATIVE_SIDE;  // p0..p3 are positively oriented
        const Point* cell[4] = {&p0, &p1, &p2, &p3};
        cell[k] = &t;
        const CGAL::Orientation o = Orientation_3()(*cell[0], *cell[1], *cell[2], *cell[3]);
        if (o != CGAL::COPLANAR) return CGAL::Oriented_side(o);
      }
      return CGAL::ON_NEGATIVE_SIDE;  // unreachable for a positively oriented cell (CGAL asserts)
    }
  };
  // Lexicographic order, the symbolic perturbation's point order (CGAL still sorts with it in the
  // coplanar in-circle tests of the hull's infinite cells), so keep it a plain double comparison.
  struct Compare_xyz_3 : Kernel::Compare_xyz_3 {
    using Kernel::Compare_xyz_3::operator();
    CGAL::Comparison_result operator()(const Point& p, const Point& q) const {
      if (p.x() != q.x()) return p.x() < q.x() ? CGAL::SMALLER : CGAL::LARGER;
      if (p.y() != q.y()) return p.y() < q.y() ? CGAL::SMALLER : CGAL::LARGER;
      if (p.z() != q.z()) return p.z() < q.z() ? CGAL::SMALLER : CGAL::LARGER;
      return CGAL::EQUAL;
    }
  };
  Orientation_3 orientation_3_object() const { return Orientation_3(); }
  Compare_xyz_3 compare_xyz_3_object() const { return Compare_xyz_3(); }
  Side_of_oriented_sphere_3 side_of_oriented_sphere_3_object() const { return Side_of_oriented_sphere_3(); }
};

template <class ConcurrencyTag>
struct Cgal {
  using Vb = CGAL::Triangulation_vertex_base_with_info_3<std::uint32_t, LatticeTraits>;
  using Cb = CGAL::Delaunay_triangulation_cell_base_3<LatticeTraits>;
  using Tds = CGAL::Triangulation_data_structure_3<Vb, Cb, ConcurrencyTag>;
  using Triangulation = CGAL::Delaunay_triangulation_3<LatticeTraits, Tds>;
};
using SequentialTriangulation = Cgal<CGAL::Sequential_tag>::Triangulation;
using ParallelTriangulation = Cgal<CGAL::Parallel_tag>::Triangulation;

constexpr std::size_t kProgressStep = std::size_t{1} << 16;

std::vector<Point> to_cgal(const std::vector<LatticePoint>& points) {
  std::vector<Point> out;
  out.reserve(points.size());
  for (const LatticePoint& p : points) {
    for (std::int32_t c : p) {
      if (c < 0 || c > kMaxLatticeCoordinate) {
        throw std::invalid_argument("Delaunay tetrahedralization: lattice coordinate " + std::to_string(c) +
                                    " outside [0, 2^18]");
      }
    }
    out.emplace_back(double(p[0]), double(p[1]), double(p[2]));
  }
  return out;
}

void check_all_inserted(std::size_t vertices, std::size_t points) {
  if (vertices != points)
    throw std::invalid_argument("Delaunay tetrahedralization: " + std::to_string(points - vertices) + " of " +
                                std::to_string(points) + " points coincide with another point");
}

template <class Triangulation>
void visit_cells(const Triangulation& t, const std::function<void(const Tet*, std::size_t)>& visit) {
  if (t.dimension() < 3) return;
  std::vector<Tet> batch;
  batch.reserve(DelaunayTetrahedralization::kCellBatch);
  for (auto c = t.finite_cells_begin(); c != t.finite_cells_end(); ++c) {
    batch.push_back(Tet{c->vertex(0)->info(), c->vertex(1)->info(), c->vertex(2)->info(), c->vertex(3)->info()});
    if (batch.size() == DelaunayTetrahedralization::kCellBatch) {
      visit(batch.data(), batch.size());
      batch.clear();
    }
  }
  if (!batch.empty()) visit(batch.data(), batch.size());
}

}  // namespace

struct DelaunayTetrahedralization::Impl {
  std::unique_ptr<SequentialTriangulation> sequential;
  std::unique_ptr<ParallelTriangulation> parallel;
  std::unique_ptr<ParallelTriangulation::Lock_data_structure> lock;
};

DelaunayTetrahedralization::DelaunayTetrahedralization(const std::vector<LatticePoint>& points, bool parallel,
                                                       const ProgressFn& progress)
    : impl_(std::make_unique<Impl>()) {
  const std::size_t n = points.size();
  report(progress, "tetrahedralize", 0, double(n));
  std::vector<Point> cgal_points = to_cgal(points);
  if (parallel && n > 0) {
    // CGAL spatially sorts the range (in parallel), inserts the first points sequentially and the
    // rest with tbb::parallel_for, each thread locking the cells it touches in a 50^3 grid over
    // the bounding box. Progress is reported only from this thread: at the start and the end.
    const CGAL::Bbox_3 box = CGAL::bbox_3(cgal_points.begin(), cgal_points.end());
    impl_->lock = std::make_unique<ParallelTriangulation::Lock_data_structure>(box, 50);
    impl_->parallel = std::make_unique<ParallelTriangulation>(impl_->lock.get());
    std::vector<std::pair<Point, std::uint32_t>> with_info;
    with_info.reserve(n);
    for (std::size_t i = 0; i < n; ++i) with_info.emplace_back(cgal_points[i], std::uint32_t(i));
    std::vector<Point>().swap(cgal_points);
    impl_->parallel->insert(with_info.begin(), with_info.end());
    impl_->parallel->set_lock_data_structure(nullptr);  // the grid is only needed while inserting
    impl_->lock.reset();
    check_all_inserted(impl_->parallel->number_of_vertices(), n);
  } else {
    // The same as CGAL's range insertion (spatial sort, then insertion with the previous vertex
    // as hint), unrolled so that progress can be reported.
    impl_->sequential = std::make_unique<SequentialTriangulation>();
    SequentialTriangulation& t = *impl_->sequential;
    std::vector<std::size_t> order(n);  // the adapter's "points" are indices of this type
    std::iota(order.begin(), order.end(), std::size_t{0});
    using Traits = CGAL::Spatial_sort_traits_adapter_3<LatticeTraits, CGAL::Pointer_property_map<Point>::const_type>;
    if (n > 0) CGAL::spatial_sort(order.begin(), order.end(), Traits(CGAL::make_property_map(std::as_const(cgal_points))));
    SequentialTriangulation::Vertex_handle hint;
    for (std::size_t i = 0; i < n; ++i) {
      hint = t.insert(cgal_points[order[i]], hint);
      hint->info() = std::uint32_t(order[i]);
      if ((i + 1) % kProgressStep == 0) report(progress, "tetrahedralize", double(i + 1), double(n));
    }
    check_all_inserted(t.number_of_vertices(), n);
  }
  report(progress, "tetrahedralize", double(n), double(n));
}

DelaunayTetrahedralization::~DelaunayTetrahedralization() = default;

std::size_t DelaunayTetrahedralization::number_of_cells() const {
  if (impl_->sequential) return impl_->sequential->dimension() < 3 ? 0 : impl_->sequential->number_of_finite_cells();
  if (impl_->parallel) return impl_->parallel->dimension() < 3 ? 0 : impl_->parallel->number_of_finite_cells();
  return 0;
}

void DelaunayTetrahedralization::for_each_cell_batch(
    const std::function<void(const Tet* cells, std::size_t count)>& visit) const {
  if (impl_->sequential) visit_cells(*impl_->sequential, visit);
  if (impl_->parallel) visit_cells(*impl_->parallel, visit);
}

void DelaunayTetrahedralization::for_each_cell(const std::function<void(const Tet&)>& visit) const {
  for_each_cell_batch([&](const Tet* cells, std::size_t count) {
    for (std::size_t i = 0; i < count; ++i) visit(cells[i]);
  });
}

namespace {
Point point_of(const LatticePoint& p) { return Point(double(p[0]), double(p[1]), double(p[2])); }
}  // namespace

int lattice_orientation(const LatticePoint& p, const LatticePoint& q, const LatticePoint& r, const LatticePoint& s) {
  return int(LatticeTraits::Orientation_3()(point_of(p), point_of(q), point_of(r), point_of(s)));
}

int lattice_side_of_sphere(const LatticePoint* cell[4], const LatticePoint& t) {
  // The traits' predicate perturbs on the sphere itself (see Side_of_oriented_sphere_3).
  return int(LatticeTraits::Side_of_oriented_sphere_3()(point_of(*cell[0]), point_of(*cell[1]), point_of(*cell[2]),
                                                        point_of(*cell[3]), point_of(t)));
}

std::vector<Tet> delaunay_tetrahedra(const std::vector<LatticePoint>& points, bool parallel) {
  std::vector<Tet> cells;
  {
    const DelaunayTetrahedralization dt(points, parallel, nullptr);
    cells.reserve(dt.number_of_cells());
    dt.for_each_cell([&](const Tet& t) {
      // Even permutations only (orientation kept): bring the smallest index to the front with a
      // double transposition, then rotate the other three cyclically.
      Tet c = t;
      const int m = int(std::min_element(c.begin(), c.end()) - c.begin());
      if (m == 1) c = {c[1], c[0], c[3], c[2]};
      if (m == 2) c = {c[2], c[3], c[0], c[1]};
      if (m == 3) c = {c[3], c[2], c[1], c[0]};
      const int r = int(std::min_element(c.begin() + 1, c.end()) - c.begin());
      if (r == 2) c = {c[0], c[2], c[3], c[1]};
      if (r == 3) c = {c[0], c[3], c[1], c[2]};
      cells.push_back(c);
    });
  }
  std::sort(cells.begin(), cells.end());
  return cells;
}

}  // namespace sf::extract_detail
