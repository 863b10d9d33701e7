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
#include <map>
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

// Why a scan got no pose.
enum class NoPoseReason {
  kNone,          // it has a pose
  kQueueFull,     // queue_size newer scans were waiting: the oldest goes
  kTimedOut,      // its pose did not come within pose_timeout
  kSkipped,       // an odometry message for a later scan came, none for this one
  kUnusable,      // a pose came and cannot be used (wrong frame, failed lookup)
};

// A scan's pose, or why it has none.
struct PoseLookup {
  std::optional<LidarPose> pose;
  std::string reason;  // when there is no pose
  NoPoseReason no_pose = NoPoseReason::kNone;
  double waited_s = 0.0;  // wall time the scan waited for its pose
};

// Scans wait for their pose in a bounded queue, in arrival order: a scan's
// pose exists only after the Odometry registered that scan, and under load
// its message comes late. A scan leaves with its pose, or dropped with the
// reason (queue full, timed out, skipped by the odometry); never silently.
class PoseSource {
 public:
  using Answer = std::function<void(const LidarRangeImage& scan, const PoseLookup& lookup)>;

  // node: the nodelet's (single-threaded) node handle, whose queue runs the
  // retries of waiting scans; logger_name: the nodelet's name. Uses
  // world_frame, pose_source, pose_timeout, lidar_transform_timeout and
  // queue_size of parameters.
  PoseSource(ros::NodeHandle& node, const MapperParameters& parameters, const std::string& logger_name,
             Answer answer);
  PoseSource(const PoseSource&) = delete;  // the timer holds this object's address
  PoseSource& operator=(const PoseSource&) = delete;

  // A scan in. pose_source tf: world_frame -> the scan's frame at its stamp,
  // once tf has it (the Odometry publishes it after processing the same
  // scan). pose_source odometry: the odometry message with the scan's stamp
  // (addOdometry, before or after the scan), composed with base -> lidar from
  // tf (LidarMount). Scans are answered in arrival order; one waits at most
  // pose_timeout of wall time; past queue_size waiting scans the oldest is
  // given up.
  void addScan(const LidarRangeImage::ConstPtr& scan);
  // pose_source odometry: the pose of the scan with this stamp. Kept until
  // that scan comes (at most queue_size messages).
  void addOdometry(const nav_msgs::Odometry::ConstPtr& odometry);
  // Forgets the waiting scans, unanswered, and the odometry (a map reset).
  void clear();
  std::size_t waitingCount() const { return waiting_.size(); }
  // Non-empty when the identity stands in for a mount tf never had (LidarMount::fallback).
  const std::string& mountFallback() const { return mount_.fallback(); }

  // Where the poses come from, for the start-up log.
  std::string description() const;

 private:
  struct WaitingScan {
    LidarRangeImage::ConstPtr scan;
    ros::SteadyTime arrived;
  };
  void answerWaitingScans();
  // The scan's pose or why none; nullopt: keep waiting.
  std::optional<PoseLookup> lookUpTf(const WaitingScan& waiting, double waited_s);
  std::optional<PoseLookup> lookUpOdometry(const WaitingScan& waiting, double waited_s);
  // nullopt while base -> lidar is not on tf yet.
  std::optional<PoseLookup> fromOdometry(const LidarRangeImage& scan, const nav_msgs::Odometry& odometry);

  MapperParameters parameters_;
  Answer answer_;
  tf2_ros::Buffer tf_buffer_;
  tf2_ros::TransformListener tf_listener_;
  LidarMount mount_;

  std::deque<WaitingScan> waiting_;
  std::map<ros::Time, nav_msgs::Odometry::ConstPtr> odometry_;  // by stamp, for scans yet to come
  ros::Time last_odometry_stamp_;  // of the odometry message received last
  ros::SteadyTimer retry_timer_;
};

}  // namespace range_image_mapping
