// A bag that looks like a velodyne_pointcloud recording (VLP-16 clouds on
// /velodyne_points in frame velodyne: no-return dropped, ring 0 the lowest
// beam, time in float32 s after the stamp), written by the simulator's
// BagWriter, replayed with rosbag play through pointcloud.launch with
// sensor:=VLP-16 sensor_frame:=velodyne: every scan becomes its source range
// image, stamped with its first point's time, and no setting is warned about.
//
// As simulated_bag.test, driver_bag.test runs this node twice: first as
// `driver_bag_node --write-bag BAG` from a <param command=...>, then as the test.
#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/ros/bag_writer.h"
#include "named_sensor_image.h"
#include "spin_until.h"

#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <ros/ros.h>

#include <cstring>
#include <iostream>
#include <map>

namespace range_image_mapping {
namespace {

constexpr int kScans = 5;
constexpr uint64_t kFirstScanNs = 1'700'000'000'000'000'000ull;
constexpr uint64_t kScanPeriodNs = 100'000'000ull;
constexpr const char* kTopic = "/velodyne_points";

RangeImage sourceScan(int scan) {
  return test::namedSensorImage("VLP-16", kFirstScanNs + scan * kScanPeriodNs, 10 + scan);
}

int writeBag(const std::string& path) {
  BagWriter bag(path);
  sensor_msgs::PointCloud2 cloud;
  for (int scan = 0; scan < kScans; ++scan) {
    rangeImageToPointCloud2(sourceScan(scan), CloudLayout::kVelodyne, "velodyne", cloud);
    bag.writePointCloud(cloud, kTopic);
  }
  bag.close();
  std::cout << path << std::endl;  // the <param command> value
  return 0;
}

TEST(DriverBag, VelodyneRecordingThroughTheLaunchGivesTheSourceImages) {
  ros::NodeHandle node;
  const double timeout_s = ros::NodeHandle("~").param("timeout", 30.0);
  std::map<uint64_t, LidarRangeImage::ConstPtr> images;  // by stamp
  ros::Subscriber subscriber = node.subscribe<LidarRangeImage>(
      "/range_image", 10, [&](const LidarRangeImage::ConstPtr& image) { images[image->header.stamp.toNSec()] = image; });
  std::vector<std::string> warnings;
  ros::Subscriber diagnostics = node.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 10, [&](const diagnostic_msgs::DiagnosticArray::ConstPtr& array) {
        for (const auto& status : array->status)
          for (const auto& value : status.values)
            if (value.key.rfind("warning: ", 0) == 0) warnings.push_back(value.key + " " + value.value);
      });
  ASSERT_TRUE(test::spinUntil([&] { return images.size() >= std::size_t(kScans); }, timeout_s))
      << images.size() << " range images of " << kScans;
  for (int scan = 0; scan < kScans; ++scan) {
    const RangeImage source = sourceScan(scan);
    const auto found = images.find(source.stamp_ns);
    ASSERT_NE(found, images.end()) << "no range image stamped with scan " << scan << "'s first point time";
    const LidarRangeImage& image = *found->second;
    ASSERT_EQ(int(image.height), source.rows());
    ASSERT_EQ(int(image.width), source.columns());
    EXPECT_EQ(image.header.frame_id, "velodyne");
    std::size_t differing = 0;
    for (std::size_t i = 0; i < source.range.size(); ++i) {
      const bool expected = isValidRange(source.range[i]);
      differing += expected != std::isfinite(image.range[i]) ||
                   (expected && std::abs(image.range[i] - source.range[i]) > 1e-3f);
    }
    EXPECT_EQ(differing, 0u) << "scan " << scan;
  }
  test::spinUntil([] { return false; }, 1.5);  // a diagnostics update
  EXPECT_TRUE(warnings.empty()) << warnings.front();
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  if (argc >= 3 && std::strcmp(argv[1], "--write-bag") == 0) return range_image_mapping::writeBag(argv[2]);
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "driver_bag");
  ros::NodeHandle keep_node_alive;
  return RUN_ALL_TESTS();
}
