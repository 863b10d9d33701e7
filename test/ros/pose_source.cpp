// PoseSource without a running Mapper: poses from tf (a static transform the
// test broadcasts) and from odometry messages (composed with base -> lidar
// from tf, the twist moved from the base to the lidar), and the reasons a
// scan gets no pose.
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
  parameters.tf_timeout_s = 30.0;
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
  parameters.tf_timeout_s = 0.2;
  parameters.queue_size = 2;
  Answers answers;
  PoseSource source(node, parameters, "pose_source_test", answers.callback());
  for (const char* frame : {"nowhere_1", "nowhere_2", "nowhere_3"}) source.addScan(scanIn(frame, 10.0));
  // The third scan pushed the first out of the full queue, in arrival order.
  ASSERT_EQ(answers.lookups.size(), 1u);
  EXPECT_EQ(answers.frames[0], "nowhere_1");
  EXPECT_EQ(answers.lookups[0].reason, "the queue of scans waiting for tf is full");
  ASSERT_TRUE(spinUntil([&] { return answers.lookups.size() == 3; }, 10.0));
  EXPECT_EQ(answers.frames[1], "nowhere_2");
  EXPECT_FALSE(answers.lookups[1].pose);
  EXPECT_NE(answers.lookups[1].reason.find("no transform tf_world -> nowhere_2 within 0.2"), std::string::npos)
      << answers.lookups[1].reason;
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
  odometry.child_frame_id = "odometry_base";
  const Eigen::Isometry3d world_from_base = pose({5.0, -1.0, 0.0}, 1.2, 0.0);
  odometry.pose.pose = tf2::toMsg(world_from_base);
  Twist base_twist;
  base_twist << 0.01, -0.02, 0.3, 1.0, 0.1, 0.0;
  odometry.twist.twist = toTwistMessage(base_twist);
  // Answered at once: waiting for the mount until the listener has it.
  ASSERT_TRUE(spinUntil(
      [&] {
        source.addScan(scanIn("odometry_lidar", 10.0), odometry);
        return answers.lookups.back().pose.has_value();
      },
      20.0))
      << answers.lookups.back().reason;
  EXPECT_EQ(answers.lookups.front().reason, "waiting for tf odometry_base -> odometry_lidar");
  const LidarPose& lidar = *answers.lookups.back().pose;
  EXPECT_TRUE(lidar.world_from_lidar.isApprox(world_from_base * base_from_lidar, 1e-9));
  ASSERT_TRUE(lidar.twist);
  // The lidar's twist, carried back through the mount, is the message's; and
  // it is the motion the base's twist gives the lidar over a short time.
  EXPECT_LT((twistInFrame(base_from_lidar, *lidar.twist) - base_twist).norm(), 1e-9);
  const double dt = 1e-3;
  const Eigen::Isometry3d lidar_later = world_from_base * twistExponential(dt * base_twist) * base_from_lidar;
  EXPECT_LT((twistBetween(lidar.world_from_lidar, lidar_later, dt) - *lidar.twist).norm(), 1e-6);

  // An odometry in another frame than world_frame gives no pose.
  odometry.header.frame_id = "map";
  source.addScan(scanIn("odometry_lidar", 11.0), odometry);
  EXPECT_FALSE(answers.lookups.back().pose);
  EXPECT_EQ(answers.lookups.back().reason, "the odometry is in frame 'map', world_frame is 'odom'");
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  return range_image_mapping::test::runRostestNode(argc, argv, "pose_source");
}
