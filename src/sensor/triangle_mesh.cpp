#include "range_image_mapping/triangle_mesh.h"

#include <stdexcept>
#include <string>

namespace range_image_mapping {
namespace {

// An optional per-vertex attribute (empty or one per vertex) of two meshes
// about to be joined: both have it or neither, unless one has no vertices.
template <typename Attribute>
void requireSamePresence(const TriangleMesh& mesh, const TriangleMesh& other, const std::vector<Attribute>& own,
                         const std::vector<Attribute>& others, const char* what) {
  if (mesh.vertices.empty() || other.vertices.empty()) return;
  if (own.empty() != others.empty())
    throw std::invalid_argument(std::string("TriangleMesh::append: one mesh has ") + what +
                                ", the other has none");
}

}  // namespace

void TriangleMesh::append(const TriangleMesh& other, const Eigen::Isometry3f& pose) {
  requireSamePresence(*this, other, normals, other.normals, "normals");
  requireSamePresence(*this, other, intensities, other.intensities, "intensities");
  // No exact reserve here: scenes are built from thousands of small appends,
  // and growing by exactly what each needs would copy the mesh every time.
  const int first = static_cast<int>(vertices.size());
  for (const Eigen::Vector3f& vertex : other.vertices) vertices.push_back(pose * vertex);
  for (const Eigen::Vector3i& triangle : other.triangles)
    triangles.push_back(triangle + Eigen::Vector3i::Constant(first));
  const Eigen::Matrix3f rotation = pose.linear();
  for (const Eigen::Vector3f& normal : other.normals) normals.push_back(rotation * normal);
  intensities.insert(intensities.end(), other.intensities.begin(), other.intensities.end());
}

Eigen::AlignedBox3f TriangleMesh::bounds() const {
  Eigen::AlignedBox3f box;  // empty until extended
  for (const Eigen::Vector3f& vertex : vertices) box.extend(vertex);
  return box;
}

double TriangleMesh::area() const {
  double total = 0.0;
  for (const Eigen::Vector3i& t : triangles) {
    const Eigen::Vector3d a = vertices.at(t[0]).cast<double>();
    const Eigen::Vector3d b = vertices.at(t[1]).cast<double>();
    const Eigen::Vector3d c = vertices.at(t[2]).cast<double>();
    total += 0.5 * (b - a).cross(c - a).norm();
  }
  return total;
}

}  // namespace range_image_mapping
