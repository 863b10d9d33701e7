// A simulated Ouster sequence (rim simulate, written as a bag of raw packets)
// replayed through odometry.launch: the odometry and tf must follow the
// simulator's ground truth (ATE after SE(3) alignment), the twist must be the
// ground truth's velocity of base_link in base_link (nav_msgs: the twist is
// in child_frame_id), the tf chain odom -> base_link -> lidar must exist and
// agree with the odometry messages, and the covariances must be finite.
// write_odometry_bag.sh writes the sequence while roslaunch loads the test.
#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/evaluation/trajectory_metrics.h"
#include "range_image_mapping/ros/range_image_conversions.h"
#include "range_image_mapping/scan_motion.h"

#include "rostest_main.h"
#include "spin_until.h"

#include <diagnostic_msgs/DiagnosticArray.h>
#include <geometry_msgs/TransformStamped.h>
#include <gtest/gtest.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Empty.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

using test::spinUntil;

struct Settings {
  std::string bag_file, ground_truth_file;
  std::string odom_frame, base_frame, lidar_frame, sensor_frame;
  bool invert_tf = false;
  double timeout_s = 60.0;
  double max_ate_m = 0.1;
  double max_rotation_error_deg = 1.0;
  double max_linear_velocity_error_mps = 0.1;    // rms over the scans
  double max_angular_velocity_error_radps = 0.05;
  int min_frames = 25;
  // > 0: the mount base_link -> sensor goes on tf only once this many range
  // images were seen, so the Odometry must hold the scans until it comes.
  int mount_after_scans = 0;
  // Non-empty: the run starves every coarse level (min_coarse_pairs in
  // extra_config), and diagnostics must say so with a WARN naming this;
  // empty: no scan may have had every coarse level passed over.
  std::string expect_coarse_warning;
};

Settings readSettings() {
  ros::NodeHandle private_node("~");
  Settings settings;
  settings.bag_file = private_node.param<std::string>("bag_file", "");
  settings.ground_truth_file = std::filesystem::path(settings.bag_file).parent_path() / "poses_tum.txt";
  settings.odom_frame = private_node.param<std::string>("odom_frame", "odom");
  settings.base_frame = private_node.param<std::string>("base_frame", "base_link");
  settings.lidar_frame = private_node.param<std::string>("lidar_frame", "os_lidar");
  settings.sensor_frame = private_node.param<std::string>("sensor_frame", "os_sensor");
  settings.invert_tf = private_node.param("invert_tf", false);
  settings.timeout_s = private_node.param("timeout", settings.timeout_s);
  settings.max_ate_m = private_node.param("max_ate", settings.max_ate_m);
  settings.max_rotation_error_deg = private_node.param("max_rotation_error_deg", settings.max_rotation_error_deg);
  settings.max_linear_velocity_error_mps =
      private_node.param("max_linear_velocity_error", settings.max_linear_velocity_error_mps);
  settings.max_angular_velocity_error_radps =
      private_node.param("max_angular_velocity_error", settings.max_angular_velocity_error_radps);
  settings.min_frames = private_node.param("min_frames", settings.min_frames);
  settings.mount_after_scans = private_node.param("mount_after_scans", settings.mount_after_scans);
  settings.expect_coarse_warning = private_node.param<std::string>("expect_coarse_warning", "");
  return settings;
}

// The robot carries the sensor off-centre and slightly turned, so a wrong
// composition of base_link -> lidar shows in the trajectory.
Eigen::Isometry3d baseFromSensor() {
  Eigen::Isometry3d transform = Eigen::Isometry3d::Identity();
  transform.translate(Eigen::Vector3d(0.3, -0.1, 0.8));
  transform.rotate(Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitZ()));
  return transform;
}

// The bag's time origin, where the simulator's clock (the ground truth's
// times) starts: rim simulate writes the latched Ouster metadata at it, and
// stamps each cloud with it plus the scan's time.
double bagEpochSeconds(const std::string& bag_file, double first_ground_truth_time_s) {
  rosbag::Bag bag(bag_file, rosbag::bagmode::Read);
  rosbag::View view(bag);
  if (view.size() == 0) throw std::runtime_error(bag_file + " is empty");
  for (const rosbag::MessageInstance& message : view)
    if (message.getTopic() == "/ouster/metadata") return message.getTime().toSec();
  return view.begin()->getTime().toSec() - first_ground_truth_time_s;
}

TEST(OdometrySimulated, FollowsTheGroundTruthOnTfAndOdometry) {
  const Settings settings = readSettings();
  ASSERT_TRUE(std::filesystem::exists(settings.bag_file)) << settings.bag_file;
  ros::NodeHandle node;
  tf2_ros::Buffer tf_buffer(ros::Duration(120.0));
  tf2_ros::TransformListener tf_listener(tf_buffer);
  tf2_ros::StaticTransformBroadcaster static_broadcaster;
  geometry_msgs::TransformStamped mount = tf2::eigenToTransform(baseFromSensor());
  mount.header.frame_id = settings.base_frame;
  mount.child_frame_id = settings.sensor_frame;
  std::size_t range_images = 0;
  ros::Time first_range_image_stamp;
  ros::Subscriber range_image_subscriber;
  if (settings.mount_after_scans > 0) {
    range_image_subscriber = node.subscribe<LidarRangeImage>(
        "/range_image", 100, [&](const LidarRangeImage::ConstPtr& image) {
          if (range_images == 0) first_range_image_stamp = image->header.stamp;
          if (++range_images == std::size_t(settings.mount_after_scans)) {
            static_broadcaster.sendTransform(mount);
            std::cout << "mount on tf after " << range_images << " range images\n";
          }
        });
  } else {
    static_broadcaster.sendTransform(mount);
  }

  std::vector<nav_msgs::Odometry::ConstPtr> odometry;
  nav_msgs::Path::ConstPtr path;
  ros::Subscriber odometry_subscriber = node.subscribe<nav_msgs::Odometry>(
      "/odometry", 100, [&](const nav_msgs::Odometry::ConstPtr& message) { odometry.push_back(message); });
  std::size_t deskewed_clouds = 0;
  sensor_msgs::PointCloud2::ConstPtr deskewed_cloud;
  ros::Subscriber cloud_subscriber = node.subscribe<sensor_msgs::PointCloud2>(
      "/deskewed_cloud", 4, [&](const sensor_msgs::PointCloud2::ConstPtr& message) {
        ++deskewed_clouds;
        deskewed_cloud = message;
      });
  ros::Subscriber path_subscriber =
      node.subscribe<nav_msgs::Path>("/path", 4, [&](const nav_msgs::Path::ConstPtr& message) { path = message; });
  // The Odometry's diagnostics: scans with every coarse level passed over,
  // and the WARN summaries.
  int odometry_statuses = 0, starved_scans = 0;
  std::vector<std::string> warnings;
  ros::Subscriber diagnostics_subscriber = node.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 100, [&](const diagnostic_msgs::DiagnosticArray::ConstPtr& array) {
        for (const diagnostic_msgs::DiagnosticStatus& status : array->status) {
          if (status.name != "odometry: odometry") continue;
          ++odometry_statuses;
          if (status.level == diagnostic_msgs::DiagnosticStatus::WARN) warnings.push_back(status.message);
          for (const diagnostic_msgs::KeyValue& value : status.values)
            if (value.key == "every coarse level passed over (scans)") starved_scans += std::stoi(value.value);
        }
      });

  // Until the replay is over: enough messages, then none for 3 s.
  std::size_t seen = 0;
  ros::WallTime last_change = ros::WallTime::now();
  spinUntil(
      [&] {
        if (odometry.size() != seen) {
          seen = odometry.size();
          last_change = ros::WallTime::now();
        }
        return int(seen) >= settings.min_frames && (ros::WallTime::now() - last_change).toSec() > 3.0;
      },
      settings.timeout_s);
  ASSERT_GE(int(odometry.size()), settings.min_frames) << "odometry messages within " << settings.timeout_s << " s";
  if (settings.mount_after_scans > 0) {
    EXPECT_GE(range_images, std::size_t(settings.mount_after_scans)) << "the mount was never sent";
    // The scans that waited for the mount are posed too: the first message is
    // the first scan's, not the first after the mount.
    EXPECT_EQ(odometry.front()->header.stamp, first_range_image_stamp);
  }

  // A starved pyramid is said in diagnostics; a normal run has none.
  EXPECT_GT(odometry_statuses, 0) << "no odometry diagnostics";
  std::cout << odometry_statuses << " odometry diagnostics, " << warnings.size() << " WARN (first: "
            << (warnings.empty() ? std::string("none") : warnings.front()) << "); " << starved_scans
            << " scans with every coarse level passed over\n";
  if (settings.expect_coarse_warning.empty()) {
    EXPECT_EQ(starved_scans, 0);
  } else {
    EXPECT_GE(starved_scans, settings.min_frames / 2) << "scans with every coarse level passed over";
    EXPECT_TRUE(std::any_of(warnings.begin(), warnings.end(), [&](const std::string& warning) {
      return warning.find(settings.expect_coarse_warning) != std::string::npos;
    })) << "no WARN naming " << settings.expect_coarse_warning << " among " << warnings.size() << " warnings";
  }

  // Every message: frames, finite pose, finite symmetric covariance.
  for (const auto& message : odometry) {
    EXPECT_EQ(message->header.frame_id, settings.odom_frame);
    EXPECT_EQ(message->child_frame_id, settings.base_frame);
    const Eigen::Isometry3d pose = [&] {
      Eigen::Isometry3d p;
      tf2::fromMsg(message->pose.pose, p);
      return p;
    }();
    ASSERT_TRUE(pose.matrix().allFinite());
    for (int r = 0; r < 6; ++r) {
      EXPECT_GT(message->pose.covariance[r * 6 + r], 0.0);
      for (int c = 0; c < 6; ++c) {
        ASSERT_TRUE(std::isfinite(message->pose.covariance[r * 6 + c]));
        ASSERT_TRUE(std::isfinite(message->twist.covariance[r * 6 + c]));
        EXPECT_NEAR(message->pose.covariance[r * 6 + c], message->pose.covariance[c * 6 + r], 1e-9);
      }
    }
    EXPECT_TRUE(std::isfinite(message->twist.twist.linear.x) && std::isfinite(message->twist.twist.angular.z));
  }

  // tf: odom -> base_link (or its inverse) at each stamp equals the message;
  // base_link -> lidar is the mount and the Adapter's sensor -> lidar.
  ASSERT_TRUE(tf_buffer.canTransform(settings.base_frame, settings.lidar_frame, ros::Time(0)));
  const Eigen::Isometry3d base_from_lidar =
      tf2::transformToEigen(tf_buffer.lookupTransform(settings.base_frame, settings.lidar_frame, ros::Time(0)));
  const std::string& parent = settings.invert_tf ? settings.base_frame : settings.odom_frame;
  const std::string& child = settings.invert_tf ? settings.odom_frame : settings.base_frame;
  std::size_t checked_on_tf = 0;
  for (const auto& message : odometry) {
    std::string error;
    if (!tf_buffer.canTransform(parent, child, message->header.stamp, &error)) continue;
    Eigen::Isometry3d on_tf = tf2::transformToEigen(tf_buffer.lookupTransform(parent, child, message->header.stamp));
    if (settings.invert_tf) on_tf = on_tf.inverse();
    Eigen::Isometry3d pose;
    tf2::fromMsg(message->pose.pose, pose);
    EXPECT_LT((on_tf.matrix() - pose.matrix()).cwiseAbs().maxCoeff(), 1e-6);
    ++checked_on_tf;
  }
  EXPECT_GE(checked_on_tf, odometry.size() - 1) << "odometry stamps with a " << parent << " -> " << child
                                                << " transform on tf";
  // The chain through the odometry: the lidar in the odom frame.
  EXPECT_TRUE(tf_buffer.canTransform(settings.odom_frame, settings.lidar_frame, odometry.back()->header.stamp));

  // The deskewed scans: in the lidar frame, most of the 128 x 1024 pixels.
  EXPECT_GE(deskewed_clouds, odometry.size() / 2);
  ASSERT_TRUE(deskewed_cloud);
  EXPECT_EQ(deskewed_cloud->header.frame_id, settings.lidar_frame);
  EXPECT_GT(std::size_t(deskewed_cloud->width) * deskewed_cloud->height, 10000u);

  ASSERT_TRUE(path);
  EXPECT_EQ(path->header.frame_id, settings.odom_frame);
  EXPECT_GE(path->poses.size(), odometry.size() / 2);

  // Accuracy: lidar poses from the odometry (T_odom_base T_base_lidar) against
  // the simulator's T_world_lidar, associated by time.
  evaluation::StampedTrajectory estimate;
  for (const auto& message : odometry) {
    Eigen::Isometry3d odom_from_base;
    tf2::fromMsg(message->pose.pose, odom_from_base);
    estimate.times_s.push_back(message->header.stamp.toSec());
    estimate.poses.push_back(odom_from_base * base_from_lidar);
  }
  const evaluation::StampedTrajectory ground_truth =
      evaluation::readTrajectory(settings.ground_truth_file, evaluation::PoseFileFormat::kTum);
  ASSERT_FALSE(ground_truth.poses.empty());
  const double epoch_s = bagEpochSeconds(settings.bag_file, ground_truth.times_s.front());
  for (double& time : estimate.times_s) time -= epoch_s;
  // Packet stamps are the receive time of each revolution's first packet, on
  // a /clock that ticks at 100 Hz: within a few ms of its first column. Cloud
  // stamps are the scan time itself.
  const evaluation::AssociatedPoses associated =
      evaluation::associateByTimestamp(estimate, ground_truth, 0.03);
  EXPECT_GE(int(associated.estimate.size()), settings.min_frames);
  const evaluation::TrajectoryEvaluation result =
      evaluation::evaluateTrajectory(associated.estimate, associated.ground_truth);
  // Umeyama aligns positions only: on a nearly straight path it leaves the
  // rotation about the path free, so orientations are checked from the first
  // pose instead (the odometry starts there by definition).
  std::vector<Eigen::Isometry3d> anchored;
  const Eigen::Isometry3d anchor = associated.ground_truth.front() * associated.estimate.front().inverse();
  for (const Eigen::Isometry3d& pose : associated.estimate) anchored.push_back(anchor * pose);
  evaluation::TrajectoryEvaluationOptions unaligned;
  unaligned.alignment = evaluation::Alignment::kNone;
  const evaluation::TrajectoryEvaluation from_start =
      evaluation::evaluateTrajectory(anchored, associated.ground_truth, unaligned);
  std::cout << "odometry over " << associated.estimate.size() << " of " << ground_truth.poses.size()
            << " frames, " << result.ground_truth_length_m << " m: ATE rmse "
            << result.absolute_translation_m.rmse << " m (max " << result.absolute_translation_m.maximum
            << " m); from the first pose: translation rmse " << from_start.absolute_translation_m.rmse
            << " m (max " << from_start.absolute_translation_m.maximum << " m), rotation rmse "
            << from_start.absolute_rotation_deg.rmse << " deg (max " << from_start.absolute_rotation_deg.maximum
            << " deg); frame to frame " << result.frame_to_frame.translation_m.rmse << " m, "
            << result.frame_to_frame.rotation_deg.rmse << " deg rmse\n";
  EXPECT_LE(result.absolute_translation_m.rmse, settings.max_ate_m);

  // Twist: the message's (base_link in base_link) against the ground truth's
  // velocity of base_link, the central difference of its poses around the
  // scan (T_world_lidar T_lidar_base). The lidar's own twist reported as the
  // base's (no frame change: the 180 deg yaw of os_sensor -> os_lidar and the
  // off-centre mount) must be far worse, so the check can tell them apart.
  double linear_error2 = 0.0, angular_error2 = 0.0, unchanged_linear_error2 = 0.0;
  int twists = 0;
  for (std::size_t k = 2; k < odometry.size(); ++k) {  // the first scans' velocity is not measured yet
    const double time_s = odometry[k]->header.stamp.toSec() - epoch_s;
    const auto after = std::lower_bound(ground_truth.times_s.begin(), ground_truth.times_s.end(), time_s);
    std::size_t i = std::size_t(after - ground_truth.times_s.begin());
    if (i > 0 && (i == ground_truth.times_s.size() ||
                  time_s - ground_truth.times_s[i - 1] < ground_truth.times_s[i] - time_s))
      --i;
    if (i == 0 || i + 1 >= ground_truth.times_s.size() || std::abs(ground_truth.times_s[i] - time_s) > 0.03) continue;
    const Eigen::Isometry3d lidar_from_base = base_from_lidar.inverse();
    const Twist truth = twistBetween(ground_truth.poses[i - 1] * lidar_from_base,
                                     ground_truth.poses[i + 1] * lidar_from_base,
                                     ground_truth.times_s[i + 1] - ground_truth.times_s[i - 1]);
    const Twist estimate = fromTwistMessage(odometry[k]->twist.twist);
    const Twist lidar_estimate = twistInFrame(lidar_from_base, estimate);
    angular_error2 += (estimate.head<3>() - truth.head<3>()).squaredNorm();
    linear_error2 += (estimate.tail<3>() - truth.tail<3>()).squaredNorm();
    unchanged_linear_error2 += (lidar_estimate.tail<3>() - truth.tail<3>()).squaredNorm();
    ++twists;
  }
  ASSERT_GE(twists, settings.min_frames / 2) << "odometry messages with ground truth on both sides";
  const double linear_rms = std::sqrt(linear_error2 / twists), angular_rms = std::sqrt(angular_error2 / twists);
  const double unchanged_linear_rms = std::sqrt(unchanged_linear_error2 / twists);
  std::cout << "twist of " << settings.base_frame << " over " << twists << " scans: rms error " << linear_rms
            << " m/s, " << angular_rms << " rad/s (the lidar's twist unchanged: " << unchanged_linear_rms
            << " m/s)\n";
  EXPECT_LE(linear_rms, settings.max_linear_velocity_error_mps);
  EXPECT_LE(angular_rms, settings.max_angular_velocity_error_radps);
  EXPECT_GT(unchanged_linear_rms, 3 * linear_rms);

  // The reset service answers (the next scan would start at the identity).
  std_srvs::Empty reset;
  EXPECT_TRUE(ros::service::waitForService("/odometry/reset", ros::Duration(5.0)));
  EXPECT_TRUE(ros::service::call("/odometry/reset", reset));
  EXPECT_LE(from_start.absolute_translation_m.maximum, 2 * settings.max_ate_m);
  EXPECT_LE(from_start.absolute_rotation_deg.maximum, settings.max_rotation_error_deg);
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  return range_image_mapping::test::runRostestNode(argc, argv, "odometry_simulated");
}
