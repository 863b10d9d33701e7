// pointcloud.launch on KITTI scan 94: the Adapter's range image equals the
// core projection of the cloud's finite points (so injected NaNs leave no
// trace), float64 coordinates give the same image, and clouds it cannot read
// are dropped without stopping it.
#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/point_cloud_projection.h"
#include "range_image_mapping/ros/range_image_conversions.h"
#include "test_data.h"

#include "spin_until.h"

#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/PointField.h>

#include <cmath>
#include <cstring>
#include <algorithm>
#include <functional>
#include <limits>
#include <map>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

constexpr char kKittiScan[] = "kitti00/velodyne/000094.bin";

using test::spinUntil;

struct CloudLayout {
  uint8_t coordinate_type = sensor_msgs::PointField::FLOAT32;
  bool with_z = true;
  uint8_t x_type_override = 0;  // nonzero: declare x with this (wrong) type
};

// A PointCloud2 with x, y, z (float32 or float64) and float32 intensity.
sensor_msgs::PointCloud2 makeCloud(const PointCloudInput& input, const CloudLayout& layout,
                                   const ros::Time& stamp) {
  sensor_msgs::PointCloud2 cloud;
  cloud.header.stamp = stamp;
  cloud.header.frame_id = "velodyne";
  const uint32_t coordinate_size = layout.coordinate_type == sensor_msgs::PointField::FLOAT64 ? 8 : 4;
  const auto add_field = [&](const std::string& name, uint32_t offset, uint8_t datatype) {
    sensor_msgs::PointField field;
    field.name = name;
    field.offset = offset;
    field.datatype = datatype;
    field.count = 1;
    cloud.fields.push_back(field);
  };
  add_field("x", 0, layout.x_type_override ? layout.x_type_override : layout.coordinate_type);
  add_field("y", coordinate_size, layout.coordinate_type);
  if (layout.with_z) add_field("z", 2 * coordinate_size, layout.coordinate_type);
  add_field("intensity", 3 * coordinate_size, sensor_msgs::PointField::FLOAT32);
  cloud.height = 1;
  cloud.width = static_cast<uint32_t>(input.points.size());
  cloud.point_step = 3 * coordinate_size + 4;
  cloud.row_step = cloud.point_step * cloud.width;
  cloud.is_dense = false;
  cloud.data.resize(cloud.row_step);
  for (std::size_t i = 0; i < input.points.size(); ++i) {
    uint8_t* point = cloud.data.data() + i * cloud.point_step;
    for (int axis = 0; axis < 3; ++axis) {
      const float value = input.points[i][axis];
      if (coordinate_size == 8) {
        const double wide = value;
        std::memcpy(point + axis * 8, &wide, 8);
      } else {
        std::memcpy(point + axis * 4, &value, 4);
      }
    }
    std::memcpy(point + 3 * coordinate_size, &input.intensity[i], 4);
  }
  return cloud;
}

// Publishes clouds to the Adapter and collects its images by stamp.
class PointCloudAdapterTest : public testing::Test {
 protected:
  void SetUp() override {
    timeout_s_ = ros::NodeHandle("~").param("timeout", 20.0);
    const auto collect = [this](const LidarRangeImage::ConstPtr& image) {
      images_[image->header.stamp.toNSec()] = image;
    };
    publisher_ = node_.advertise<sensor_msgs::PointCloud2>("points", 1);
    subscriber_ = node_.subscribe<LidarRangeImage>("range_image", 8, collect);
    ring_publisher_ = node_.advertise<sensor_msgs::PointCloud2>("ring/points", 1);
    ring_subscriber_ = node_.subscribe<LidarRangeImage>("ring/range_image", 8, collect);
    ASSERT_TRUE(spinUntil(
        [&] {
          return publisher_.getNumSubscribers() > 0 && subscriber_.getNumPublishers() > 0 &&
                 ring_publisher_.getNumSubscribers() > 0 && ring_subscriber_.getNumPublishers() > 0;
        },
        timeout_s_))
        << "the Adapters did not connect to " << publisher_.getTopic() << ", "
        << subscriber_.getTopic() << ", " << ring_publisher_.getTopic() << " and "
        << ring_subscriber_.getTopic();
    ros::WallDuration(0.2).sleep();  // let the Adapter's side of the connection settle
  }

  // The image made from the cloud with this stamp, or null after the timeout.
  LidarRangeImage::ConstPtr publishAndWait(const sensor_msgs::PointCloud2& cloud, double timeout_s,
                                           ros::Publisher* publisher = nullptr) {
    (publisher ? *publisher : publisher_).publish(cloud);
    const uint64_t stamp = cloud.header.stamp.toNSec();
    spinUntil([&] { return images_.count(stamp) > 0; }, timeout_s);
    return images_.count(stamp) ? images_[stamp] : nullptr;
  }

  static ros::Time nextStamp() {
    static uint32_t seconds = 1000;
    return ros::Time(++seconds, 0);
  }

  ros::NodeHandle node_;
  ros::Publisher publisher_;
  ros::Subscriber subscriber_;
  ros::Publisher ring_publisher_;
  ros::Subscriber ring_subscriber_;
  std::map<uint64_t, LidarRangeImage::ConstPtr> images_;
  double timeout_s_ = 20.0;
};

// The core's own projection of the same points, with the model of the message.
RangeImage projectWithMessageModel(PointCloudInput cloud, const LidarRangeImage& message) {
  LidarModelCache models;
  cloud.intensity_field = "intensity";
  return projectPointCloud(cloud, models.modelFor(message));
}

void expectSameRanges(const LidarRangeImage& message, const RangeImage& expected) {
  ASSERT_EQ(message.range.size(), expected.range.size());
  std::size_t differing = 0;
  for (std::size_t i = 0; i < expected.range.size(); ++i) {
    const float got = message.range[i];
    const float want = expected.range[i];
    differing += !((std::isnan(got) && std::isnan(want)) || got == want);
  }
  EXPECT_EQ(differing, 0u) << "pixels whose range differs from the core projection";
}

TEST_F(PointCloudAdapterTest, KittiScanWithNaNsBecomesTheCoreProjectionOfItsFinitePoints) {
  RIM_REQUIRE_DATA(scan_path, kKittiScan);
  const PointCloudInput clean = io::readKittiVelodyne(scan_path);
  // Every 7th point becomes NaN or Inf, as drivers mark missing returns.
  PointCloudInput with_gaps = clean;
  std::size_t injected = 0;
  for (std::size_t i = 0; i < with_gaps.points.size(); i += 7, ++injected)
    with_gaps.points[i].setConstant(i % 2 ? std::numeric_limits<float>::quiet_NaN()
                                          : std::numeric_limits<float>::infinity());
  PointCloudInput finite_only;
  for (std::size_t i = 0; i < clean.points.size(); ++i) {
    if (i % 7 == 0) continue;
    finite_only.points.push_back(clean.points[i]);
    finite_only.intensity.push_back(clean.intensity[i]);
  }
  finite_only.organized_width = static_cast<int>(finite_only.points.size());

  const auto image = publishAndWait(makeCloud(with_gaps, {}, nextStamp()), timeout_s_);
  ASSERT_TRUE(image) << "no range image within " << timeout_s_ << " s";

  // The config's intrinsics are KITTI's, as the core defines them.
  const LidarIntrinsics kitti = io::kittiHdl64Intrinsics(static_cast<int>(image->width));
  ASSERT_EQ(int(image->height), kitti.rows);
  for (int v = 0; v < kitti.rows; ++v) EXPECT_NEAR(image->altitude[v], kitti.altitude_rad[v], 1e-12);
  EXPECT_EQ(image->header.frame_id, "velodyne");
  EXPECT_EQ(image->intensity_field, "intensity");
  ASSERT_EQ(image->intensity.size(), image->range.size());

  const RangeImage expected = projectWithMessageModel(finite_only, *image);
  expectSameRanges(*image, expected);
  std::size_t valid = 0;
  for (const float range : image->range) {
    if (std::isnan(range)) continue;
    EXPECT_TRUE(std::isfinite(range) && range > 0) << range;
    ++valid;
  }
  EXPECT_EQ(valid, expected.validCount());
  EXPECT_GT(valid, 0u);
  EXPECT_LE(valid, clean.points.size() - injected);
}

TEST_F(PointCloudAdapterTest, Float64CoordinatesGiveTheSameImageAsFloat32) {
  RIM_REQUIRE_DATA(scan_path, kKittiScan);
  const PointCloudInput clean = io::readKittiVelodyne(scan_path);
  CloudLayout wide;
  wide.coordinate_type = sensor_msgs::PointField::FLOAT64;
  const auto from_float64 = publishAndWait(makeCloud(clean, wide, nextStamp()), timeout_s_);
  ASSERT_TRUE(from_float64) << "no range image for the float64 cloud";
  expectSameRanges(*from_float64, projectWithMessageModel(clean, *from_float64));
}

TEST_F(PointCloudAdapterTest, UnreadableCloudsAreDroppedAndTheAdapterKeepsGoing) {
  RIM_REQUIRE_DATA(scan_path, kKittiScan);
  const PointCloudInput clean = io::readKittiVelodyne(scan_path);
  CloudLayout without_z;
  without_z.with_z = false;
  CloudLayout integer_x;
  integer_x.x_type_override = sensor_msgs::PointField::INT16;
  for (const CloudLayout& broken : {without_z, integer_x}) {
    const auto image = publishAndWait(makeCloud(clean, broken, nextStamp()), 1.5);
    EXPECT_FALSE(image) << "an image came out of an unreadable cloud";
  }
  const auto image = publishAndWait(makeCloud(clean, {}, nextStamp()), timeout_s_);
  ASSERT_TRUE(image) << "no range image for a good cloud after the broken ones";
  EXPECT_GT(std::count_if(image->range.begin(), image->range.end(),
                          [](float range) { return std::isfinite(range); }),
            0);
}

TEST_F(PointCloudAdapterTest, RingIntrinsicsComeFromTheRingField) {
  RIM_REQUIRE_DATA(scan_path, kKittiScan);
  // A cloud whose ring field is the row of the KITTI image: the unprojected
  // pixels of the first Adapter's image (toPointCloud2 writes ring = row).
  const auto kitti_image =
      publishAndWait(makeCloud(io::readKittiVelodyne(scan_path), {}, nextStamp()), timeout_s_);
  ASSERT_TRUE(kitti_image) << "no KITTI range image";
  LidarModelCache models;
  const RangeImage synthetic = fromMessage(*kitti_image, models);
  sensor_msgs::PointCloud2 ring_cloud;
  std_msgs::Header header;
  header.stamp = nextStamp();
  header.frame_id = "velodyne";
  toPointCloud2(synthetic, header, ring_cloud);

  const auto image = publishAndWait(ring_cloud, timeout_s_, &ring_publisher_);
  ASSERT_TRUE(image) << "no range image from the ring Adapter";
  EXPECT_EQ(image->sensor_model, "ring");
  int rings = 0;  // the highest ring with points, plus one (KITTI leaves the lowest rows empty)
  for (int v = 0; v < synthetic.rows(); ++v)
    for (int u = 0; u < synthetic.columns(); ++u)
      if (synthetic.valid(v, u)) rings = v + 1;
  ASSERT_EQ(int(image->height), rings) << "one row per ring";
  EXPECT_EQ(image->width, 1808u) << "columns of config/velodyne_vlp16.yaml";
  // Ring r holds the points of synthetic row r, so its median elevation lies
  // within half a row spacing of that row's altitude.
  const LidarIntrinsics& rows = synthetic.model->intrinsics();
  const double half_spacing = 0.5 * (rows.altitude_rad.front() - rows.altitude_rad.back()) / (rows.rows - 1);
  for (int v = 0; v < rings; ++v)
    EXPECT_NEAR(image->altitude[v], rows.altitude_rad[v], half_spacing) << "row " << v;
  const std::size_t valid = std::count_if(image->range.begin(), image->range.end(),
                                          [](float range) { return std::isfinite(range); });
  EXPECT_GT(valid, 0u);
  EXPECT_LE(valid, std::size_t(ring_cloud.width));
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "pointcloud_adapter");
  ros::NodeHandle keep_node_alive;
  return RUN_ALL_TESTS();
}
