// Continuous-time sensor trajectories: pose of the lidar frame in the world,
// T_world_lidar(t), for any t in [startTime(), endTime()].
#pragma once

#include "range_image_mapping/simulation/scene_generator.h"

#include <Eigen/Geometry>

#include <memory>
#include <string>
#include <vector>

namespace range_image_mapping::simulation {

// pose() must be safe to call concurrently (the simulator asks for every
// column's pose from several threads).
class Trajectory {
 public:
  virtual ~Trajectory() = default;
  virtual Eigen::Isometry3d pose(double time_s) const = 0;
  virtual double startTime() const = 0;
  virtual double endTime() const = 0;
};

// Poses at given times, interpolated in between (linear translation, slerp
// rotation): user pose files, or any hand-made motion.
class InterpolatedTrajectory : public Trajectory {
 public:
  // Throws std::invalid_argument for no poses, counts that differ, times that
  // are not finite or not strictly increasing.
  InterpolatedTrajectory(std::vector<double> times_s, std::vector<Eigen::Isometry3d> poses);
  // Throws std::out_of_range outside [startTime(), endTime()].
  Eigen::Isometry3d pose(double time_s) const override;
  double startTime() const override { return times_.front(); }
  double endTime() const override { return times_.back(); }
  const std::vector<double>& times() const { return times_; }
  const std::vector<Eigen::Isometry3d>& poses() const { return poses_; }

 private:
  std::vector<double> times_;
  std::vector<Eigen::Isometry3d> poses_;
  std::vector<Eigen::Quaterniond> rotations_;
};

enum class MotionProfile {
  kCar,        // along the route, up to 15 m/s, slowing into turns, smooth
  kCart,       // hand-pushed cart indoors: ~1 m/s, gentle turns, small vibration
  kHandheld,   // aggressive handheld: walking speed, yaw rates up to 180 deg/s, pitch/roll sway
};

struct MotionOptions {
  MotionProfile profile = MotionProfile::kCar;
  double duration_s = 30.0;      // within (0, 3600]
  double sensor_height_m = 1.8;  // above the route points (the route lies on the ground)
  uint32_t seed = 1;             // drives vibration and sway; the path itself is the route's
};

// Smooth motion along scene.route, starting at route[0] at t = 0 (already
// moving) and looping around the closed route; defined on [0, duration_s].
// The route is smoothed by a closed cubic B-spline (C2): routes with rounded
// corners (the scene generator's) are followed within a few centimetres,
// sharp corners get rounded (car: radius ~4 m, cutting ~3 m; cart and
// handheld: ~0.35 m, cutting ~0.25 m). It is followed by arc length with a
// speed profile limited by lateral acceleration and path yaw rate,
// accelerating and braking gently (so the car slows into turns). The lidar x
// axis follows the path tangent, z stays up (tilting with slopes).
//  - Car: up to 15 m/s, turns at most 30 deg/s, light body vibration.
//  - Cart: up to 1 m/s, small high-frequency vibration.
//  - Handheld: up to 1.4 m/s, looking around (yaw rate up to ~170 deg/s,
//    below 180), pitch and roll sway, walking bob.
// Translation is C2 and rotation C1 in time. Throws std::invalid_argument for
// a route with fewer than 3 distinct or non-finite points or a U-turn (a turn
// above 170 deg), or bad options.
std::unique_ptr<Trajectory> makeTrajectory(const Scene& scene, const MotionOptions& options);

// A user pose file, T_world_lidar per line, interpolated in time (linear
// translation, slerp rotation), read by io::readPoseFile: TUM ("t x y z qx qy
// qz qw"), or KITTI (12 numbers, row-major 3x4) with its times from
// "<stem>_times.txt" next to it (poses.txt -> poses_times.txt, one time in
// seconds per line). KITTI poses without a times file are taken at 10 Hz
// from t = 0 (KITTI's Velodyne rate). Throws std::runtime_error naming the
// file and the problem for anything malformed, or times that do not increase.
std::unique_ptr<InterpolatedTrajectory> loadTrajectory(const std::string& path);

}  // namespace range_image_mapping::simulation
