// Reference geometry for tests: ray-mesh distances by brute force in double.
#pragma once

#include "range_image_mapping/triangle_mesh.h"

#include <cmath>
#include <limits>

namespace range_image_mapping::test {

// Moller-Trumbore over every triangle: the nearest hit along the unit
// direction, or NaN.
inline double bruteForceDistance(const TriangleMesh& mesh, const Eigen::Vector3d& origin,
                                 const Eigen::Vector3d& direction) {
  double best = std::numeric_limits<double>::quiet_NaN();
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>();
    const Eigen::Vector3d edge1 = mesh.vertices[t[1]].cast<double>() - a;
    const Eigen::Vector3d edge2 = mesh.vertices[t[2]].cast<double>() - a;
    const Eigen::Vector3d p = direction.cross(edge2);
    const double determinant = edge1.dot(p);
    if (std::abs(determinant) < 1e-15) continue;
    const Eigen::Vector3d s = origin - a;
    const double b1 = s.dot(p) / determinant;
    const Eigen::Vector3d q = s.cross(edge1);
    const double b2 = direction.dot(q) / determinant;
    if (b1 < 0 || b2 < 0 || b1 + b2 > 1) continue;
    const double distance = edge2.dot(q) / determinant;
    if (distance > 0 && !(distance >= best)) best = distance;
  }
  return best;
}

}  // namespace range_image_mapping::test
