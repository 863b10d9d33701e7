// Polygons of mesh files (PLY faces, OBJ "f" lines) as triangles.
#pragma once

#include <Eigen/Core>

#include <cstddef>
#include <vector>

namespace range_image_mapping::io {

// Splits a polygon of three or more corners into a fan around its first
// corner, keeping the winding: exact for convex polygons, which is what mesh
// writers emit.
inline void appendTriangleFan(const std::vector<int>& corners,
                              std::vector<Eigen::Vector3i>& triangles) {
  for (std::size_t i = 1; i + 1 < corners.size(); ++i)
    triangles.emplace_back(corners[0], corners[i], corners[i + 1]);
}

}  // namespace range_image_mapping::io
