#include "range_image_mapping/simulation/moving_actors.h"

#include <cmath>
#include <limits>

namespace range_image_mapping::simulation {

const char* toString(ActorKind kind) {
  switch (kind) {
    case ActorKind::kCar: return "car";
    case ActorKind::kTruck: return "truck";
    case ActorKind::kPedestrian: return "pedestrian";
  }
  return "unknown";
}

Eigen::Isometry3d MovingActor::worldFromActor(double time_s) const {
  const double travelled = motion.distance(time_s - delay_s);
  const Eigen::Vector3d along(std::cos(heading_rad), std::sin(heading_rad), 0.0);
  Eigen::Isometry3d world_from_actor = Eigen::Isometry3d::Identity();
  world_from_actor.linear() = Eigen::AngleAxisd(heading_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  world_from_actor.translation() = start_m + travelled * along;
  return world_from_actor;
}

Eigen::AlignedBox3d MovingActor::boundsInActor() const {
  Eigen::AlignedBox3d bounds;
  for (const ActorBox& box : boxes) {
    bounds.extend(box.centre_m - box.half_size_m);
    bounds.extend(box.centre_m + box.half_size_m);
  }
  return bounds;
}

double rayBoxDistance(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, const ActorBox& box,
                      double near_m, double far_m, int* face_axis) {
  double entry = -std::numeric_limits<double>::infinity();
  double exit = std::numeric_limits<double>::infinity();
  int entry_axis = -1;
  for (int axis = 0; axis < 3; ++axis) {
    const double low = box.centre_m[axis] - box.half_size_m[axis] - origin[axis];
    const double high = box.centre_m[axis] + box.half_size_m[axis] - origin[axis];
    if (direction[axis] == 0.0) {  // parallel to the slab: inside it or a miss
      if (low > 0.0 || high < 0.0) return -1.0;
      continue;
    }
    double t_low = low / direction[axis], t_high = high / direction[axis];
    if (t_low > t_high) std::swap(t_low, t_high);
    if (t_low > entry) {
      entry = t_low;
      entry_axis = axis;
    }
    exit = std::min(exit, t_high);
  }
  // Entry before near_m also covers a ray starting inside (entry < 0 <= exit).
  if (entry_axis < 0 || entry > exit || entry < near_m || entry > far_m) return -1.0;
  if (face_axis) *face_axis = entry_axis;
  return entry;
}

void ActorSnapshot::reset(const std::vector<MovingActor>& actors, double time_s) {
  time_s_ = time_s;
  posed_.resize(actors.size());
  for (std::size_t i = 0; i < actors.size(); ++i) {
    const Eigen::Isometry3d world_from_actor = actors[i].worldFromActor(time_s);
    const Eigen::AlignedBox3d bounds = actors[i].boundsInActor();
    Posed& posed = posed_[i];
    posed.actor_from_world = world_from_actor.inverse();
    posed.world_from_actor_rotation = world_from_actor.linear();
    posed.sphere_centre_world = world_from_actor * bounds.center();
    posed.sphere_radius_m = 0.5 * bounds.diagonal().norm();
    posed.boxes = &actors[i].boxes;
  }
}

ActorHit ActorSnapshot::intersect(const Eigen::Vector3d& origin_world, const Eigen::Vector3d& direction_world,
                                  double near_m, double far_m) const {
  ActorHit hit;
  double nearest = far_m;
  for (std::size_t i = 0; i < posed_.size(); ++i) {
    const Posed& posed = posed_[i];
    // Bounding sphere first: most rays pass far from most actors.
    const Eigen::Vector3d to_centre = posed.sphere_centre_world - origin_world;
    const double along = to_centre.dot(direction_world);
    const double radius = posed.sphere_radius_m;
    if (along + radius < near_m || along - radius > nearest) continue;
    if (to_centre.squaredNorm() - along * along > radius * radius) continue;
    const Eigen::Vector3d origin = posed.actor_from_world * origin_world;
    const Eigen::Vector3d direction = posed.actor_from_world.linear() * direction_world;
    for (const ActorBox& box : *posed.boxes) {
      int axis = -1;
      const double distance = rayBoxDistance(origin, direction, box, near_m, nearest, &axis);
      if (distance < 0.0) continue;
      nearest = distance;
      hit.distance_m = distance;
      hit.actor = static_cast<int>(i);
      Eigen::Vector3d normal = Eigen::Vector3d::Zero();
      normal[axis] = direction[axis] > 0.0 ? -1.0 : 1.0;
      hit.normal_world = posed.world_from_actor_rotation * normal;
    }
  }
  return hit;
}

bool ActorSnapshot::contains(const Eigen::Vector3d& point_world, double margin_m) const {
  for (const Posed& posed : posed_) {
    if ((point_world - posed.sphere_centre_world).norm() > posed.sphere_radius_m + margin_m) continue;
    const Eigen::Vector3d point = posed.actor_from_world * point_world;
    for (const ActorBox& box : *posed.boxes)
      if (((point - box.centre_m).cwiseAbs() - box.half_size_m).maxCoeff() <= margin_m) return true;
  }
  return false;
}

}  // namespace range_image_mapping::simulation
