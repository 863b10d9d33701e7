// Analytic triangle-mesh primitives the procedural scenes are built from and
// tests use as exact ground truth.
#pragma once

#include "range_image_mapping/triangle_mesh.h"

#include <Eigen/Core>

namespace range_image_mapping::simulation {

// Analytic primitives (exact ground truth for tests). Bad sizes (not finite,
// not positive, parallel edges, out-of-range counts) throw std::invalid_argument.
// Quad corner, corner + u, corner + u + v, corner + v: its outside faces u x v.
TriangleMesh makeQuad(const Eigen::Vector3f& corner, const Eigen::Vector3f& edge_u, const Eigen::Vector3f& edge_v);
// 8 corners, 12 triangles; inward_facing flips them (a room seen from inside).
TriangleMesh makeBox(const Eigen::Vector3f& minimum, const Eigen::Vector3f& maximum, bool inward_facing = false);
// Every vertex on the sphere; 20 * 4^subdivisions triangles, subdivisions in [0, 8].
TriangleMesh makeSphere(const Eigen::Vector3f& centre, float radius, int subdivisions = 5);  // icosphere
// Vertical axis from base up by height, closed by both caps; segments >= 3.
TriangleMesh makeCylinder(const Eigen::Vector3f& base, float radius, float height, int segments = 24);

}  // namespace range_image_mapping::simulation
