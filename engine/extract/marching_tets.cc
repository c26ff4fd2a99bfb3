#include "engine/extract/marching_tets.h"

#include <algorithm>
#include <utility>

namespace sf::extract_detail {
namespace {

// Class of a distance: 0 negative, 1 zero, 2 positive.
int sign_class(float d) { return d < 0 ? 0 : (d > 0 ? 2 : 1); }

constexpr int pattern(int negative, int zero, int positive) { return negative * 16 + zero * 4 + positive; }

}  // namespace

SignCount count_signs(const std::array<float, 4>& d) {
  SignCount s;
  for (float x : d) {
    if (x < 0) ++s.negative;
    else if (x > 0) ++s.positive;
    else ++s.zero;
  }
  return s;
}

bool emits_triangles(const std::array<float, 4>& d) {
  const SignCount s = count_signs(d);
  if (s.negative == 0) return false;                // (0,*,*): positive side or all zero
  if (s.positive > 0) return s.zero <= 2;           // both signs: every such pattern emits
  return s.zero == 3;                               // (1,3,0): the zero face
}

int march_tetrahedron(const std::array<std::uint32_t, 4>& tet, const FieldView& field, MtTriangle out[2]) {
  // Sort the vertices by (class, index) and remember the parity of the permutation: an odd one
  // turns the positively oriented tetrahedron into a negatively oriented one, and every template
  // triangle below must then be flipped. Sorting by index inside a class makes the output
  // independent of the vertex order CGAL happened to store.
  struct Vert {
    int cls;
    std::uint32_t id;
  };
  std::array<Vert, 4> v;
  for (int i = 0; i < 4; ++i) v[i] = {sign_class(field.distance[tet[i]]), tet[i]};
  bool odd = false;
  for (int i = 1; i < 4; ++i) {
    for (int j = i; j > 0; --j) {
      const bool less = v[j].cls < v[j - 1].cls || (v[j].cls == v[j - 1].cls && v[j].id < v[j - 1].id);
      if (!less) break;
      std::swap(v[j], v[j - 1]);
      odd = !odd;
    }
  }
  int negative = 0, zero = 0, positive = 0;
  for (const Vert& x : v) (x.cls == 0 ? negative : x.cls == 1 ? zero : positive)++;

  const auto X = [&](int i, int j) { return MtVertex::edge(v[i].id, v[j].id); };
  const auto Z = [&](int i) { return MtVertex::voxel(v[i].id); };
  int n = 0;
  const auto emit = [&](MtVertex a, MtVertex b, MtVertex c, bool zero_face = false) {
    if (odd) std::swap(b, c);
    out[n++] = MtTriangle{{a, b, c}, zero_face};
  };

  // Templates for the sorted, positively oriented tetrahedron (v0 .. v3 ordered -, 0, +): the
  // triangle (v0, v1, v2) of such a tetrahedron faces v3, which fixes each template's winding.
  switch (pattern(negative, zero, positive)) {
    case pattern(1, 0, 3):  // cut off the negative corner
      emit(X(0, 1), X(0, 2), X(0, 3));
      break;
    case pattern(3, 0, 1):  // cut off the positive corner
      emit(X(0, 3), X(1, 3), X(2, 3));
      break;
    case pattern(2, 0, 2): {  // quad X02 X03 X13 X12, split along the shorter diagonal
      const std::array<MtVertex, 4> q{X(0, 2), X(0, 3), X(1, 3), X(1, 2)};
      const double diag02 = (vertex_position(field, q[0]) - vertex_position(field, q[2])).squaredNorm();
      const double diag13 = (vertex_position(field, q[1]) - vertex_position(field, q[3])).squaredNorm();
      bool split02 = diag02 < diag13;
      if (diag02 == diag13) {
        split02 = std::min(q[0].id(), q[2].id()) < std::min(q[1].id(), q[3].id());
      }
      if (split02) {
        emit(q[0], q[1], q[2]);
        emit(q[0], q[2], q[3]);
      } else {
        emit(q[0], q[1], q[3]);
        emit(q[1], q[2], q[3]);
      }
      break;
    }
    case pattern(1, 1, 2):  // the quad above with X12, X13 collapsed onto the zero voxel v1
      emit(X(0, 2), X(0, 3), Z(1));
      break;
    case pattern(2, 1, 1):  // X02, X12 collapsed onto the zero voxel v2
      emit(Z(2), X(0, 3), X(1, 3));
      break;
    case pattern(1, 2, 1):  // two zero voxels and the crossing between the signed ones
      emit(Z(1), Z(2), X(0, 3));
      break;
    case pattern(1, 3, 0):  // the zero face, seen from its negative side
      emit(Z(1), Z(2), Z(3), true);
      break;
    default:  // touches zero in at most an edge, lies on the positive side, or is all zero
      break;
  }
  return n;
}

}  // namespace sf::extract_detail
