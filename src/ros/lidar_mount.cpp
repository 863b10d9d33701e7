#include "range_image_mapping/ros/lidar_mount.h"

#include <ros/console.h>
#include <tf2_eigen/tf2_eigen.h>

#include <utility>

namespace range_image_mapping {

Matrix6d covarianceInFrame(const Eigen::Isometry3d& to_from_frame, const Matrix6d& covariance) {
  Matrix6d left;  // Ad C, column by column
  for (int c = 0; c < 6; ++c) left.col(c) = twistInFrame(to_from_frame, covariance.col(c));
  Matrix6d result;  // (Ad (Ad C)^T)^T = Ad C Ad^T
  for (int r = 0; r < 6; ++r) result.row(r) = twistInFrame(to_from_frame, left.row(r).transpose()).transpose();
  return result;
}

LidarMount::LidarMount(const tf2_ros::Buffer& tf, double timeout_s, std::string logger_name)
    : tf_(tf), timeout_s_(timeout_s), logger_name_(std::move(logger_name)) {}

const Eigen::Isometry3d* LidarMount::baseFromLidar(const std::string& base_frame, const std::string& lidar_frame) {
  if (base_frame != base_frame_ || lidar_frame != lidar_frame_) {
    base_frame_ = base_frame;
    lidar_frame_ = lidar_frame;
    base_from_lidar_.reset();
    fallback_.clear();
    wait_started_ = ros::SteadyTime::now();
    if (lidar_frame.empty() || lidar_frame == base_frame) base_from_lidar_ = Eigen::Isometry3d::Identity();
  }
  if (base_from_lidar_) return &*base_from_lidar_;
  std::string error;
  if (tf_.canTransform(base_frame, lidar_frame, ros::Time(0), &error)) {
    base_from_lidar_ = tf2::transformToEigen(tf_.lookupTransform(base_frame, lidar_frame, ros::Time(0)));
    const Eigen::Vector3d t = base_from_lidar_->translation();
    ROS_INFO_NAMED(logger_name_, "%s -> %s from tf: translation (%.3f, %.3f, %.3f) m", base_frame.c_str(),
                   lidar_frame.c_str(), t.x(), t.y(), t.z());
  } else if ((ros::SteadyTime::now() - wait_started_).toSec() >= timeout_s_) {
    base_from_lidar_ = Eigen::Isometry3d::Identity();
    fallback_ = "no transform " + base_frame + " -> " + lidar_frame + " on tf within lidar_transform_timeout: the " +
                "identity stands in, so the poses are the lidar's; publish the mount (static transform), set " +
                "base_frame to the lidar frame, or raise lidar_transform_timeout";
    ROS_WARN_NAMED(logger_name_, "no transform %s -> %s after %.1f s (%s): using the identity, so %s is the lidar",
                   base_frame.c_str(), lidar_frame.c_str(), timeout_s_, error.c_str(), base_frame.c_str());
  } else {
    return nullptr;
  }
  return &*base_from_lidar_;
}

}  // namespace range_image_mapping
