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
  // Waiting scans are retried at this period (tf, the mount, timeouts), not
  // only when the next scan or odometry message arrives.
  retry_timer_ =
      node.createSteadyTimer(ros::WallDuration(0.02), [this](const ros::SteadyTimerEvent&) { answerWaitingScans(); });
}

std::string PoseSource::description() const {
  return parameters_.pose_source == PoseSourceType::kTf
             ? "tf " + parameters_.world_frame + " -> image frame"
             : "the odometry (same stamp) and tf base -> lidar";
}

void PoseSource::clear() {
  waiting_.clear();
  odometry_.clear();
  last_odometry_stamp_ = ros::Time();
}

void PoseSource::addScan(const LidarRangeImage::ConstPtr& scan) {
  if (int(waiting_.size()) >= parameters_.queue_size) {
    const WaitingScan oldest = waiting_.front();
    waiting_.pop_front();
    PoseLookup lookup;
    lookup.reason = "the queue of " + std::to_string(parameters_.queue_size) +
                    " scans waiting for their pose is full (queue_size)";
    lookup.no_pose = NoPoseReason::kQueueFull;
    lookup.waited_s = (ros::SteadyTime::now() - oldest.arrived).toSec();
    answer_(*oldest.scan, lookup);
  }
  waiting_.push_back({scan, ros::SteadyTime::now()});
  answerWaitingScans();
}

void PoseSource::addOdometry(const nav_msgs::Odometry::ConstPtr& odometry) {
  odometry_[odometry->header.stamp] = odometry;
  last_odometry_stamp_ = odometry->header.stamp;  // the latest, also when time went back (a replay loop)
  while (int(odometry_.size()) > parameters_.queue_size) odometry_.erase(odometry_.begin());
  answerWaitingScans();
}

void PoseSource::answerWaitingScans() {
  while (!waiting_.empty()) {
    const WaitingScan& front = waiting_.front();
    const double waited_s = (ros::SteadyTime::now() - front.arrived).toSec();
    std::optional<PoseLookup> lookup = parameters_.pose_source == PoseSourceType::kTf
                                           ? lookUpTf(front, waited_s)
                                           : lookUpOdometry(front, waited_s);
    if (!lookup) return;  // still waiting, and so are the scans behind it
    lookup->waited_s = waited_s;
    // Off the queue before the answer, which may clear it (a reset).
    const LidarRangeImage::ConstPtr scan = front.scan;
    waiting_.pop_front();
    if (parameters_.pose_source == PoseSourceType::kOdometry)  // what is older is for no scan to come
      odometry_.erase(odometry_.begin(), odometry_.upper_bound(scan->header.stamp));
    answer_(*scan, *lookup);
  }
}

std::optional<PoseLookup> PoseSource::lookUpTf(const WaitingScan& waiting, double waited_s) {
  const LidarRangeImage& scan = *waiting.scan;
  const std::string& frame = scan.header.frame_id;
  std::string error;
  PoseLookup lookup;
  if (tf_buffer_.canTransform(parameters_.world_frame, frame, scan.header.stamp, &error)) {
    try {
      lookup.pose = LidarPose{
          tf2::transformToEigen(tf_buffer_.lookupTransform(parameters_.world_frame, frame, scan.header.stamp)),
          std::nullopt};
    } catch (const std::exception& lookup_error) {
      lookup.reason = std::string("tf lookup failed: ") + lookup_error.what();
      lookup.no_pose = NoPoseReason::kUnusable;
    }
    return lookup;
  }
  if (waited_s < parameters_.pose_timeout_s) return std::nullopt;
  lookup.reason = "no transform " + parameters_.world_frame + " -> " + frame + " within " +
                  std::to_string(parameters_.pose_timeout_s) + " s (pose_timeout): " + error;
  lookup.no_pose = NoPoseReason::kTimedOut;
  return lookup;
}

std::optional<PoseLookup> PoseSource::lookUpOdometry(const WaitingScan& waiting, double waited_s) {
  const LidarRangeImage& scan = *waiting.scan;
  const auto found = odometry_.find(scan.header.stamp);
  std::optional<PoseLookup> lookup;
  if (found != odometry_.end()) {
    try {
      lookup = fromOdometry(scan, *found->second);
    } catch (const std::exception& error) {
      lookup = PoseLookup{std::nullopt, std::string("pose from the odometry failed: ") + error.what(),
                          NoPoseReason::kUnusable};
    }
    if (lookup || waited_s < parameters_.pose_timeout_s) return lookup;
    return PoseLookup{std::nullopt,
                      "no tf " + found->second->child_frame_id + " -> " + scan.header.frame_id + " within " +
                          std::to_string(parameters_.pose_timeout_s) + " s (pose_timeout)",
                      NoPoseReason::kTimedOut};
  }
  // The odometry poses scans in order: a later one posed means this one never will be.
  if (last_odometry_stamp_ > scan.header.stamp)
    return PoseLookup{std::nullopt,
                      "no odometry for this scan, and one for a later scan came: the Odometry skipped this one, "
                      "or the odometry subscriber queue (queue_size) was full",
                      NoPoseReason::kSkipped};
  if (waited_s < parameters_.pose_timeout_s) return std::nullopt;
  return PoseLookup{std::nullopt,
                    "no odometry with the same stamp within " + std::to_string(parameters_.pose_timeout_s) +
                        " s (pose_timeout)",
                    NoPoseReason::kTimedOut};
}

std::optional<PoseLookup> PoseSource::fromOdometry(const LidarRangeImage& scan, const nav_msgs::Odometry& odometry) {
  if (odometry.header.frame_id != parameters_.world_frame)
    return PoseLookup{std::nullopt,
                      "the odometry is in frame '" + odometry.header.frame_id + "', world_frame is '" +
                          parameters_.world_frame + "'",
                      NoPoseReason::kUnusable};
  const Eigen::Isometry3d* base_from_lidar = mount_.baseFromLidar(odometry.child_frame_id, scan.header.frame_id);
  if (!base_from_lidar) return std::nullopt;  // waiting for tf base -> lidar
  Eigen::Isometry3d world_from_base;
  tf2::fromMsg(odometry.pose.pose, world_from_base);
  // The message's twist is the base's, in the base frame (child_frame_id):
  // back to the lidar's, the inverse of the Odometry's change.
  const Twist lidar_twist = twistInFrame(base_from_lidar->inverse(), fromTwistMessage(odometry.twist.twist));
  return PoseLookup{LidarPose{world_from_base * *base_from_lidar, lidar_twist}, ""};
}

}  // namespace range_image_mapping
