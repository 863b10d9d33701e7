// PoseSource without a running Mapper: poses from tf (a static transform the
// test broadcasts) and from odometry messages (composed with base -> lidar
// from tf, the twist moved from the base to the lidar), scans waiting for
// odometry that comes late, and the reasons a scan gets no pose.
#include "range_image_mapping/ros/pose_source.h"

#include "range_image_mapping/ros/range_image_conversions.h"
#include "range_image_mapping/scan_motion.h"
#include "rostest_main.h"
#include "spin_until.h"

#include <geometry_msgs/TransformStamped.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/static_transform_broadcaster.h>

#include <boost/make_shared.hpp>

#include <Eigen/Geometry>

#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

using test::spinUntil;

Eigen::Isometry3d pose(const Eigen::Vector3d& translation, double yaw, double roll) {
  Eigen::Isometry3d result = Eigen::Isometry3d::Identity();
  result.translate(translation);
  result.rotate(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()));
  return result;
}

void broadcast(tf2_ros::StaticTransformBroadcaster& broadcaster, const std::string& parent, const std::string& child,
               const Eigen::Isometry3d& parent_from_child) {
  geometry_msgs::TransformStamped transform = tf2::eigenToTransform(parent_from_child);
  transform.header.frame_id = parent;
  transform.child_frame_id = child;
  broadcaster.sendTransform(transform);
}

LidarRangeImage::ConstPtr scanIn(const std::string& frame, double stamp_s) {
  const auto scan = boost::make_shared<LidarRangeImage>();
  scan->header.frame_id = frame;
  scan->header.stamp = ros::Time(stamp_s);
  return scan;
}

// Timeouts long enough for the listener to hear the test's transforms.
MapperParameters parametersFor(PoseSourceType type, const std::string& world_frame) {
  MapperParameters parameters;
  parameters.pose_source = type;
  parameters.world_frame = world_frame;
  parameters.pose_timeout_s = 30.0;
  parameters.lidar_transform_timeout_s = 30.0;
  return parameters;
}

struct Answers {
  std::vector<PoseLookup> lookups;
  std::vector<std::string> frames;
  PoseSource::Answer callback() {
    return [this](const LidarRangeImage& scan, const PoseLookup& lookup) {
      lookups.push_back(lookup);
      frames.push_back(scan.header.frame_id);
    };
  }
};

TEST(PoseSource, FromTfOnceItHasTheTransform) {
  ros::NodeHandle node;
  tf2_ros::StaticTransformBroadcaster broadcaster;
  const Eigen::Isometry3d world_from_lidar = pose({1.0, 2.0, 0.5}, 0.4, 0.1);
  broadcast(broadcaster, "tf_world", "tf_lidar", world_from_lidar);
  const MapperParameters parameters = parametersFor(PoseSourceType::kTf, "tf_world");
  Answers answers;
  PoseSource source(node, parameters, "pose_source_test", answers.callback());
  source.addScan(scanIn("tf_lidar", 10.0));
  ASSERT_TRUE(spinUntil([&] { return !answers.lookups.empty(); }, 20.0));  // retried by its timer
  ASSERT_TRUE(answers.lookups[0].pose) << answers.lookups[0].reason;
  EXPECT_TRUE(answers.lookups[0].pose->world_from_lidar.isApprox(world_from_lidar, 1e-9));
  EXPECT_FALSE(answers.lookups[0].pose->twist);  // tf carries poses only
}

TEST(PoseSource, FromTfReasonsForNoPose) {
  ros::NodeHandle node;
  MapperParameters parameters = parametersFor(PoseSourceType::kTf, "tf_world");
  parameters.pose_timeout_s = 0.2;
  parameters.queue_size = 2;
  Answers answers;
  PoseSource source(node, parameters, "pose_source_test", answers.callback());
  for (const char* frame : {"nowhere_1", "nowhere_2", "nowhere_3"}) source.addScan(scanIn(frame, 10.0));
  // The third scan pushed the first out of the full queue, in arrival order.
  ASSERT_EQ(answers.lookups.size(), 1u);
  EXPECT_EQ(answers.frames[0], "nowhere_1");
  EXPECT_EQ(answers.lookups[0].reason, "the queue of 2 scans waiting for their pose is full (queue_size)");
  EXPECT_EQ(answers.lookups[0].no_pose, NoPoseReason::kQueueFull);
  ASSERT_TRUE(spinUntil([&] { return answers.lookups.size() == 3; }, 10.0));
  EXPECT_EQ(answers.frames[1], "nowhere_2");
  EXPECT_FALSE(answers.lookups[1].pose);
  EXPECT_NE(answers.lookups[1].reason.find("no transform tf_world -> nowhere_2 within 0.2"), std::string::npos)
      << answers.lookups[1].reason;
  EXPECT_EQ(answers.lookups[1].no_pose, NoPoseReason::kTimedOut);
  EXPECT_GE(answers.lookups[1].waited_s, 0.2);
}

TEST(PoseSource, FromOdometryThroughTheMount) {
  ros::NodeHandle node;
  tf2_ros::StaticTransformBroadcaster broadcaster;
  const Eigen::Isometry3d base_from_lidar = pose({0.3, -0.1, 0.8}, 0.2 + M_PI, 0.05);
  broadcast(broadcaster, "odometry_base", "odometry_lidar", base_from_lidar);
  const MapperParameters parameters = parametersFor(PoseSourceType::kOdometry, "odom");
  Answers answers;
  PoseSource source(node, parameters, "pose_source_test", answers.callback());

  nav_msgs::Odometry odometry;
  odometry.header.frame_id = "odom";
  odometry.header.stamp = ros::Time(10.0);
  odometry.child_frame_id = "odometry_base";
  const Eigen::Isometry3d world_from_base = pose({5.0, -1.0, 0.0}, 1.2, 0.0);
  odometry.pose.pose = tf2::toMsg(world_from_base);
  Twist base_twist;
  base_twist << 0.01, -0.02, 0.3, 1.0, 0.1, 0.0;
  odometry.twist.twist = toTwistMessage(base_twist);
  // The scan first, its odometry later: it waits (also for the mount, until
  // the listener has it).
  source.addScan(scanIn("odometry_lidar", 10.0));
  EXPECT_TRUE(answers.lookups.empty());
  EXPECT_EQ(source.waitingCount(), 1u);
  source.addOdometry(boost::make_shared<nav_msgs::Odometry>(odometry));
  ASSERT_TRUE(spinUntil([&] { return !answers.lookups.empty(); }, 20.0));
  ASSERT_EQ(answers.lookups.size(), 1u);
  ASSERT_TRUE(answers.lookups[0].pose) << answers.lookups[0].reason;
  const LidarPose& lidar = *answers.lookups.back().pose;
  EXPECT_TRUE(lidar.world_from_lidar.isApprox(world_from_base * base_from_lidar, 1e-9));
  ASSERT_TRUE(lidar.twist);
  // The lidar's twist, carried back through the mount, is the message's; and
  // it is the motion the base's twist gives the lidar over a short time.
  EXPECT_LT((twistInFrame(base_from_lidar, *lidar.twist) - base_twist).norm(), 1e-9);
  const double dt = 1e-3;
  const Eigen::Isometry3d lidar_later = world_from_base * twistExponential(dt * base_twist) * base_from_lidar;
  EXPECT_LT((twistBetween(lidar.world_from_lidar, lidar_later, dt) - *lidar.twist).norm(), 1e-6);

  // The odometry first (the Odometry's static_range_image comes after its
  // message): answered at once. In another frame than world_frame: no pose.
  odometry.header.frame_id = "map";
  odometry.header.stamp = ros::Time(11.0);
  source.addOdometry(boost::make_shared<nav_msgs::Odometry>(odometry));
  source.addScan(scanIn("odometry_lidar", 11.0));
  ASSERT_EQ(answers.lookups.size(), 2u);
  EXPECT_FALSE(answers.lookups.back().pose);
  EXPECT_EQ(answers.lookups.back().reason, "the odometry is in frame 'map', world_frame is 'odom'");
  EXPECT_EQ(answers.lookups.back().no_pose, NoPoseReason::kUnusable);
}

TEST(PoseSource, FromOdometryInOrderSkippedAndTimedOut) {
  ros::NodeHandle node;
  MapperParameters parameters = parametersFor(PoseSourceType::kOdometry, "odom");
  parameters.pose_timeout_s = 0.3;
  parameters.queue_size = 3;
  Answers answers;
  PoseSource source(node, parameters, "pose_source_test", answers.callback());
  const auto odometryAt = [](double stamp_s) {
    const auto odometry = boost::make_shared<nav_msgs::Odometry>();
    odometry->header.frame_id = "odom";
    odometry->header.stamp = ros::Time(stamp_s);
    odometry->child_frame_id = "same_frame";  // base = lidar: no tf needed
    odometry->pose.pose.orientation.w = 1.0;
    return odometry;
  };
  // Three scans waiting; the odometry of the second and third arrives late
  // (under load), none for the first: the Odometry skipped it.
  for (const double stamp : {1.0, 1.1, 1.2}) source.addScan(scanIn("same_frame", stamp));
  EXPECT_EQ(source.waitingCount(), 3u);
  source.addOdometry(odometryAt(1.1));
  source.addOdometry(odometryAt(1.2));
  ASSERT_EQ(answers.lookups.size(), 3u);
  EXPECT_EQ(answers.lookups[0].no_pose, NoPoseReason::kSkipped) << answers.lookups[0].reason;
  EXPECT_TRUE(answers.lookups[1].pose) << answers.lookups[1].reason;
  EXPECT_TRUE(answers.lookups[2].pose) << answers.lookups[2].reason;
  // A full queue gives up its oldest scan at once, named.
  for (const double stamp : {2.0, 2.1, 2.2, 2.3}) source.addScan(scanIn("same_frame", stamp));
  ASSERT_EQ(answers.lookups.size(), 4u);
  EXPECT_EQ(answers.lookups[3].no_pose, NoPoseReason::kQueueFull);
  // The rest time out, one after the other, each with the reason.
  ASSERT_TRUE(spinUntil([&] { return answers.lookups.size() == 7; }, 10.0));
  for (std::size_t i = 4; i < 7; ++i) {
    EXPECT_EQ(answers.lookups[i].no_pose, NoPoseReason::kTimedOut);
    EXPECT_NE(answers.lookups[i].reason.find("no odometry with the same stamp within 0.3"), std::string::npos)
        << answers.lookups[i].reason;
  }
  EXPECT_EQ(source.waitingCount(), 0u);
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  return range_image_mapping::test::runRostestNode(argc, argv, "pose_source");
}
