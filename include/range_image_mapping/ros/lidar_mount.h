// The lidar's mount on the robot's base: where it is (T_base_lidar, from tf),
// and how it carries a pose covariance from one frame to the other (twists:
// twistInFrame of the core). The Odometry and the Mapper follow the same
// rule, so they agree on what an odometry message means.
#pragma once

#include "range_image_mapping/scan_motion.h"

#include <tf2_ros/buffer.h>

#include <Eigen/Geometry>

#include <optional>
#include <string>

namespace range_image_mapping {

using Matrix6d = Eigen::Matrix<double, 6, 6>;

// The covariance of a pose perturbation of a frame, order [rotation,
// translation], as that of a frame rigidly attached to it with
// to_from_frame: Ad C Ad^T, Ad the adjoint that twistInFrame applies.
Matrix6d covarianceInFrame(const Eigen::Isometry3d& to_from_frame, const Matrix6d& covariance);

// T_base_lidar: the static transform from tf, looked up once per pair of
// frames, or the identity (the base is the lidar) once tf has had none for
// `timeout_s` of wall time since the pair was first asked for. Both outcomes
// are logged once, under `logger_name` (the nodelet's name).
class LidarMount {
 public:
  LidarMount(const tf2_ros::Buffer& tf, double timeout_s, std::string logger_name);

  // nullptr while waiting for tf. Frames equal (or an empty lidar frame):
  // the identity at once.
  const Eigen::Isometry3d* baseFromLidar(const std::string& base_frame, const std::string& lidar_frame);
  // What to tell the user when the identity stands in because tf had no
  // mount within the timeout (the poses are then the lidar's, labelled as
  // the base's); empty otherwise.
  const std::string& fallback() const { return fallback_; }

 private:
  const tf2_ros::Buffer& tf_;
  double timeout_s_;
  std::string logger_name_;
  std::string base_frame_, lidar_frame_;
  std::optional<Eigen::Isometry3d> base_from_lidar_;
  ros::SteadyTime wait_started_;
  std::string fallback_;
};

}  // namespace range_image_mapping
