// ouster_replay.launch on the ouster-sdk test bag: the one revolution it holds
// must come out bit-exact (golden md5 of ouster-extra/SOURCE.md), and the
// message alone must unproject its pixels as the core model of the metadata does.
#include "md5.h"
#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/ouster_metadata.h"

#include "spin_until.h"

#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

// Golden values of ouster-extra/SOURCE.md: frame 1798, RANGE uint32 128x512 staggered mm.
constexpr char kGoldenRangeMd5[] = "9d68e9c6cde0eab641726111793b2a0e";
constexpr uint32_t kGoldenFrameId = 1798;
constexpr std::size_t kGoldenNonZeroPixels = 28751;

using test::spinUntil;

// Unprojection exactly as msg/LidarRangeImage.msg documents it, from the message's
// own tables (no core code), so the test shows the message is self-describing.
Eigen::Vector3d unprojectFromMessage(const LidarRangeImage& message, int u, int v, double range) {
  const double theta_e = 2 * M_PI - 2 * M_PI * u / message.width;
  const double theta = theta_e + message.azimuth_offset[v];
  const double phi = message.altitude[v];
  const Eigen::Vector3d direction(std::cos(theta) * std::cos(phi), std::sin(theta) * std::cos(phi),
                                  std::sin(phi));
  const double r0 = message.beam_origin_radius;
  const double z0 = message.beam_origin_z;
  const double origin_norm = std::hypot(r0, z0);
  return (range - origin_norm) * direction +
         Eigen::Vector3d(r0 * std::cos(theta_e), r0 * std::sin(theta_e), z0);
}

TEST(OusterReplay, RangeImageMatchesGoldenMd5AndIsSelfDescribing) {
  ros::NodeHandle private_node("~");
  const std::string bag_file = private_node.param<std::string>("bag_file", "");
  const std::string metadata_file = private_node.param<std::string>("metadata_file", "");
  const double timeout_s = private_node.param("timeout", 60.0);
  // With loop:=true the bag's one revolution comes round again and again; ROS
  // time jumps back each time, and every pass must give the same image.
  const int expected_images = private_node.param("expected_images", 1);
  if (!std::filesystem::exists(bag_file) || !std::filesystem::exists(metadata_file))
    GTEST_SKIP() << "sensor data not found: " << bag_file << " and " << metadata_file
                 << " (set RIM_DATA_DIR to the shared/data folder)";

  ros::NodeHandle node;
  std::vector<LidarRangeImage::ConstPtr> images;
  sensor_msgs::PointCloud2::ConstPtr cloud;
  const ros::Subscriber image_subscriber = node.subscribe<LidarRangeImage>(
      "range_image", 4, [&](const LidarRangeImage::ConstPtr& message) { images.push_back(message); });
  const ros::Subscriber cloud_subscriber = node.subscribe<sensor_msgs::PointCloud2>(
      "cloud", 4, [&](const sensor_msgs::PointCloud2::ConstPtr& message) { if (!cloud) cloud = message; });
  tf2_ros::Buffer transforms;
  const tf2_ros::TransformListener transform_listener(transforms);

  ASSERT_TRUE(spinUntil([&] { return int(images.size()) >= expected_images && cloud; }, timeout_s))
      << images.size() << " of " << expected_images << " range images (and "
      << (cloud ? "a" : "no") << " cloud) on " << image_subscriber.getTopic() << " within "
      << timeout_s << " s of wall time";
  const auto validCount = [](const LidarRangeImage& message) {
    return std::count_if(message.range.begin(), message.range.end(), [](float r) { return !std::isnan(r); });
  };
  for (const auto& repeated : images) {
    EXPECT_EQ(validCount(*repeated), validCount(*images.front()));
    EXPECT_EQ(repeated->frame_id, kGoldenFrameId);
    EXPECT_EQ(repeated->range.size(), images.front()->range.size());
    EXPECT_TRUE(std::equal(repeated->range.begin(), repeated->range.end(), images.front()->range.begin(),
                           [](float a, float b) { return a == b || (std::isnan(a) && std::isnan(b)); }))
        << "a replayed revolution differs from the first";
  }
  const LidarRangeImage::ConstPtr& image = images.front();

  // Bit-exact ranges: metres back to the sensor's millimetres.
  EXPECT_EQ(image->frame_id, kGoldenFrameId);
  EXPECT_EQ(image->column_order, LidarRangeImage::STAGGERED);
  ASSERT_EQ(image->height, 128u);
  ASSERT_EQ(image->width, 512u);
  ASSERT_EQ(image->range.size(), std::size_t(image->height) * image->width);
  std::vector<uint32_t> millimetres(image->range.size());
  std::size_t non_zero = 0;
  for (std::size_t i = 0; i < image->range.size(); ++i) {
    const float range = image->range[i];
    millimetres[i] = std::isnan(range) ? 0u : static_cast<uint32_t>(std::lround(range * 1000.0));
    non_zero += millimetres[i] != 0;
  }
  EXPECT_EQ(non_zero, kGoldenNonZeroPixels);
  EXPECT_EQ(test::md5Hex(millimetres), kGoldenRangeMd5);
  EXPECT_EQ(image->header.frame_id, "os_lidar");

  // Self-describing: the message's tables unproject every pixel like the core
  // model built from the metadata file.
  const OusterMetadata metadata = loadOusterMetadata(metadata_file);
  const LidarModel model(metadata.intrinsics);
  double worst_m = 0.0;
  std::size_t compared = 0;
  for (int v = 0; v < int(image->height); ++v) {
    for (int u = 0; u < int(image->width); ++u) {
      const float range = image->range[std::size_t(v) * image->width + u];
      if (std::isnan(range)) continue;
      const Eigen::Vector3d from_message = unprojectFromMessage(*image, u, v, range);
      const Eigen::Vector3d from_metadata = model.unproject(u, v, range).cast<double>();
      worst_m = std::max(worst_m, (from_message - from_metadata).norm());
      ++compared;
    }
  }
  EXPECT_EQ(compared, kGoldenNonZeroPixels);
  EXPECT_LT(worst_m, 1e-3) << "message tables and metadata disagree";
  Eigen::Matrix4d lidar_to_sensor;
  for (int i = 0; i < 16; ++i) lidar_to_sensor(i / 4, i % 4) = image->lidar_to_sensor[i];
  EXPECT_TRUE(lidar_to_sensor.isApprox(metadata.intrinsics.lidar_to_sensor.matrix(), 1e-12));

  // The unprojected cloud has one point per valid pixel, in the lidar frame.
  EXPECT_EQ(cloud->width * cloud->height, kGoldenNonZeroPixels);
  EXPECT_EQ(cloud->header.frame_id, "os_lidar");

  // The static transform sensor -> lidar is the metadata's lidar_to_sensor.
  ASSERT_TRUE(spinUntil([&] { return transforms.canTransform("os_sensor", "os_lidar", ros::Time(0)); },
                        10.0))
      << "no transform os_sensor -> os_lidar";
  const geometry_msgs::TransformStamped transform =
      transforms.lookupTransform("os_sensor", "os_lidar", ros::Time(0));
  const Eigen::Vector3d translation = metadata.intrinsics.lidar_to_sensor.translation();
  EXPECT_NEAR(transform.transform.translation.x, translation.x(), 1e-9);
  EXPECT_NEAR(transform.transform.translation.y, translation.y(), 1e-9);
  EXPECT_NEAR(transform.transform.translation.z, translation.z(), 1e-9);
  const Eigen::Quaterniond expected_rotation(metadata.intrinsics.lidar_to_sensor.rotation());
  const Eigen::Quaterniond rotation(transform.transform.rotation.w, transform.transform.rotation.x,
                                    transform.transform.rotation.y, transform.transform.rotation.z);
  EXPECT_NEAR(rotation.angularDistance(expected_rotation), 0.0, 1e-9);
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "ouster_replay_md5");
  ros::NodeHandle keep_node_alive;
  return RUN_ALL_TESTS();
}
