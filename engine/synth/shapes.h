#pragma once
// Meshes of simple shapes with known geometry, for synthetic scenes and tests. All faces are wound
// counter-clockwise seen from outside (normals point outwards).
#include <Eigen/Core>

#include "engine/mesh.h"

namespace sf {

// Icosphere: an icosahedron whose faces are split 4-to-1 `subdivisions` times (20 * 4^s faces),
// with every vertex on the sphere. The chordal error is about radius * 1.9 / 4^s.
Mesh make_sphere(const Eigen::Vector3d& centre, double radius, int subdivisions);

// Axis-aligned box, two triangles per side.
Mesh make_box(const Eigen::Vector3d& min, const Eigen::Vector3d& max);

// Rectangle [x0,x1] x [y0,y1] in the plane z = z, facing -z (towards a camera at the origin
// looking along +z), two triangles.
Mesh make_rectangle(double x0, double x1, double y0, double y1, double z);

}  // namespace sf
