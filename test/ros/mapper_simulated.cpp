// A simulated Ouster sequence (rim simulate, raw packets in a bag) replayed
// through mapping.launch: the Mapper's mesh markers must arrive as valid
// triangle lists, later updates must re-send only the chunks that changed,
// save_mesh must write a PLY that matches the simulator's ground-truth surface
// (F-score after moving it from odom to the simulator's world with the first
// ground-truth pose), a late subscriber must get the whole mesh, and reset must
// empty the map. write_odometry_bag.sh writes the sequence while roslaunch
// loads the test.
#include "range_image_mapping/SaveMesh.h"
#include "range_image_mapping/evaluation/surface_metrics.h"
#include "range_image_mapping/evaluation/trajectory_metrics.h"

#include "rostest_main.h"
#include "spin_until.h"

#include <gtest/gtest.h>
#include <nav_msgs/Odometry.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <std_srvs/Empty.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/MarkerArray.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <map>
#include <regex>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

using test::spinUntil;

struct Settings {
  std::string bag_file, sequence_dir;  // sequence_dir: rim simulate's folder, bag_file in it
  std::string world_frame, lidar_frame;
  std::string color_mode = "height";  // the Mapper's
  double timeout_s = 90.0;
  double voxel_m = 0.0;
  double min_f_score = 0.5;
  int min_frames = 25;
};

Settings readSettings() {
  ros::NodeHandle private_node("~");
  Settings settings;
  settings.bag_file = private_node.param<std::string>("bag_file", "");
  settings.sequence_dir = private_node.param<std::string>("sequence_dir", "");
  settings.world_frame = private_node.param<std::string>("world_frame", "odom");
  settings.lidar_frame = private_node.param<std::string>("lidar_frame", "os_lidar");
  settings.timeout_s = private_node.param("timeout", settings.timeout_s);
  // The Mapper's own voxel (from its config), for the paper's 3-voxel threshold.
  if (!ros::param::get("/mapper/voxel_size", settings.voxel_m))
    throw std::runtime_error("no /mapper/voxel_size on the parameter server");
  settings.min_f_score = private_node.param("min_f_score", settings.min_f_score);
  settings.min_frames = private_node.param("min_frames", settings.min_frames);
  ros::param::get("/mapper/color_mode", settings.color_mode);
  return settings;
}

// The bag's time origin, where the simulator's clock (the ground truth's
// times) starts: rim simulate writes the latched Ouster metadata at it.
double bagEpochSeconds(const std::string& bag_file) {
  rosbag::Bag bag(bag_file, rosbag::bagmode::Read);
  rosbag::View view(bag);
  for (const rosbag::MessageInstance& message : view)
    if (message.getTopic() == "/ouster/metadata") return message.getTime().toSec();
  throw std::runtime_error(bag_file + " has no /ouster/metadata");
}

// What a subscriber holds after each MarkerArray, as rviz applies them: per
// marker id, its triangle count. Also checks every marker as rviz would.
struct MeshSubscriber {
  std::map<int32_t, std::size_t> held;  // id -> triangles
  std::size_t messages = 0, delete_all = 0;
  std::size_t grey_colors = 0, colors = 0;  // r = g = b: intensity colours
  // Per message: markers added or replaced, markers held afterwards, DELETEALL in it.
  std::vector<std::size_t> added, held_after;
  std::vector<bool> full;
  std::string world_frame;
  ros::WallTime last_message;

  void apply(const visualization_msgs::MarkerArray& array) {
    ++messages;
    last_message = ros::WallTime::now();
    std::size_t adds = 0;
    bool has_delete_all = false;
    for (const visualization_msgs::Marker& marker : array.markers) {
      EXPECT_EQ(marker.header.frame_id, world_frame);
      if (marker.ns == "mesh_triangles") {  // the count of triangles shown, as text
        EXPECT_EQ(marker.type, visualization_msgs::Marker::TEXT_VIEW_FACING);
        EXPECT_NE(marker.text.find("triangles shown"), std::string::npos) << marker.text;
        continue;
      }
      EXPECT_EQ(marker.ns, "mesh");
      if (marker.action == visualization_msgs::Marker::DELETEALL) {
        held.clear();
        has_delete_all = true;
        ++delete_all;
      } else if (marker.action == visualization_msgs::Marker::DELETE) {
        EXPECT_EQ(held.erase(marker.id), 1u) << "DELETE of marker " << marker.id << " that was never added";
      } else {
        ASSERT_EQ(marker.action, visualization_msgs::Marker::ADD);
        ASSERT_EQ(marker.type, visualization_msgs::Marker::TRIANGLE_LIST);
        ASSERT_FALSE(marker.points.empty());
        ASSERT_EQ(marker.points.size() % 3, 0u);
        ASSERT_EQ(marker.colors.size(), marker.points.size());
        EXPECT_EQ(marker.color.a, 1.0f);
        EXPECT_EQ(marker.pose.orientation.w, 1.0);
        for (const geometry_msgs::Point& point : marker.points)
          ASSERT_TRUE(std::isfinite(point.x) && std::isfinite(point.y) && std::isfinite(point.z));
        for (const std_msgs::ColorRGBA& color : marker.colors) {
          ASSERT_TRUE(color.r >= 0.0f && color.r <= 1.0f && color.g >= 0.0f && color.g <= 1.0f &&
                      color.b >= 0.0f && color.b <= 1.0f);
          grey_colors += color.r == color.g && color.g == color.b;
        }
        colors += marker.colors.size();
        held[marker.id] = marker.points.size() / 3;
        ++adds;
      }
    }
    added.push_back(adds);
    held_after.push_back(held.size());
    full.push_back(has_delete_all);
  }

  std::size_t triangles() const {
    std::size_t total = 0;
    for (const auto& [id, count] : held) total += count;
    return total;
  }
};

SaveMesh::Response saveMesh(const std::string& path) {
  SaveMesh save;
  save.request.path = path;
  EXPECT_TRUE(ros::service::call("/mapper/save_mesh", save)) << "calling /mapper/save_mesh";
  return save.response;
}

TEST(MapperSimulated, MeshGrowsIncrementallyAndMatchesTheGroundTruth) {
  const Settings settings = readSettings();
  ASSERT_TRUE(std::filesystem::exists(settings.bag_file)) << settings.bag_file;
  ros::NodeHandle node;
  tf2_ros::Buffer tf_buffer(ros::Duration(120.0));
  tf2_ros::TransformListener tf_listener(tf_buffer);

  std::vector<nav_msgs::Odometry::ConstPtr> odometry;
  ros::Subscriber odometry_subscriber = node.subscribe<nav_msgs::Odometry>(
      "/odometry", 100, [&](const nav_msgs::Odometry::ConstPtr& message) { odometry.push_back(message); });
  MeshSubscriber early;
  early.world_frame = settings.world_frame;
  ros::Subscriber mesh_subscriber = node.subscribe<visualization_msgs::MarkerArray>(
      "/mesh", 100, [&](const visualization_msgs::MarkerArray::ConstPtr& message) { early.apply(*message); });

  // The Adapter's range image for rviz, published while someone listens.
  sensor_msgs::Image::ConstPtr display;
  ros::Subscriber display_subscriber = node.subscribe<sensor_msgs::Image>(
      "/range_image_display", 2, [&](const sensor_msgs::Image::ConstPtr& message) { display = message; });

  // Until the replay is over: enough odometry, a mesh, then no mesh change for
  // 4 s (the test runs the mesh timer at 2 Hz; a loaded Mapper defers updates,
  // so the first, empty message is no sign that meshing is done).
  spinUntil(
      [&] {
        return int(odometry.size()) >= settings.min_frames && early.triangles() > 0 &&
               (ros::WallTime::now() - early.last_message).toSec() > 4.0;
      },
      settings.timeout_s);
  ASSERT_GE(int(odometry.size()), settings.min_frames) << "odometry messages within " << settings.timeout_s << " s";
  ASSERT_GT(early.messages, 0u) << "no mesh on /mesh";
  std::cout << "mesh: " << early.messages << " messages, " << early.held.size() << " markers, "
            << early.triangles() << " triangles\n";
  EXPECT_GE(early.held.size(), 10u);
  EXPECT_GT(early.triangles(), 10000u);
  // The range image: destaggered 128 x 1024 millimetres, mostly returns.
  ASSERT_TRUE(display) << "nothing on /range_image_display";
  EXPECT_EQ(display->encoding, "mono16");
  EXPECT_EQ(display->height, 128u);
  EXPECT_EQ(display->width, 1024u);
  ASSERT_EQ(display->data.size(), std::size_t(display->step) * display->height);
  const auto* millimetres = reinterpret_cast<const uint16_t*>(display->data.data());
  const std::size_t returns = std::count_if(millimetres, millimetres + std::size_t(display->width) * display->height,
                                            [](uint16_t range) { return range > 0; });
  EXPECT_GT(returns, std::size_t(display->width) * display->height / 2);

  // Intensity is grey, height a colour ramp.
  if (settings.color_mode == "intensity")
    EXPECT_EQ(early.grey_colors, early.colors);
  else
    EXPECT_LT(early.grey_colors, early.colors / 100);

  // The mesh vertices as a cloud, sent at the mesh rate while someone listens.
  sensor_msgs::PointCloud2::ConstPtr surface_points;
  ros::Subscriber surface_subscriber = node.subscribe<sensor_msgs::PointCloud2>(
      "/surface_points", 1, [&](const sensor_msgs::PointCloud2::ConstPtr& message) { surface_points = message; });
  spinUntil([&] { return bool(surface_points); }, 15.0);
  ASSERT_TRUE(surface_points) << "nothing on /surface_points";
  EXPECT_EQ(surface_points->header.frame_id, settings.world_frame);
  EXPECT_GT(std::size_t(surface_points->width) * surface_points->height, early.triangles() / 4);
  const bool has_intensity =
      std::any_of(surface_points->fields.begin(), surface_points->fields.end(),
                  [](const sensor_msgs::PointField& field) { return field.name == "intensity"; });
  EXPECT_EQ(has_intensity, settings.color_mode == "intensity");
  surface_subscriber.shutdown();

  // Incremental: the first message is the full mesh sent to a new subscriber
  // (DELETEALL first; the map is still empty while the replay waits); once
  // the mesh grows, each update carries only the chunks that changed.
  ASSERT_TRUE(early.full.front());
  std::size_t incremental = 0, partial = 0;
  bool growing = false;
  for (std::size_t i = 0; i < early.messages; ++i) {
    if (growing) {
      EXPECT_FALSE(early.full[i]) << "message " << i << " re-sent everything without a new subscriber or a reset";
      ++incremental;
      if (early.added[i] < early.held_after[i]) ++partial;
    }
    growing = growing || early.added[i] > 0;
  }
  EXPECT_GE(incremental, 2u) << "the mesh grew in fewer than three updates";
  EXPECT_GE(partial, 1u) << "every update re-sent the whole mesh";

  // save_mesh refuses what it cannot write, with the reason.
  const SaveMesh::Response missing_folder = saveMesh("/nonexistent_rim_folder/mesh.ply");
  EXPECT_FALSE(missing_folder.success);
  EXPECT_NE(missing_folder.message.find("does not exist"), std::string::npos) << missing_folder.message;
  const SaveMesh::Response relative = saveMesh("mesh.ply");
  EXPECT_FALSE(relative.success);
  EXPECT_NE(relative.message.find("not an absolute path"), std::string::npos) << relative.message;

  // The saved mesh against the ground truth, moved from odom into the
  // simulator's world: odom is the base at the first odometry pose.
  const std::string mesh_path = settings.sequence_dir + "/mapper_mesh.ply";
  const SaveMesh::Response saved = saveMesh(mesh_path);
  ASSERT_TRUE(saved.success) << saved.message;
  // Every scan the odometry posed was integrated (the Mapper keeps up).
  std::smatch scans;
  ASSERT_TRUE(std::regex_search(saved.message, scans, std::regex("from ([0-9]+) scans"))) << saved.message;
  EXPECT_GE(std::stoul(scans[1]), odometry.size() - 1) << saved.message;
  ASSERT_TRUE(std::filesystem::exists(mesh_path));
  ASSERT_TRUE(tf_buffer.canTransform(odometry.front()->child_frame_id, settings.lidar_frame, ros::Time(0)));
  const Eigen::Isometry3d base_from_lidar = tf2::transformToEigen(
      tf_buffer.lookupTransform(odometry.front()->child_frame_id, settings.lidar_frame, ros::Time(0)));
  const evaluation::StampedTrajectory ground_truth = evaluation::readTrajectory(
      settings.sequence_dir + "/poses_tum.txt", evaluation::PoseFileFormat::kTum);
  evaluation::StampedTrajectory first;
  Eigen::Isometry3d odom_from_base;
  tf2::fromMsg(odometry.front()->pose.pose, odom_from_base);
  first.times_s.push_back(odometry.front()->header.stamp.toSec() - bagEpochSeconds(settings.bag_file));
  first.poses.push_back(odom_from_base * base_from_lidar);
  const evaluation::AssociatedPoses associated = evaluation::associateByTimestamp(first, ground_truth, 0.03);
  ASSERT_EQ(associated.estimate.size(), 1u);
  const Eigen::Isometry3f world_from_odom =
      (associated.ground_truth.front() * associated.estimate.front().inverse()).cast<float>();

  const double threshold_m = 3.0 * settings.voxel_m;  // the paper's F-score threshold
  evaluation::SurfaceSamplingOptions sampling;
  sampling.spacing_m = threshold_m / 4.0;  // as rim eval mesh
  evaluation::SurfaceSample mesh = evaluation::loadSurfaceSample(mesh_path, sampling);
  EXPECT_TRUE(mesh.from_mesh);
  for (Eigen::Vector3f& point : mesh.points) point = world_from_odom * point;
  const evaluation::SurfaceSample truth =
      evaluation::loadSurfaceSample(settings.sequence_dir + "/surface.ply", sampling);
  const evaluation::SurfaceMetrics metrics = evaluation::compareSurfaces(mesh.points, truth.points, threshold_m);
  std::cout << "saved mesh: " << mesh.triangle_count << " triangles (" << saved.message << "); at "
            << threshold_m << " m: precision " << metrics.precision << ", recall " << metrics.recall
            << ", F-score " << metrics.f_score << ", Chamfer " << metrics.chamfer_m << " m\n";
  EXPECT_GE(metrics.f_score, settings.min_f_score);

  // A late subscriber gets the whole mesh: the markers the early one holds.
  // The early one leaves first: roscpp shares one connection between the
  // subscribers of a topic in one node, so only a new connection is "late".
  mesh_subscriber.shutdown();
  spinUntil([] { return false; }, 1.0);
  MeshSubscriber late;
  late.world_frame = settings.world_frame;
  ros::Subscriber late_subscriber = node.subscribe<visualization_msgs::MarkerArray>(
      "/mesh", 100, [&](const visualization_msgs::MarkerArray::ConstPtr& message) { late.apply(*message); });
  spinUntil([&] { return late.messages > 0 && (ros::WallTime::now() - late.last_message).toSec() > 1.5; }, 10.0);
  ASSERT_GT(late.messages, 0u) << "nothing for a late subscriber";
  EXPECT_TRUE(late.full.front());
  EXPECT_EQ(late.held, early.held);

  // republish_mesh sends everything again, DELETEALL first.
  const std::size_t before_republish = late.messages;
  std_srvs::Empty republish;
  ASSERT_TRUE(ros::service::call("/mapper/republish_mesh", republish));
  spinUntil([&] { return late.messages > before_republish; }, 5.0);
  ASSERT_GT(late.messages, before_republish) << "nothing after republish_mesh";
  EXPECT_TRUE(late.full[before_republish]);
  spinUntil([] { return false; }, 1.0);
  EXPECT_EQ(late.held, early.held);

  // Reset: subscribers drop everything, and there is nothing left to save.
  std_srvs::Empty reset;
  ASSERT_TRUE(ros::service::call("/mapper/reset", reset));
  spinUntil([&] { return late.held.empty(); }, 5.0);
  EXPECT_TRUE(late.held.empty()) << late.held.size() << " markers left after reset";
  const SaveMesh::Response after_reset = saveMesh(settings.sequence_dir + "/after_reset.ply");
  EXPECT_FALSE(after_reset.success);
  EXPECT_NE(after_reset.message.find("no surface"), std::string::npos) << after_reset.message;
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  return range_image_mapping::test::runRostestNode(argc, argv, "mapper_simulated");
}
