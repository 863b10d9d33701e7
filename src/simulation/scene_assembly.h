// A procedural scene under construction: the mesh with a class per triangle,
// and the route's keep-out space every optional object must respect.
#pragma once

#include "range_image_mapping/simulation/mesh_primitives.h"
#include "range_image_mapping/simulation/scene_generator.h"

#include <Eigen/Geometry>

#include <vector>

namespace range_image_mapping::simulation {

// One object made of parts of different classes (a lamp: pole and shade),
// added to the scene as a whole or not at all.
struct SceneObject {
  TriangleMesh mesh;
  std::vector<SurfaceClass> classes;  // one per triangle

  void add(const TriangleMesh& part, SurfaceClass surface,
           const Eigen::Isometry3f& pose = Eigen::Isometry3f::Identity());
  void add(const SceneObject& other, const Eigen::Isometry3f& pose = Eigen::Isometry3f::Identity());
  void addBox(const Eigen::Vector3d& minimum, const Eigen::Vector3d& maximum, SurfaceClass surface);
  // A quad facing `normal`: the corner and the two edges span it, in either order.
  void addQuad(const Eigen::Vector3d& corner, const Eigen::Vector3d& edge_a,
               const Eigen::Vector3d& edge_b, const Eigen::Vector3d& normal, SurfaceClass surface);
};

class SceneAssembly {
 public:
  // route: closed, on the ground; optional objects keep placement_margin_m
  // beyond the clearance, so a trajectory may stray that far from the route.
  SceneAssembly(std::vector<Eigen::Vector3d> route, const RouteClearance& clearance,
                double placement_margin_m);

  // Structure the route was planned around (ground, walls): added unconditionally.
  void add(const SceneObject& object);
  // Furniture, cars, trees: added only where they keep clear of the route.
  bool addIfClear(const SceneObject& object);
  bool keepsClear(const Eigen::AlignedBox3d& box) const;

  Scene finish() &&;

 private:
  // Smallest distance from box to the band swept between lowest_m and
  // highest_m above one route segment.
  double distanceToBand(const Eigen::AlignedBox3d& box, const Eigen::Vector3d& from,
                        const Eigen::Vector3d& to) const;

  Scene scene_;
  double required_distance_m_;
};

}  // namespace range_image_mapping::simulation
