// Odometry: range images in (the Adapter's shared pointers, same manager),
// LiDAR odometry out as nav_msgs/Odometry (the pose of base_link and its
// twist, the core's velocity carried through the lidar's mount), a bounded
// path, tf odom -> base_link and optionally the deskewed cloud.
//
// Every callback (images, the reset service, timers) runs on the nodelet's
// single-threaded queue (getNodeHandle), so the members need no locks. Nothing
// thrown by bad input leaves a callback: it is counted and logged (throttled).
#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/pipeline/scan_to_map_pipeline.h"
#include "range_image_mapping/ros/lidar_mount.h"
#include "range_image_mapping/ros/parameters.h"
#include "range_image_mapping/ros/range_image_conversions.h"
#include "range_image_mapping/ros/statistics_window.h"
#include "range_image_mapping/ros/steady_throttle.h"
#include "range_image_mapping/ros/wall_clock_diagnostics.h"

#include <diagnostic_updater/diagnostic_updater.h>
#include <geometry_msgs/PoseStamped.h>
#include <geometry_msgs/TransformStamped.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Empty.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include <boost/make_shared.hpp>

#include <limits>

#include <Eigen/Geometry>

#include <algorithm>
#include <deque>
#include <memory>
#include <optional>
#include <string>

namespace range_image_mapping {
namespace {

// Counts since the start; windows (log, diagnostics) are differences of two snapshots.
struct OdometryStatistics {
  std::size_t received = 0;        // range images that arrived
  std::size_t frames = 0;          // scans given to the odometry
  std::size_t registered = 0;      // scans registered (not skipped, not a reset)
  std::size_t iterations = 0;      // over registered scans
  std::size_t inliers = 0;         // over registered scans
  std::size_t degenerate = 0;
  std::size_t untrusted = 0;       // registrations that broke a physical limit (among degenerate)
  std::size_t suspect = 0;         // registered, but few pixels paired or moving objects fill the scan
  std::size_t coarse_passed_over = 0;        // registered scans with a coarse level passed over (min_coarse_pairs)
  std::size_t every_coarse_passed_over = 0;  // ... with every coarse level passed over
  double inlier_share = 0.0;       // sums over registered scans
  double moving_share = 0.0;
  double prior_difference_m = 0.0;
  std::size_t skipped = 0;
  std::size_t resets = 0;
  std::size_t dropped_frames = 0;  // gaps in the sensor's frame counter
  std::size_t out_of_order = 0;    // frames older than the last published one
  std::size_t rejected = 0;        // messages that could not be converted
  std::size_t published = 0;       // odometry messages published
  std::size_t held_for_mount = 0;  // scans that waited for tf base_frame -> lidar before their step
  std::size_t dropped_for_mount = 0;  // of those, dropped: too many waiting
  double seconds = 0.0;            // wall time in the odometry step

  OdometryStatistics operator-(const OdometryStatistics& earlier) const {
    OdometryStatistics d;
    d.received = received - earlier.received;
    d.frames = frames - earlier.frames;
    d.registered = registered - earlier.registered;
    d.iterations = iterations - earlier.iterations;
    d.inliers = inliers - earlier.inliers;
    d.degenerate = degenerate - earlier.degenerate;
    d.untrusted = untrusted - earlier.untrusted;
    d.suspect = suspect - earlier.suspect;
    d.coarse_passed_over = coarse_passed_over - earlier.coarse_passed_over;
    d.every_coarse_passed_over = every_coarse_passed_over - earlier.every_coarse_passed_over;
    d.inlier_share = inlier_share - earlier.inlier_share;
    d.moving_share = moving_share - earlier.moving_share;
    d.prior_difference_m = prior_difference_m - earlier.prior_difference_m;
    d.skipped = skipped - earlier.skipped;
    d.resets = resets - earlier.resets;
    d.dropped_frames = dropped_frames - earlier.dropped_frames;
    d.out_of_order = out_of_order - earlier.out_of_order;
    d.rejected = rejected - earlier.rejected;
    d.published = published - earlier.published;
    d.held_for_mount = held_for_mount - earlier.held_for_mount;
    d.dropped_for_mount = dropped_for_mount - earlier.dropped_for_mount;
    d.seconds = seconds - earlier.seconds;
    return d;
  }
};

}  // namespace

class OdometryNodelet : public nodelet::Nodelet {
 public:
  void onInit() override;

 private:
  void onRangeImage(const LidarRangeImage::ConstPtr& message);
  // Steps the scans held for the mount, in arrival order, as far as tf has it.
  void stepWaitingScans();
  void step(const LidarRangeImage::ConstPtr& message, const Eigen::Isometry3d& base_from_lidar);
  bool onReset(std_srvs::Empty::Request&, std_srvs::Empty::Response&);
  void noteFrameCounter(const LidarRangeImage& message);
  // step_s: time since the previous registered scan, 0 after a reset.
  void publish(const pipeline::ScanResult& result, const std_msgs::Header& header,
               const Eigen::Isometry3d& base_from_lidar, double step_s);
  void publishDeskewedCloud(const std_msgs::Header& header);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);
  void onStatisticsTimer(const ros::SteadyTimerEvent&);
  void clearTrajectory();

  OdometryParameters parameters_;
  std::unique_ptr<pipeline::ScanToMapPipeline> pipeline_;  // odometry only
  LidarModelCache models_;

  ros::Subscriber range_image_subscriber_;
  ros::Publisher odometry_publisher_, path_publisher_, deskewed_cloud_publisher_;
  // The range image without the pixels found moving, for the Mapper: the
  // incoming message itself (no copy) when nothing moved.
  ros::Publisher static_image_publisher_;
  void publishStaticImage(const LidarRangeImage::ConstPtr& message, const RangeImage& image,
                          const registration::OdometryUpdate& update);
  ros::ServiceServer reset_service_;
  ros::SteadyTimer statistics_timer_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  std::unique_ptr<tf2_ros::TransformBroadcaster> tf_broadcaster_;
  std::unique_ptr<LidarMount> mount_;  // base_frame -> lidar frame
  // Scans that arrived before the mount was known (tf base_frame -> lidar,
  // at most lidar_transform_timeout): held, not stepped, so the pipeline
  // poses the base from the first scan on and none goes unpublished. The
  // timer retries when no scan follows.
  std::deque<LidarRangeImage::ConstPtr> waiting_for_mount_;
  static constexpr std::size_t kMaxScansWaitingForMount = 200;
  ros::SteadyTimer mount_timer_;
  std::unique_ptr<WallClockDiagnostics> diagnostics_;

  // ROS time at the previous scan, and whether it has gone back since the
  // last scan that belonged to the new time (a bag loop).
  ros::Time last_ros_time_;
  bool ros_time_jumped_back_ = false;

  std::deque<geometry_msgs::PoseStamped> path_;
  ros::Time last_published_stamp_;
  std::optional<uint32_t> last_frame_counter_;

  OdometryStatistics statistics_;
  StatisticsWindow<OdometryStatistics> log_window_, diagnostics_window_;
  registration::OdometryUpdate last_update_;
  std::string last_warning_;
  SteadyThrottle warning_log_, error_log_, frame_log_;
};

void OdometryNodelet::onInit() {
  ros::NodeHandle& node = getNodeHandle();
  startOrRefuseLoad(getName(), "Odometry", [&] {
    parameters_ = readOdometryParameters(getPrivateNodeHandle());
    pipeline::PipelineOptions options;
    options.odometry = parameters_.odometry;
    pipeline_ = std::make_unique<pipeline::ScanToMapPipeline>(options);
  });
  tf_buffer_ = std::make_unique<tf2_ros::Buffer>();
  tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_);
  mount_ = std::make_unique<LidarMount>(*tf_buffer_, parameters_.lidar_transform_timeout_s, getName());
  if (parameters_.publish_tf) tf_broadcaster_ = std::make_unique<tf2_ros::TransformBroadcaster>();

  odometry_publisher_ = node.advertise<nav_msgs::Odometry>("odometry", 16);
  static_image_publisher_ = node.advertise<LidarRangeImage>("static_range_image", 16);
  if (parameters_.path_length > 0) path_publisher_ = node.advertise<nav_msgs::Path>("path", 1);
  if (parameters_.publish_deskewed_cloud)
    deskewed_cloud_publisher_ = node.advertise<sensor_msgs::PointCloud2>("deskewed_cloud", 4);
  reset_service_ = getPrivateNodeHandle().advertiseService("reset", &OdometryNodelet::onReset, this);

  diagnostics_ = std::make_unique<WallClockDiagnostics>(node, getPrivateNodeHandle(), getName(), "lidar_odometry");
  diagnostics_->updater().add("odometry", this, &OdometryNodelet::diagnose);
  statistics_timer_ = node.createSteadyTimer(ros::WallDuration(parameters_.statistics_period_s),
                                             &OdometryNodelet::onStatisticsTimer, this);

  range_image_subscriber_ = node.subscribe("range_image", parameters_.queue_size,
                                           &OdometryNodelet::onRangeImage, this);
  mount_timer_ = node.createSteadyTimer(ros::WallDuration(0.05), [this](const ros::SteadyTimerEvent&) {
    if (waiting_for_mount_.empty()) return;
    try {
      stepWaitingScans();
    } catch (const std::exception& error) {
      NODELET_ERROR("scans waiting for tf %s -> lidar: %s", parameters_.base_frame.c_str(), error.what());
    }
  });
  NODELET_INFO("Odometry: range images from %s, odometry on %s, %s %s -> %s%s",
               range_image_subscriber_.getTopic().c_str(), odometry_publisher_.getTopic().c_str(),
               parameters_.publish_tf ? "tf" : "no tf",
               parameters_.invert_tf ? parameters_.base_frame.c_str() : parameters_.odom_frame.c_str(),
               parameters_.invert_tf ? parameters_.odom_frame.c_str() : parameters_.base_frame.c_str(),
               parameters_.invert_tf ? " (inverted)" : "");
}

void OdometryNodelet::onRangeImage(const LidarRangeImage::ConstPtr& message) {
  try {
    ++statistics_.received;
    noteFrameCounter(*message);
    waiting_for_mount_.push_back(message);
    if (waiting_for_mount_.size() > kMaxScansWaitingForMount) {
      const LidarRangeImage::ConstPtr oldest = waiting_for_mount_.front();
      waiting_for_mount_.pop_front();
      ++statistics_.dropped_for_mount;
      last_warning_ = "scans dropped waiting for tf " + parameters_.base_frame + " -> " + oldest->header.frame_id +
                      ": publish the lidar's mount (static transform), or set base_frame to the lidar frame";
      if (frame_log_.allow(1.0))
        NODELET_WARN("frame %u dropped: %zu scans wait for tf %s -> %s (%zu dropped so far); publish the lidar's "
                     "mount, or set base_frame to the lidar frame",
                     oldest->frame_id, kMaxScansWaitingForMount, parameters_.base_frame.c_str(),
                     oldest->header.frame_id.c_str(), statistics_.dropped_for_mount);
    }
    stepWaitingScans();
    if (!waiting_for_mount_.empty()) ++statistics_.held_for_mount;
  } catch (const std::exception& error) {
    ++statistics_.rejected;
    if (error_log_.allow(parameters_.statistics_period_s))
      NODELET_ERROR("range image on %s failed: %s", range_image_subscriber_.getTopic().c_str(), error.what());
  }
}

void OdometryNodelet::stepWaitingScans() {
  const std::size_t waited = waiting_for_mount_.size();
  while (!waiting_for_mount_.empty()) {
    const LidarRangeImage::ConstPtr message = waiting_for_mount_.front();
    const Eigen::Isometry3d* mount = mount_->baseFromLidar(parameters_.base_frame, message->header.frame_id);
    if (!mount) return;  // tf has not got it yet; the next scan or the timer asks again
    const Eigen::Isometry3d base_from_lidar = *mount;
    if (waited > 1 && waiting_for_mount_.size() == waited)
      NODELET_INFO("%zu scans waited for tf %s -> %s: stepped now", waited, parameters_.base_frame.c_str(),
                   message->header.frame_id.c_str());
    waiting_for_mount_.pop_front();
    step(message, base_from_lidar);
  }
}

void OdometryNodelet::step(const LidarRangeImage::ConstPtr& message, const Eigen::Isometry3d& base_from_lidar) {
  try {
    RangeImage image;
    try {
      image = fromMessage(*message, models_);
    } catch (const std::exception& error) {
      ++statistics_.rejected;
      if (error_log_.allow(parameters_.statistics_period_s))
        NODELET_ERROR("range image on %s dropped: %s", range_image_subscriber_.getTopic().c_str(), error.what());
      return;
    }
    // The mount first: the pipeline poses the base, odom being the base at the first scan.
    pipeline_->setBaseFromLidar(base_from_lidar);

    // ROS time going back (a bag loop, a restarted replay): the source
    // started over, and the pipeline restarts the odometry at the identity if
    // the scan is older than the last (not for a scan that continues the data).
    const ros::Time now = ros::Time::now();
    if (!last_ros_time_.isZero() && now < last_ros_time_) ros_time_jumped_back_ = true;
    last_ros_time_ = now;
    const pipeline::ScanResult result = pipeline_->process(image, ros_time_jumped_back_);
    registration::OdometryUpdate update = *result.odometry;
    if (result.restart == pipeline::Restart::kSourceStartedOver)
      update.warning = "ROS time jumped back (a bag loop or a restarted replay); " + update.warning;
    if (result.restart == pipeline::Restart::kSourceStartedOver || message->header.stamp <= now)
      ros_time_jumped_back_ = false;
    ++statistics_.frames;
    statistics_.seconds += update.seconds;
    if (update.skipped) ++statistics_.skipped;
    if (update.reset) ++statistics_.resets;
    if (update.degenerate) ++statistics_.degenerate;
    if (update.limit_exceeded) ++statistics_.untrusted;
    if (!update.skipped && !update.reset) {
      ++statistics_.registered;
      statistics_.iterations += update.iterations;
      statistics_.inliers += update.inliers;
      statistics_.inlier_share += update.inlierShare();
      statistics_.moving_share += update.movingShare();
      statistics_.prior_difference_m += update.prior_difference_m;
      if (update.suspect) ++statistics_.suspect;
      if (update.levels_passed_over > 0) ++statistics_.coarse_passed_over;
      if (update.every_coarse_level_passed_over) ++statistics_.every_coarse_passed_over;
    }
    const double step_s = update.reset || update.skipped || last_update_.stamp_ns == 0 ||
                                  update.stamp_ns <= last_update_.stamp_ns
                              ? 0.0
                              : double(update.stamp_ns - last_update_.stamp_ns) * 1e-9;
    if (!update.skipped) last_update_ = update;
    if (update.reset && update.warning.empty())  // the first scan
      NODELET_INFO("odometry started: frame %u in %s, stamped %.3f", message->frame_id,
                   message->header.frame_id.c_str(), message->header.stamp.toSec());
    if (!update.warning.empty()) {
      last_warning_ = update.warning;
      if (warning_log_.allow(1.0))
        NODELET_WARN("odometry, frame %u stamped %.3f: %s", message->frame_id, message->header.stamp.toSec(),
                     update.warning.c_str());
    }
    if (update.reset) clearTrajectory();
    if (update.skipped) return;

    if (!last_published_stamp_.isZero() && message->header.stamp <= last_published_stamp_ && !update.reset) {
      ++statistics_.out_of_order;
      if (frame_log_.allow(1.0))
        NODELET_WARN("frame %u stamped %.3f is not after the last published one (%.3f): not published",
                     message->frame_id, message->header.stamp.toSec(), last_published_stamp_.toSec());
      return;
    }
    publish(result, message->header, base_from_lidar, step_s);
    if (static_image_publisher_.getNumSubscribers() > 0) publishStaticImage(message, image, update);
    if (deskewed_cloud_publisher_ && deskewed_cloud_publisher_.getNumSubscribers() > 0)
      publishDeskewedCloud(message->header);
    diagnostics_->updater().update();
  } catch (const std::exception& error) {
    ++statistics_.rejected;
    if (error_log_.allow(parameters_.statistics_period_s))
      NODELET_ERROR("range image on %s failed: %s", range_image_subscriber_.getTopic().c_str(), error.what());
  }
}

// Ouster revolutions count up by one: a gap means scans were dropped (by the
// Adapter, a full queue or the network), a step back a restart or a bag loop.
// Sources without a counter (PointCloud2) send 0 throughout.
void OdometryNodelet::noteFrameCounter(const LidarRangeImage& message) {
  const uint32_t counter = message.frame_id;
  if (last_frame_counter_ && !(counter == 0 && *last_frame_counter_ == 0)) {
    const uint32_t previous = *last_frame_counter_;
    if (counter > previous + 1) {
      statistics_.dropped_frames += counter - previous - 1;
      if (frame_log_.allow(1.0))
        NODELET_WARN("dropped frames: frame %u follows frame %u (%u missing, %zu so far)", counter, previous,
                     counter - previous - 1, statistics_.dropped_frames);
    } else if (counter <= previous) {
      if (frame_log_.allow(1.0))
        NODELET_WARN("frame %u after frame %u: out of order, a restart or a bag loop", counter, previous);
    }
  }
  last_frame_counter_ = counter;
}

void OdometryNodelet::publish(const pipeline::ScanResult& result, const std_msgs::Header& header,
                              const Eigen::Isometry3d& base_from_lidar, double step_s) {
  const Eigen::Isometry3d& odom_from_base = result.world_from_base;  // odom: base_frame at the first scan
  if (!odom_from_base.matrix().allFinite()) {
    NODELET_ERROR("non-finite pose for frame stamped %.3f: not published", header.stamp.toSec());
    return;
  }
  last_published_stamp_ = header.stamp;
  ++statistics_.published;

  const auto odometry = boost::make_shared<nav_msgs::Odometry>();
  odometry->header.stamp = header.stamp;
  odometry->header.frame_id = parameters_.odom_frame;
  odometry->child_frame_id = parameters_.base_frame;
  odometry->pose.pose = tf2::toMsg(odom_from_base);
  // The lidar's motion as the base's, in base_frame (nav_msgs: the twist is
  // in child_frame_id): the pose perturbation's covariance and the body twist
  // both change frame with the mount's adjoint.
  const Matrix6d covariance = covarianceInFrame(base_from_lidar, result.odometry->covariance);
  toCovarianceMessage(covariance, odometry->pose.covariance);
  odometry->twist.twist = toTwistMessage(twistInFrame(base_from_lidar, result.twist));
  // The registration's covariance is that of one step: divided by the step's
  // squared duration, the velocity's. Unknown (the core's identity) otherwise.
  toCovarianceMessage(step_s > 0.0 ? Matrix6d(covariance / (step_s * step_s)) : covariance,
                      odometry->twist.covariance);
  odometry_publisher_.publish(boost::shared_ptr<const nav_msgs::Odometry>(odometry));

  if (tf_broadcaster_) {
    geometry_msgs::TransformStamped transform =
        tf2::eigenToTransform(parameters_.invert_tf ? odom_from_base.inverse() : odom_from_base);
    transform.header.stamp = header.stamp;
    transform.header.frame_id = parameters_.invert_tf ? parameters_.base_frame : parameters_.odom_frame;
    transform.child_frame_id = parameters_.invert_tf ? parameters_.odom_frame : parameters_.base_frame;
    tf_broadcaster_->sendTransform(transform);
  }

  if (path_publisher_) {
    geometry_msgs::PoseStamped pose;
    pose.header = odometry->header;
    pose.pose = odometry->pose.pose;
    path_.push_back(pose);
    while (path_.size() > std::size_t(parameters_.path_length)) path_.pop_front();
    if (path_publisher_.getNumSubscribers() > 0) {
      const auto path = boost::make_shared<nav_msgs::Path>();
      path->header = odometry->header;
      path->poses.assign(path_.begin(), path_.end());
      path_publisher_.publish(boost::shared_ptr<const nav_msgs::Path>(path));
    }
  }
}

void OdometryNodelet::publishDeskewedCloud(const std_msgs::Header& header) {
  const auto cloud = boost::make_shared<sensor_msgs::PointCloud2>();
  pointsToPointCloud2(pipeline_->odometry()->deskewedScan().points, nullptr, header, *cloud);
  deskewed_cloud_publisher_.publish(boost::shared_ptr<const sensor_msgs::PointCloud2>(cloud));
}

void OdometryNodelet::clearTrajectory() {
  path_.clear();
  last_published_stamp_ = ros::Time();
}

bool OdometryNodelet::onReset(std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
  pipeline_->reset();
  clearTrajectory();
  last_frame_counter_.reset();
  last_update_ = registration::OdometryUpdate();
  NODELET_INFO("odometry reset: the next scan starts at the identity");
  return true;
}

void OdometryNodelet::publishStaticImage(const LidarRangeImage::ConstPtr& message, const RangeImage& image,
                                         const registration::OdometryUpdate& update) {
  if (update.moving_pixels == 0) {
    static_image_publisher_.publish(message);
    return;
  }
  // The odometry's mask is per staggered pixel; the message keeps its order.
  RangeImage staggered = image.column_order == ColumnOrder::kStaggered ? image : image.staggered();
  const std::vector<uint8_t>& moving = pipeline_->odometry()->movingPixels();
  if (moving.size() != staggered.range.size()) {
    // Never leave the Mapper without the scan: mapped as it came, and said.
    if (error_log_.allow(parameters_.statistics_period_s))
      NODELET_WARN("moving-pixel mask of %zu pixels for a %zu-pixel image: scan passed to the Mapper unmasked",
                   moving.size(), staggered.range.size());
    static_image_publisher_.publish(message);
    return;
  }
  for (std::size_t i = 0; i < moving.size(); ++i)
    if (moving[i]) staggered.range[i] = std::numeric_limits<float>::quiet_NaN();
  const LidarRangeImage::Ptr masked = boost::make_shared<LidarRangeImage>(*message);
  masked->range = image.column_order == ColumnOrder::kStaggered ? staggered.range : staggered.destaggered().range;
  static_image_publisher_.publish(masked);
}

void OdometryNodelet::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  const auto [window, period] = diagnostics_window_.advance(statistics_);
  const double rate = period > 0.0 ? double(window.frames) / period : 0.0;
  const double registered = std::max<double>(1.0, double(window.registered));
  status.add("rate (Hz)", rate);
  status.add("frames", window.frames);
  status.add("mean iterations", double(window.iterations) / registered);
  status.add("mean inliers", double(window.inliers) / registered);
  status.add("mean step (ms)", window.frames > 0 ? 1e3 * window.seconds / double(window.frames) : 0.0);
  status.add("degenerate", window.degenerate);
  status.add("untrusted (physical limits)", window.untrusted);
  status.add("suspect (few pairs or many moving pixels)", window.suspect);
  status.add("coarse levels passed over (scans; min_coarse_pairs)", window.coarse_passed_over);
  status.add("every coarse level passed over (scans)", window.every_coarse_passed_over);
  status.add("mean inlier share", window.inlier_share / registered);
  status.add("mean moving share", window.moving_share / registered);
  status.add("mean difference from the motion prior (m)", window.prior_difference_m / registered);
  status.add("skipped", window.skipped);
  status.add("resets", window.resets);
  status.add("dropped frames", window.dropped_frames);
  status.add("out of order", window.out_of_order);
  status.add("rejected messages", window.rejected);
  status.add("scans waiting for tf (base_frame -> lidar)", waiting_for_mount_.size());
  status.add("dropped waiting for tf", window.dropped_for_mount);
  status.add("total scans received", statistics_.received);
  status.add("total scans stepped", statistics_.frames);
  status.add("total scans published", statistics_.published);
  status.add("total scans held for tf (base_frame -> lidar)", statistics_.held_for_mount);
  status.add("total dropped frames", statistics_.dropped_frames);
  status.add("total out of order", statistics_.out_of_order);
  status.add("condition number", last_update_.condition_number);
  status.add("keyframe distance in use (m)", last_update_.keyframe_distance_m);
  status.add("last warning", last_warning_);
  if (!mount_->fallback().empty())
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, mount_->fallback());
  else if (window.dropped_for_mount > 0 || !waiting_for_mount_.empty())
    status.summaryf(diagnostic_msgs::DiagnosticStatus::WARN,
                    "scans wait for tf %s -> lidar (the mount; up to %g s, lidar_transform_timeout): publish it, or "
                    "set base_frame to the lidar frame",
                    parameters_.base_frame.c_str(), parameters_.lidar_transform_timeout_s);
  else if (window.frames == 0)
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "no range images");
  else if (window.degenerate + window.suspect + window.every_coarse_passed_over + window.dropped_frames +
               window.out_of_order + window.rejected + window.skipped >
           0)
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN,
                   window.untrusted > 0   ? "registrations broke a physical limit (max_speed, max_angular_rate_deg, "
                                            "max_acceleration): a moving object or a wrong match; motion prior used"
                   : window.degenerate > 0 ? "degenerate registrations"
                   : window.suspect > 0    ? "suspect registrations: moving objects fill much of the view, or few "
                                             "pixels pair with the model (check the sensor settings); see last warning"
                   : window.every_coarse_passed_over > 0
                       ? "every coarse level passed over (fewer than min_coarse_pairs pairs): only full resolution "
                         "registers, with a short capture range; check the sensor model, or use fewer, finer strides"
                                           : "dropped, skipped or out-of-order frames");
  else
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, "tracking");
}

void OdometryNodelet::onStatisticsTimer(const ros::SteadyTimerEvent&) {
  const auto [window, period] = log_window_.advance(statistics_);
  if (window.received == 0 || period <= 0.0) return;
  // Scans received but none stepped: they wait for the mount (stepWaitingScans).
  const double stepped = std::max<double>(1.0, double(window.frames));
  const double registered = std::max<double>(1.0, double(window.registered));
  NODELET_INFO("odometry: %.1f Hz, %.1f ms per step, %.1f iterations, %.0f inliers (%.0f %% of pixels), %.1f %% "
               "moving; degenerate %zu (untrusted %zu), suspect %zu, coarse levels passed over %zu (all %zu), "
               "skipped %zu, resets %zu, dropped %zu, out of order %zu, rejected %zu; %zu received, %zu held and %zu "
               "dropped waiting for tf %s -> lidar",
               double(window.frames) / period, 1e3 * window.seconds / stepped,
               double(window.iterations) / registered, double(window.inliers) / registered,
               100.0 * window.inlier_share / registered, 100.0 * window.moving_share / registered, window.degenerate,
               window.untrusted, window.suspect, window.coarse_passed_over, window.every_coarse_passed_over,
               window.skipped, window.resets, window.dropped_frames, window.out_of_order,
               window.rejected, window.received, window.held_for_mount, window.dropped_for_mount,
               parameters_.base_frame.c_str());
}

}  // namespace range_image_mapping

PLUGINLIB_EXPORT_CLASS(range_image_mapping::OdometryNodelet, nodelet::Nodelet)
