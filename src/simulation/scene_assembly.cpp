#include "scene_assembly.h"

#include <algorithm>
#include <cmath>

namespace range_image_mapping::simulation {

void SceneObject::add(const TriangleMesh& part, SurfaceClass surface,
                      const Eigen::Isometry3f& pose) {
  mesh.append(part, pose);
  classes.insert(classes.end(), part.triangles.size(), surface);
}

void SceneObject::add(const SceneObject& other, const Eigen::Isometry3f& pose) {
  mesh.append(other.mesh, pose);
  classes.insert(classes.end(), other.classes.begin(), other.classes.end());
}

void SceneObject::addBox(const Eigen::Vector3d& minimum, const Eigen::Vector3d& maximum,
                         SurfaceClass surface) {
  add(makeBox(minimum.cast<float>(), maximum.cast<float>()), surface);
}

void SceneObject::addQuad(const Eigen::Vector3d& corner, const Eigen::Vector3d& edge_a,
                          const Eigen::Vector3d& edge_b, const Eigen::Vector3d& normal,
                          SurfaceClass surface) {
  // makeQuad faces edge_u x edge_v.
  const bool in_order = edge_a.cross(edge_b).dot(normal) > 0.0;
  add(makeQuad(corner.cast<float>(), (in_order ? edge_a : edge_b).cast<float>(),
               (in_order ? edge_b : edge_a).cast<float>()),
      surface);
}

SceneAssembly::SceneAssembly(std::vector<Eigen::Vector3d> route, const RouteClearance& clearance,
                             double placement_margin_m)
    : required_distance_m_(clearance.distance_m + placement_margin_m) {
  scene_.route = std::move(route);
  scene_.route_clearance = clearance;
}

void SceneAssembly::add(const SceneObject& object) {
  scene_.mesh.append(object.mesh);
  scene_.triangle_classes.insert(scene_.triangle_classes.end(), object.classes.begin(),
                                 object.classes.end());
}

bool SceneAssembly::addIfClear(const SceneObject& object) {
  if (!keepsClear(object.mesh.bounds().cast<double>())) return false;
  add(object);
  return true;
}

bool SceneAssembly::keepsClear(const Eigen::AlignedBox3d& box) const {
  const RouteClearance& clearance = scene_.route_clearance;
  for (std::size_t i = 0; i + 1 < scene_.route.size(); ++i) {
    const Eigen::Vector3d& from = scene_.route[i];
    const Eigen::Vector3d& to = scene_.route[i + 1];
    // The band's bounding box first: most segments are far away.
    Eigen::AlignedBox3d band(from.cwiseMin(to), from.cwiseMax(to));
    band.min().z() += clearance.lowest_m;
    band.max().z() += clearance.highest_m;
    const Eigen::Vector3d gap =
        (band.min() - box.max()).cwiseMax(box.min() - band.max()).cwiseMax(0.0);
    if (gap.norm() >= required_distance_m_) continue;
    if (distanceToBand(box, from, to) < required_distance_m_) return false;
  }
  return true;
}

double SceneAssembly::distanceToBand(const Eigen::AlignedBox3d& box, const Eigen::Vector3d& from,
                                     const Eigen::Vector3d& to) const {
  const RouteClearance& clearance = scene_.route_clearance;
  // Squared distance at a point of the segment: horizontal distance to the box
  // plus the vertical gap between the box and the band above that point. Both
  // are convex in the segment parameter, so golden-section search finds the minimum.
  const auto squared = [&](double t) {
    const Eigen::Vector3d point = from + t * (to - from);
    const Eigen::Vector2d horizontal = (box.min().head<2>() - point.head<2>())
                                           .cwiseMax(point.head<2>() - box.max().head<2>())
                                           .cwiseMax(0.0);
    const double vertical = std::max({0.0, box.min().z() - (point.z() + clearance.highest_m),
                                      (point.z() + clearance.lowest_m) - box.max().z()});
    return horizontal.squaredNorm() + vertical * vertical;
  };
  const double ratio = (std::sqrt(5.0) - 1.0) / 2.0;
  double low = 0.0, high = 1.0;
  double left = high - ratio * (high - low), right = low + ratio * (high - low);
  double left_value = squared(left), right_value = squared(right);
  for (int iteration = 0; iteration < 48; ++iteration) {
    if (left_value < right_value) {
      high = right;
      right = left;
      right_value = left_value;
      left = high - ratio * (high - low);
      left_value = squared(left);
    } else {
      low = left;
      left = right;
      left_value = right_value;
      right = low + ratio * (high - low);
      right_value = squared(right);
    }
  }
  return std::sqrt(std::min({left_value, right_value, squared(0.0), squared(1.0)}));
}

Scene SceneAssembly::finish() && { return std::move(scene_); }

}  // namespace range_image_mapping::simulation
