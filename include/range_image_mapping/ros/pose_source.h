// The pose of each scan the Mapper maps, from tf or from the odometry topic
// (parameter pose_source). In the spirit of voxblox's Transformer: given a
// scan (its frame and stamp), world_from_lidar and, from the odometry, the
// scan's twist, or the reason there is none. A scan's pose exists only after
// the scan (the Odometry publishes it once it has registered that scan), so
// the answer comes through a callback, once per scan, in the order given.
#pragma once

#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/ros/lidar_mount.h"
#include "range_image_mapping/ros/parameters.h"
#include "range_image_mapping/scan_motion.h"

#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <Eigen/Geometry>

#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <string>

namespace range_image_mapping {

struct LidarPose {
  Eigen::Isometry3d world_from_lidar = Eigen::Isometry3d::Identity();
  // Body twist of the lidar over the sweep, [angular, linear] in the lidar
  // frame: the odometry's (the velocity it deskewed the scan with). None from
  // tf, which carries poses only.
  std::optional<Twist> twist;
};

// A scan's pose, or why it has none.
struct PoseLookup {
  std::optional<LidarPose> pose;
  std::string reason;  // when there is no pose
};

class PoseSource {
 public:
  using Answer = std::function<void(const LidarRangeImage& scan, const PoseLookup& lookup)>;

  // node: the nodelet's (single-threaded) node handle, whose queue runs the
  // retries of scans waiting for tf; logger_name: the nodelet's name. Uses
  // world_frame, pose_source, tf_timeout, lidar_transform_timeout and
  // queue_size of parameters.
  PoseSource(ros::NodeHandle& node, const MapperParameters& parameters, const std::string& logger_name,
             Answer answer);
  PoseSource(const PoseSource&) = delete;  // the timer holds this object's address
  PoseSource& operator=(const PoseSource&) = delete;

  // pose_source tf: world_frame -> the scan's frame at its stamp. The scan
  // waits, in arrival order, until tf has it (the Odometry publishes it after
  // processing the same scan), at most tf_timeout of wall time; past
  // queue_size waiting scans the oldest is given up.
  void addScan(const LidarRangeImage::ConstPtr& scan);
  // pose_source odometry: the odometry message with the scan's stamp (the
  // Mapper's synchronizer pairs them), composed with base -> lidar from tf
  // (LidarMount). Answered at once.
  void addScan(const LidarRangeImage::ConstPtr& scan, const nav_msgs::Odometry& odometry);
  // Forgets the scans waiting for tf, unanswered (a map reset).
  void clear() { waiting_.clear(); }

  // Where the poses come from, for the start-up log.
  std::string description() const;

 private:
  void answerWaitingScans();
  PoseLookup fromOdometry(const LidarRangeImage& scan, const nav_msgs::Odometry& odometry);

  MapperParameters parameters_;
  Answer answer_;
  tf2_ros::Buffer tf_buffer_;
  tf2_ros::TransformListener tf_listener_;
  LidarMount mount_;

  struct WaitingScan {
    LidarRangeImage::ConstPtr scan;
    ros::SteadyTime arrived;
  };
  std::deque<WaitingScan> waiting_;
  ros::SteadyTimer retry_timer_;
};

}  // namespace range_image_mapping
