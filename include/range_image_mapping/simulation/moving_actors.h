// Moving actors for the simulator: cars, trucks and pedestrians as a few
// oriented boxes each, driving along straight lines with a SpeedProfile. Their
// pose is an exact function of time, so the simulator casts every column
// against them at the column's own time, and the ground truth knows which
// pixel saw which actor.
#pragma once

#include "range_image_mapping/simulation/speed_profile.h"

#include <Eigen/Geometry>

#include <cstdint>
#include <string>
#include <vector>

namespace range_image_mapping::simulation {

enum class ActorKind : uint8_t { kCar, kTruck, kPedestrian };
const char* toString(ActorKind kind);  // "car", "truck", "pedestrian"

// A box in the actor's frame: x forward (the direction of travel), y left,
// z up, origin on the ground under the centre of the footprint.
struct ActorBox {
  Eigen::Vector3d centre_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d half_size_m = Eigen::Vector3d::Zero();  // all > 0
};

struct MovingActor {
  ActorKind kind = ActorKind::kCar;
  std::string name;  // one word, e.g. "truck_left"
  std::vector<ActorBox> boxes;
  // Straight-line motion: at distance s along the heading the actor frame's
  // origin is start_m + s (cos heading, sin heading, 0), its x axis along the
  // heading; s = motion.distance(time - delay_s), so a delayed copy of the ego
  // car's profile drives at about the ego's speed.
  Eigen::Vector3d start_m = Eigen::Vector3d::Zero();
  double heading_rad = 0.0;
  SpeedProfile motion;
  double delay_s = 0.0;

  Eigen::Isometry3d worldFromActor(double time_s) const;
  // The footprint and height of all boxes: their bounding box in the actor frame.
  Eigen::AlignedBox3d boundsInActor() const;
};

// Which actor a ray meets first, and where.
struct ActorHit {
  double distance_m = 0.0;  // along the unit ray direction
  int actor = -1;           // index into the actor list; -1: no hit
  Eigen::Vector3d normal_world = Eigen::Vector3d::Zero();  // of the face hit, facing the ray
};

// All actors posed at one instant, ready for many rays (one per column in the
// simulator). Exact slab tests in double against each box, after a bounding
// sphere test per actor.
class ActorSnapshot {
 public:
  ActorSnapshot() = default;
  ActorSnapshot(const std::vector<MovingActor>& actors, double time_s) { reset(actors, time_s); }
  // Reuses the buffers. The actors must outlive the snapshot (it keeps
  // pointers to their boxes).
  void reset(const std::vector<MovingActor>& actors, double time_s);

  // The first box surface along origin + t direction for t in [near_m, far_m]
  // (direction unit length). A ray starting inside a box does not see it.
  ActorHit intersect(const Eigen::Vector3d& origin_world, const Eigen::Vector3d& direction_world,
                     double near_m, double far_m) const;
  // Whether a world point lies inside any actor box grown by margin_m (>= 0).
  bool contains(const Eigen::Vector3d& point_world, double margin_m = 0.0) const;
  double time() const { return time_s_; }

 private:
  struct Posed {
    Eigen::Isometry3d actor_from_world;
    Eigen::Matrix3d world_from_actor_rotation;
    Eigen::Vector3d sphere_centre_world;
    double sphere_radius_m;
    const std::vector<ActorBox>* boxes;
  };
  std::vector<Posed> posed_;
  double time_s_ = 0.0;
};

// Exact distance along a ray (in the box's frame) to the surface of a box, or
// a negative value for a miss or a ray starting inside.
double rayBoxDistance(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, const ActorBox& box,
                      double near_m, double far_m, int* face_axis = nullptr);

}  // namespace range_image_mapping::simulation
