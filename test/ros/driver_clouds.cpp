// The real drivers' PointCloud2 conventions through the Adapter (loaded in
// this process): ouster-ros (organized, destaggered, sensor frame, NaN
// no-return, t in uint32 ns), velodyne_pointcloud (no-return dropped, ring 0 =
// lowest beam, time in float32 s after the stamp) and Hesai (timestamp in
// float64 absolute s, under a header stamp that jitters) each give the range
// image they were made from (the reference path) and its scan time, from the
// points' times and not the header. The clouds are written by the simulator's
// bag writer (rangeImageToPointCloud2), as `rim simulate` would.
#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/ros/bag_writer.h"
#include "range_image_mapping/ros/range_image_conversions.h"
#include "range_image_mapping/sensor_catalog.h"
#include "named_sensor_image.h"
#include "rostest_main.h"
#include "spin_until.h"
#include "test_data.h"

#include <gtest/gtest.h>
#include <nodelet/loader.h>
#include <ros/ros.h>

#include <map>

namespace range_image_mapping {
namespace {

using test::namedSensorImage;

class DriverCloudsTest : public ::testing::Test {
 protected:
  void TearDown() override { loader_.clear(); }

  // An Adapter as NAMESPACE/adapter; returns its first range image for cloud.
  LidarRangeImage::ConstPtr convert(const std::string& ns, const std::map<std::string, std::string>& parameters,
                                    const sensor_msgs::PointCloud2& cloud) {
    ros::NodeHandle private_node(ns + "/adapter");
    private_node.setParam("input", "pointcloud");
    for (const auto& [name, value] : parameters) private_node.setParam(name, value);
    EXPECT_TRUE(loader_.load(ns + "/adapter", "range_image_mapping/Adapter", nodelet::M_string(), nodelet::V_string()));
    LidarRangeImage::ConstPtr received;
    ros::Subscriber subscriber = node_.subscribe<LidarRangeImage>(
        ns + "/range_image", 1, [&](const LidarRangeImage::ConstPtr& image) { received = image; });
    ros::Publisher publisher = node_.advertise<sensor_msgs::PointCloud2>(ns + "/points", 1);
    test::spinUntil([&] { return publisher.getNumSubscribers() > 0 && subscriber.getNumPublishers() > 0; }, 10.0);
    publisher.publish(cloud);
    test::spinUntil([&] { return received != nullptr; }, 20.0);
    return received;
  }

  // The Adapter's image is the reference: the same pixels, ranges to float
  // rounding, column times to the time field's resolution, and its stamp.
  static void expectSameImage(const LidarRangeImage& got, const RangeImage& reference, double time_tolerance_ns) {
    ASSERT_EQ(int(got.height), reference.rows());
    ASSERT_EQ(int(got.width), reference.columns());
    // Differences in integer nanoseconds (doubles hold 1.7e18 ns only to 256 ns).
    const auto apart = [](uint64_t a, uint64_t b) { return double(int64_t(a - b)); };
    EXPECT_LE(std::abs(apart(got.header.stamp.toNSec(), reference.stamp_ns)), time_tolerance_ns)
        << "the scan time is the first point's time";
    std::size_t valid = 0, differing = 0;
    for (std::size_t i = 0; i < reference.range.size(); ++i) {
      const bool expected = isValidRange(reference.range[i]);
      const bool found = std::isfinite(got.range[i]);
      valid += expected;
      differing += expected != found || (expected && std::abs(got.range[i] - reference.range[i]) > 1e-3f);
    }
    EXPECT_EQ(differing, 0u) << "of " << valid << " valid pixels";
    ASSERT_EQ(got.column_timestamps.size(), reference.column_timestamp_ns.size());
    for (int u = 0; u < reference.columns(); ++u)
      EXPECT_LE(std::abs(apart(got.column_timestamps[u], reference.column_timestamp_ns[u])), time_tolerance_ns)
          << "column " << u;
  }

  ros::NodeHandle node_;
  nodelet::Loader loader_{false};
};

TEST_F(DriverCloudsTest, OusterRosOrganizedDestaggeredInTheSensorFrame) {
  RIM_REQUIRE_DATA(pcap, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(metadata_path, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  const std::vector<RangeImage> images = io::readOusterRangeImages(pcap, loadOusterMetadata(metadata_path));
  ASSERT_FALSE(images.empty());
  RangeImage reference = images.front();
  ASSERT_GT(reference.stamp_ns, 0u);
  // Columns without a return keep no time in the image the Adapter makes.
  for (int u = 0; u < reference.columns(); ++u) {
    bool any = false;
    for (int v = 0; v < reference.rows(); ++v) any |= reference.valid(v, u);
    if (!any) reference.column_timestamp_ns[u] = 0;
  }
  sensor_msgs::PointCloud2 cloud;
  rangeImageToPointCloud2(reference, CloudLayout::kOusterRos, "os_sensor", cloud);
  const auto image = convert("/ouster", {{"intrinsics", "ouster"}, {"metadata_file", metadata_path}}, cloud);
  ASSERT_TRUE(image) << "no range image";
  expectSameImage(*image, reference, 10.0);  // the core keeps time offsets as float seconds: 8 ns steps
}

TEST_F(DriverCloudsTest, VelodynePointcloudRingAndRelativeFloatTime) {
  const RangeImage reference = namedSensorImage("VLP-32C", 1'700'000'000'000'000'000ull);
  sensor_msgs::PointCloud2 cloud;
  rangeImageToPointCloud2(reference, CloudLayout::kVelodyne, "velodyne", cloud);
  const auto image = convert("/velodyne", {{"sensor", "VLP-32C"}, {"sensor_frame", "velodyne"}}, cloud);
  ASSERT_TRUE(image) << "no range image";
  expectSameImage(*image, reference, 20.0);  // float32 seconds: 7 ns steps at 0.1 s
}

TEST_F(DriverCloudsTest, HesaiAbsoluteTimestampsUnderAJitteringHeader) {
  const RangeImage reference = namedSensorImage("Pandar64", 1'700'000'000'000'000'000ull);
  sensor_msgs::PointCloud2 cloud;
  rangeImageToPointCloud2(reference, CloudLayout::kHesai, "hesai_lidar", cloud);
  cloud.header.stamp += ros::Duration(0.0027);  // the driver's header, 2.7 ms off the scan
  const auto image = convert("/hesai", {{"sensor", "Pandar64"}, {"sensor_frame", "hesai_lidar"}}, cloud);
  ASSERT_TRUE(image) << "no range image";
  expectSameImage(*image, reference, 500.0);  // float64 seconds at 1.7e9 s: 238 ns steps, in the stamp and the column
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  return range_image_mapping::test::runRostestNode(argc, argv, "driver_clouds");
}
