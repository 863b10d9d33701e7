#include "range_image_mapping/ros/pose_source.h"

#include "range_image_mapping/ros/range_image_conversions.h"

#include <tf2_eigen/tf2_eigen.h>

#include <utility>

namespace range_image_mapping {

PoseSource::PoseSource(ros::NodeHandle& node, const MapperParameters& parameters, const std::string& logger_name,
                       Answer answer)
    : parameters_(parameters),
      answer_(std::move(answer)),
      tf_buffer_(ros::Duration(30.0)),
      tf_listener_(tf_buffer_),
      mount_(tf_buffer_, parameters.lidar_transform_timeout_s, logger_name) {
  // Scans waiting for tf are retried at this period, not only when the next scan arrives.
  if (parameters_.pose_source == PoseSourceType::kTf)
    retry_timer_ = node.createSteadyTimer(ros::WallDuration(0.02),
                                          [this](const ros::SteadyTimerEvent&) { answerWaitingScans(); });
}

std::string PoseSource::description() const {
  return parameters_.pose_source == PoseSourceType::kTf
             ? "tf " + parameters_.world_frame + " -> image frame"
             : "the odometry (same stamp) and tf base -> lidar";
}

void PoseSource::addScan(const LidarRangeImage::ConstPtr& scan) {
  if (int(waiting_.size()) >= parameters_.queue_size) {
    const LidarRangeImage::ConstPtr oldest = waiting_.front().scan;
    waiting_.pop_front();
    answer_(*oldest, {std::nullopt, "the queue of scans waiting for tf is full"});
  }
  waiting_.push_back({scan, ros::SteadyTime::now()});
  answerWaitingScans();
}

void PoseSource::answerWaitingScans() {
  while (!waiting_.empty()) {
    // Off the queue before the answer, which may clear it (a reset).
    const LidarRangeImage::ConstPtr scan = waiting_.front().scan;
    const ros::SteadyTime arrived = waiting_.front().arrived;
    const std::string& frame = scan->header.frame_id;
    std::string error;
    PoseLookup lookup;
    if (tf_buffer_.canTransform(parameters_.world_frame, frame, scan->header.stamp, &error)) {
      try {
        lookup.pose = LidarPose{
            tf2::transformToEigen(tf_buffer_.lookupTransform(parameters_.world_frame, frame, scan->header.stamp)),
            std::nullopt};
      } catch (const std::exception& lookup_error) {
        lookup.reason = std::string("tf lookup failed: ") + lookup_error.what();
      }
    } else if ((ros::SteadyTime::now() - arrived).toSec() < parameters_.tf_timeout_s) {
      return;  // still waiting, and so are the scans behind it
    } else {
      lookup.reason = "no transform " + parameters_.world_frame + " -> " + frame + " within " +
                      std::to_string(parameters_.tf_timeout_s) + " s: " + error;
    }
    waiting_.pop_front();
    answer_(*scan, lookup);
  }
}

void PoseSource::addScan(const LidarRangeImage::ConstPtr& scan, const nav_msgs::Odometry& odometry) {
  PoseLookup lookup;
  try {
    lookup = fromOdometry(*scan, odometry);
  } catch (const std::exception& error) {
    lookup = {std::nullopt, std::string("pose from the odometry failed: ") + error.what()};
  }
  answer_(*scan, lookup);
}

PoseLookup PoseSource::fromOdometry(const LidarRangeImage& scan, const nav_msgs::Odometry& odometry) {
  if (odometry.header.frame_id != parameters_.world_frame)
    return {std::nullopt, "the odometry is in frame '" + odometry.header.frame_id + "', world_frame is '" +
                              parameters_.world_frame + "'"};
  const Eigen::Isometry3d* base_from_lidar = mount_.baseFromLidar(odometry.child_frame_id, scan.header.frame_id);
  if (!base_from_lidar)
    return {std::nullopt, "waiting for tf " + odometry.child_frame_id + " -> " + scan.header.frame_id};
  Eigen::Isometry3d world_from_base;
  tf2::fromMsg(odometry.pose.pose, world_from_base);
  // The message's twist is the base's, in the base frame (child_frame_id):
  // back to the lidar's, the inverse of the Odometry's change.
  const Twist lidar_twist = twistInFrame(base_from_lidar->inverse(), fromTwistMessage(odometry.twist.twist));
  return {LidarPose{world_from_base * *base_from_lidar, lidar_twist}, ""};
}

}  // namespace range_image_mapping
