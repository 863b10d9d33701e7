// rim run against the nodelets. One simulated indoor_cart sequence, written
// as a bag of packets and as a pcap of the same packets, goes through
// range_image_mapping.launch (slowly, so the Odometry takes every scan) and
// through `rim run` offline. They tell the same story (the core's
// ScanToMapPipeline) on the same scans, so the odometry poses, associated by
// scan time, must be the same to the last digits the pose files keep (1e-9 m,
// 1e-9 rad: the registration's sums are deterministic), and the meshes, both
// in the sensor frame at the first scan and deskewed with the odometry's twist
// (the Mapper takes it from the odometry messages), must be the same mesh:
// the same vertex count, and F = 1 at one voxel.
//
// Scan time, not the header stamp: the stamp is the receipt time of the
// scan's first packet, late by however long the Adapter waited for a core
// (tens of milliseconds of bag time under load), while rim run's times are the
// scan times of the core. The test reads the scan time of each stamp from the
// range images themselves (scanTime of the image, as the Odometry computes it).
#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/SaveMesh.h"
#include "range_image_mapping/evaluation/surface_metrics.h"
#include "range_image_mapping/evaluation/trajectory_metrics.h"
#include "range_image_mapping/io/mesh_file.h"
#include "range_image_mapping/ros/range_image_conversions.h"
#include "range_image_mapping/scan_motion.h"

#include "rostest_main.h"
#include "spin_until.h"

#include <gtest/gtest.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <map>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

using test::spinUntil;
namespace fs = std::filesystem;

// The bag's time origin, where the simulator's clock starts: rim simulate
// writes the latched metadata at it, and the pcap's column times count from it.
double bagEpochSeconds(const std::string& bag_file) {
  rosbag::Bag bag(bag_file, rosbag::bagmode::Read);
  for (const rosbag::MessageInstance& message : rosbag::View(bag))
    if (message.getTopic() == "/ouster/metadata") return message.getTime().toSec();
  throw std::runtime_error(bag_file + " has no /ouster/metadata");
}

// rim is built next to this test node (the package's devel or install lib folder).
std::string rimBinary() {
  return (fs::read_symlink("/proc/self/exe").parent_path() / "rim").string();
}

double rotationRadians(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle();
}

TEST(RunMatchesNodelets, SamePosesAsRimRunOnTheSameSequence) {
  ros::NodeHandle private_node("~");
  const std::string sequence_dir = private_node.param<std::string>("sequence_dir", "");
  const int frames = private_node.param("frames", 30);
  const double timeout_s = private_node.param("timeout", 90.0);
  const double max_position_m = private_node.param("max_position_difference", 1e-9);
  const double max_rotation_rad = private_node.param("max_rotation_difference", 1e-9);
  const std::string bag_file = sequence_dir + "/packets.bag";
  ASSERT_TRUE(fs::exists(bag_file)) << bag_file;
  ASSERT_TRUE(fs::exists(sequence_dir + "/capture.pcap")) << sequence_dir;
  const std::string rim = rimBinary();
  ASSERT_TRUE(fs::exists(rim)) << rim;

  ros::NodeHandle node;
  tf2_ros::Buffer tf_buffer(ros::Duration(120.0));
  tf2_ros::TransformListener tf_listener(tf_buffer);
  std::vector<nav_msgs::Odometry::ConstPtr> odometry;
  ros::Subscriber subscriber = node.subscribe<nav_msgs::Odometry>(
      "/odometry", 1000, [&](const nav_msgs::Odometry::ConstPtr& message) { odometry.push_back(message); });
  LidarModelCache models;
  std::map<ros::Time, double> scan_time_s;  // by header stamp
  ros::Subscriber image_subscriber = node.subscribe<LidarRangeImage>(
      "/range_image", 100, [&](const LidarRangeImage::ConstPtr& message) {
        RangeImage image = fromMessage(*message, models);
        scan_time_s[message->header.stamp] = double(scanTime(image, ScanTimeSource::kFirstValidColumn)) * 1e-9;
      });

  // Until the replay is over: every scan, or no odometry for 5 s after enough.
  ros::WallTime last_message = ros::WallTime::now();
  std::size_t seen = 0;
  spinUntil(
      [&] {
        if (odometry.size() != seen) seen = odometry.size(), last_message = ros::WallTime::now();
        return int(seen) >= frames ||
               (int(seen) >= frames - 3 && (ros::WallTime::now() - last_message).toSec() > 5.0);
      },
      timeout_s);
  ASSERT_GE(int(odometry.size()), frames - 3) << "odometry messages within " << timeout_s << " s";
  spinUntil([] { return false; }, 1.0);  // the Mapper integrates the last scan
  SaveMesh save;
  save.request.path = sequence_dir + "/nodelet_mesh.ply";
  ASSERT_TRUE(ros::service::call("/mapper/save_mesh", save));
  ASSERT_TRUE(save.response.success) << save.response.message;

  // The same sequence offline, after the replay so both had the machine to themselves.
  const std::string run_dir = sequence_dir + "/run";
  const std::string command = "'" + rim + "' run '" + sequence_dir + "' --out '" + run_dir +
                              "' --environment indoor --no-plot > '" + sequence_dir + "/run.log' 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0) << command << " failed, see " << sequence_dir << "/run.log";
  const evaluation::StampedTrajectory offline =
      evaluation::readTrajectory(run_dir + "/trajectory_tum.txt", evaluation::PoseFileFormat::kTum);
  ASSERT_TRUE(offline.hasTimes());

  // The nodelets' poses are of base_frame (os_sensor) in odom, both the
  // lidar's own frame at the first scan; rim run's of the lidar frame.
  const std::string base_frame = odometry.front()->child_frame_id, lidar_frame = "os_lidar";
  ASSERT_TRUE(tf_buffer.canTransform(base_frame, lidar_frame, ros::Time(0)));
  const Eigen::Isometry3d base_from_lidar =
      tf2::transformToEigen(tf_buffer.lookupTransform(base_frame, lidar_frame, ros::Time(0)));
  const double epoch_s = bagEpochSeconds(bag_file);
  evaluation::StampedTrajectory online;
  double worst_lag_s = 0.0;  // receipt stamp after the scan time, in bag time
  for (const nav_msgs::Odometry::ConstPtr& message : odometry) {
    const auto scan_time = scan_time_s.find(message->header.stamp);
    ASSERT_NE(scan_time, scan_time_s.end()) << "no range image stamped " << message->header.stamp;
    worst_lag_s = std::max(worst_lag_s, message->header.stamp.toSec() - epoch_s - scan_time->second);
    Eigen::Isometry3d odom_from_base;
    tf2::fromMsg(message->pose.pose, odom_from_base);
    online.times_s.push_back(scan_time->second);
    online.poses.push_back(base_from_lidar.inverse() * odom_from_base * base_from_lidar);
  }
  // The same scan has the same scan time, to the nanosecond of the column times.
  const evaluation::AssociatedPoses pairs = evaluation::associateByTimestamp(online, offline, 1e-6);
  ASSERT_GE(int(pairs.estimate.size()), frames - 3) << "poses of the same scans";
  EXPECT_EQ(pairs.estimate_index.front(), 0u);
  EXPECT_EQ(pairs.ground_truth_index.front(), 0u) << "the nodelets missed the first scan: another odom origin";
  double worst_position_m = 0.0, worst_rotation_rad = 0.0, sum_position_m = 0.0;
  for (std::size_t i = 0; i < pairs.estimate.size(); ++i) {
    const double position_m = (pairs.estimate[i].translation() - pairs.ground_truth[i].translation()).norm();
    worst_position_m = std::max(worst_position_m, position_m);
    sum_position_m += position_m;
    worst_rotation_rad = std::max(worst_rotation_rad, rotationRadians(pairs.estimate[i], pairs.ground_truth[i]));
  }
  const double travelled_m = pairs.ground_truth.back().translation().norm();
  std::cout << odometry.size() << " odometry messages, " << offline.poses.size() << " rim run poses, "
            << pairs.estimate.size() << " associated; position difference mean "
            << sum_position_m / double(pairs.estimate.size()) << " m, worst " << worst_position_m
            << " m; rotation worst " << worst_rotation_rad << " rad; over " << travelled_m
            << " m; header stamps up to " << worst_lag_s << " s after the scan time\n";
  EXPECT_LE(worst_position_m, max_position_m);
  EXPECT_LE(worst_rotation_rad, max_rotation_rad);

  // The meshes, both in the sensor frame at the first scan: the same mesh.
  const double voxel_m = 0.04;  // indoor, both
  const TriangleMesh nodelet_mesh = io::loadMeshFile(save.request.path);
  const TriangleMesh run_mesh = io::loadMeshFile(run_dir + "/mesh.ply");
  EXPECT_EQ(nodelet_mesh.vertices.size(), run_mesh.vertices.size());
  EXPECT_EQ(nodelet_mesh.triangles.size(), run_mesh.triangles.size());
  evaluation::SurfaceSamplingOptions sampling;
  sampling.spacing_m = 0.25 * voxel_m;
  const evaluation::SurfaceMetrics mesh =
      evaluation::compareSurfaces(evaluation::loadSurfaceSample(save.request.path, sampling).points,
                                  evaluation::loadSurfaceSample(run_dir + "/mesh.ply", sampling).points, voxel_m);
  std::cout << "Mapper mesh (" << save.response.message << ", " << nodelet_mesh.vertices.size()
            << " vertices) against rim run's (" << run_mesh.vertices.size() << ") at " << voxel_m
            << " m: precision " << mesh.precision << ", recall " << mesh.recall << ", F-score " << mesh.f_score
            << ", Chamfer " << mesh.chamfer_m << " m\n";
  EXPECT_EQ(mesh.f_score, 1.0);
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  return range_image_mapping::test::runRostestNode(argc, argv, "run_matches_nodelets");
}
