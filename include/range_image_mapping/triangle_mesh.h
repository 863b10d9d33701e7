// The one triangle mesh type: the scenes the simulator casts rays into, the
// ground truth surfaces reconstructions are judged against, the meshes
// marching cubes extracts from a map, and the mesh files io reads and writes.
#pragma once

#include <Eigen/Geometry>

#include <vector>

namespace range_image_mapping {

struct TriangleMesh {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<Eigen::Vector3i> triangles;  // indices into vertices, counter-clockwise seen from outside
  std::vector<Eigen::Vector3f> normals;    // empty or one per vertex (unit, pointing outside)
  std::vector<float> intensities;          // empty or one per vertex

  // Appends other's triangles, moved by pose (normals turned with it). The
  // normals and intensities stay empty or one per vertex: when both meshes
  // have vertices, both must have them or neither (else std::invalid_argument).
  void append(const TriangleMesh& other, const Eigen::Isometry3f& pose = Eigen::Isometry3f::Identity());
  Eigen::AlignedBox3f bounds() const;
  double area() const;
};

}  // namespace range_image_mapping
