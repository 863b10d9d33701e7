// The ROS-side conversions, without a running nodelet.
#include "error_text.h"
#include "range_image_mapping/ros/range_image_conversions.h"

#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/PointField.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

using sensor_msgs::PointField;

// A small Ouster-like model: azimuth offsets, beam origin, shifts, a mount.
LidarModelConstPtr makeModel() {
  LidarIntrinsics intrinsics = LidarIntrinsics::synthetic(4, 16, 0.3, -0.3);
  intrinsics.azimuth_offset_rad = {0.05, -0.02, 0.01, -0.04};
  intrinsics.beam_origin_radius_m = 0.015;
  intrinsics.beam_origin_z_m = 0.002;
  intrinsics.pixel_shift_by_row = {3, 1, -1, -3};
  intrinsics.lidar_to_sensor = Eigen::Translation3d(0.0, 0.0, 0.036) *
                               Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ());
  intrinsics.column_window = {2, 13};
  intrinsics.sensor_model = "test-4";
  return std::make_shared<const LidarModel>(intrinsics);
}

RangeImage makeImage() {
  RangeImage image(makeModel());
  for (int v = 0; v < image.rows(); ++v)
    for (int u = 0; u < image.columns(); ++u)
      if ((u + v) % 3 != 0) image.range[image.index(v, u)] = 1.0f + 0.25f * u + 0.5f * v;
  image.intensity.resize(image.range.size());
  for (std::size_t i = 0; i < image.intensity.size(); ++i) image.intensity[i] = float(i);
  image.intensity_field = "reflectivity";
  for (int u = 0; u < image.columns(); ++u) image.column_timestamp_ns[u] = 1000000u + 100u * u;
  image.frame_id = 42;
  image.stamp_ns = 1000000;
  return image;
}

LidarRangeImage makeMessage() {
  std_msgs::Header header;
  header.stamp.fromNSec(1700000000123456789ull);
  header.frame_id = "os_lidar";
  LidarRangeImage message;
  toMessage(makeImage(), header, message);
  return message;
}

bool sameFloats(const std::vector<float>& a, const std::vector<float>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (!((std::isnan(a[i]) && std::isnan(b[i])) || a[i] == b[i])) return false;
  return true;
}

using test::errorOf;

// ------------------------------------------------------------ LidarRangeImage

TEST(RangeImageMessage, RoundTripKeepsPixelsTimestampsAndTables) {
  const RangeImage original = makeImage();
  const LidarRangeImage message = makeMessage();
  EXPECT_EQ(message.height, 4u);
  EXPECT_EQ(message.width, 16u);
  EXPECT_EQ(message.header.frame_id, "os_lidar");
  LidarModelCache models;
  const RangeImage back = fromMessage(message, models);
  EXPECT_TRUE(sameFloats(back.range, original.range));
  EXPECT_TRUE(sameFloats(back.intensity, original.intensity));
  EXPECT_EQ(back.intensity_field, "reflectivity");
  EXPECT_EQ(back.column_timestamp_ns, original.column_timestamp_ns);
  EXPECT_EQ(back.frame_id, 42u);
  EXPECT_EQ(back.stamp_ns, 1700000000123456789ull);
  EXPECT_EQ(back.column_order, ColumnOrder::kStaggered);
  const LidarIntrinsics& expected = original.model->intrinsics();
  const LidarIntrinsics& got = back.model->intrinsics();
  EXPECT_EQ(got.altitude_rad, expected.altitude_rad);
  EXPECT_EQ(got.azimuth_offset_rad, expected.azimuth_offset_rad);
  EXPECT_EQ(got.beam_origin_radius_m, expected.beam_origin_radius_m);
  EXPECT_EQ(got.beam_origin_z_m, expected.beam_origin_z_m);
  EXPECT_EQ(got.pixel_shift_by_row, expected.pixel_shift_by_row);
  EXPECT_EQ(got.column_window, expected.column_window);
  EXPECT_EQ(got.sensor_model, expected.sensor_model);
  EXPECT_TRUE(got.lidar_to_sensor.matrix() == expected.lidar_to_sensor.matrix());
  // The rebuilt model unprojects exactly like the original.
  for (int v = 0; v < back.rows(); ++v)
    for (int u = 0; u < back.columns(); ++u)
      EXPECT_TRUE(back.model->unproject(u, v, 7.0f).isApprox(original.model->unproject(u, v, 7.0f), 1e-6f));
}

TEST(RangeImageMessage, DestaggeredColumnOrderSurvivesTheRoundTrip) {
  const RangeImage destaggered = makeImage().destaggered();
  LidarRangeImage message;
  toMessage(destaggered, std_msgs::Header(), message);
  EXPECT_EQ(message.column_order, LidarRangeImage::DESTAGGERED);
  LidarModelCache models;
  const RangeImage back = fromMessage(message, models);
  EXPECT_EQ(back.column_order, ColumnOrder::kDestaggered);
  EXPECT_TRUE(sameFloats(back.staggered().range, makeImage().range));
}

TEST(RangeImageMessage, ModelCacheRebuildsOnlyWhenTablesChange) {
  LidarModelCache models;
  LidarRangeImage message = makeMessage();
  const LidarModelConstPtr first = models.modelFor(message);
  message.range[0] = 99.0f;  // pixels do not matter
  message.header.stamp.sec += 1;
  EXPECT_EQ(models.modelFor(message), first);
  message.altitude[2] += 1e-9;  // any table change does
  const LidarModelConstPtr second = models.modelFor(message);
  EXPECT_NE(second, first);
  message.lidar_to_sensor[3] = 0.5;
  const LidarModelConstPtr third = models.modelFor(message);
  EXPECT_NE(third, second);
  EXPECT_DOUBLE_EQ(third->intrinsics().lidar_to_sensor.translation().x(), 0.5);
  EXPECT_EQ(models.modelFor(message), third);
  // A broken message throws and leaves the cached model alone.
  LidarRangeImage broken = message;
  broken.altitude.pop_back();
  EXPECT_THROW(models.modelFor(broken), MessageConversionError);
  EXPECT_EQ(models.model(), third);
  EXPECT_EQ(models.modelFor(message), third);
}

TEST(RangeImageMessage, InconsistentMessagesAreRejectedNamingTheField) {
  LidarModelCache models;
  LidarRangeImage message = makeMessage();
  message.range.pop_back();
  EXPECT_NE(errorOf([&] { fromMessage(message, models); }).find("range has 63 values"), std::string::npos);
  message = makeMessage();
  message.intensity.resize(3);
  EXPECT_NE(errorOf([&] { fromMessage(message, models); }).find("intensity"), std::string::npos);
  message = makeMessage();
  message.column_timestamps.resize(15);
  EXPECT_NE(errorOf([&] { fromMessage(message, models); }).find("column_timestamps"), std::string::npos);
  message = makeMessage();
  message.azimuth_offset.resize(5);
  EXPECT_NE(errorOf([&] { fromMessage(message, models); }).find("azimuth_offset"), std::string::npos);
  message = makeMessage();
  message.column_order = 7;
  EXPECT_NE(errorOf([&] { fromMessage(message, models); }).find("column_order"), std::string::npos);
  message = makeMessage();
  message.width = 0;
  EXPECT_NE(errorOf([&] { fromMessage(message, models); }).find("height and width"), std::string::npos);
  message = makeMessage();
  message.altitude[1] = std::numeric_limits<double>::quiet_NaN();  // the core's own check
  EXPECT_THROW(fromMessage(message, models), IntrinsicsError);
}

TEST(RangeImageMessage, CloudHoldsTheUnprojectedValidPixels) {
  const RangeImage image = makeImage();
  sensor_msgs::PointCloud2 cloud;
  std_msgs::Header header;
  header.frame_id = "os_lidar";
  toPointCloud2(image, header, cloud);
  EXPECT_EQ(cloud.header.frame_id, "os_lidar");
  PointCloudInput points;
  fromPointCloud2(cloud, points);
  const std::vector<Eigen::Vector3f> expected = image.unprojectAll();
  ASSERT_EQ(points.points.size(), expected.size());
  for (std::size_t i = 0; i < expected.size(); ++i) EXPECT_TRUE(points.points[i] == expected[i]);
  // Rings are the image rows, intensity comes along.
  ASSERT_EQ(points.ring.size(), expected.size());
  ASSERT_EQ(points.intensity.size(), expected.size());
  std::size_t i = 0;
  for (int v = 0; v < image.rows(); ++v)
    for (int u = 0; u < image.columns(); ++u)
      if (image.valid(v, u)) {
        EXPECT_EQ(points.ring[i], v);
        EXPECT_EQ(points.intensity[i], image.intensity[image.index(v, u)]);
        ++i;
      }
}

// ------------------------------------------------------------ PointCloud2

struct FieldSpec {
  std::string name;
  uint8_t datatype;
};

std::size_t sizeOf(uint8_t datatype) {
  switch (datatype) {
    case PointField::INT8: case PointField::UINT8: return 1;
    case PointField::INT16: case PointField::UINT16: return 2;
    case PointField::FLOAT64: return 8;
    default: return 4;
  }
}

// A cloud with the given fields packed in order; value(point, field) fills them.
sensor_msgs::PointCloud2 makeCloud(const std::vector<FieldSpec>& fields, uint32_t height, uint32_t width,
                                   const std::function<double(std::size_t, std::size_t)>& value) {
  sensor_msgs::PointCloud2 cloud;
  uint32_t offset = 0;
  for (const FieldSpec& spec : fields) {
    PointField field;
    field.name = spec.name;
    field.offset = offset;
    field.datatype = spec.datatype;
    field.count = 1;
    cloud.fields.push_back(field);
    offset += sizeOf(spec.datatype);
  }
  cloud.height = height;
  cloud.width = width;
  cloud.point_step = offset;
  cloud.row_step = offset * width;
  cloud.data.resize(std::size_t(cloud.row_step) * height);
  for (std::size_t p = 0; p < std::size_t(height) * width; ++p) {
    for (std::size_t f = 0; f < fields.size(); ++f) {
      uint8_t* bytes = cloud.data.data() + p * cloud.point_step + cloud.fields[f].offset;
      const double x = value(p, f);
      switch (fields[f].datatype) {
        case PointField::UINT8: { const uint8_t v = uint8_t(x); std::memcpy(bytes, &v, 1); break; }
        case PointField::INT16: { const int16_t v = int16_t(x); std::memcpy(bytes, &v, 2); break; }
        case PointField::UINT16: { const uint16_t v = uint16_t(x); std::memcpy(bytes, &v, 2); break; }
        case PointField::UINT32: { const uint32_t v = uint32_t(x); std::memcpy(bytes, &v, 4); break; }
        case PointField::FLOAT64: std::memcpy(bytes, &x, 8); break;
        default: { const float v = float(x); std::memcpy(bytes, &v, 4); break; }
      }
    }
  }
  return cloud;
}

TEST(PointCloudConversion, OusterStyleFieldsAreRead) {
  // x, y, z float32, intensity uint16, t uint32 ns, ring uint16 (the Ouster driver's kinds).
  const auto cloud = makeCloud({{"x", PointField::FLOAT32}, {"y", PointField::FLOAT32},
                                {"z", PointField::FLOAT32}, {"intensity", PointField::UINT16},
                                {"t", PointField::UINT32}, {"ring", PointField::UINT16}},
                               2, 3, [](std::size_t p, std::size_t f) {
                                 return f < 3 ? 0.5 * p + f : f == 3 ? 100.0 + p : f == 4 ? 1000.0 * p : 7.0 - p;
                               });
  PointCloudInput input;
  fromPointCloud2(cloud, input);
  ASSERT_EQ(input.points.size(), 6u);
  EXPECT_EQ(input.organized_height, 2);
  EXPECT_EQ(input.organized_width, 3);
  for (std::size_t p = 0; p < 6; ++p) {
    EXPECT_EQ(input.points[p], Eigen::Vector3f(0.5f * p, 0.5f * p + 1, 0.5f * p + 2));
    EXPECT_EQ(input.intensity[p], 100.0f + p);
    EXPECT_FLOAT_EQ(input.time_offset_s[p], 1e-6f * p);
    EXPECT_EQ(input.ring[p], 7 - p);
  }
}

TEST(PointCloudConversion, Float64CoordinatesAndFloatTimeInSeconds) {
  const auto cloud = makeCloud({{"x", PointField::FLOAT64}, {"y", PointField::FLOAT64},
                                {"z", PointField::FLOAT64}, {"time", PointField::FLOAT32},
                                {"ring", PointField::UINT8}},
                               1, 4, [](std::size_t p, std::size_t f) { return f == 3 ? 0.025 * p : 1.25 * p + f; });
  PointCloudInput input;
  input.intensity.assign(10, 1.0f);  // stale buffers from a previous cloud are cleared
  fromPointCloud2(cloud, input);
  ASSERT_EQ(input.points.size(), 4u);
  EXPECT_EQ(input.organized_height, 1);
  EXPECT_TRUE(input.intensity.empty());
  for (std::size_t p = 0; p < 4; ++p) {
    EXPECT_EQ(input.points[p], Eigen::Vector3f(1.25f * p, 1.25f * p + 1, 1.25f * p + 2));
    EXPECT_FLOAT_EQ(input.time_offset_s[p], 0.025f * p);
    EXPECT_EQ(input.ring[p], uint8_t(1.25 * p + 4));
  }
}

TEST(PointCloudConversion, UnusableCloudsNameTheFieldAndType) {
  const auto any = [](std::size_t, std::size_t) { return 1.0; };
  PointCloudInput input;
  const auto error = [&](const sensor_msgs::PointCloud2& cloud) {
    return errorOf([&] { fromPointCloud2(cloud, input); });
  };
  EXPECT_NE(error(makeCloud({{"x", PointField::FLOAT32}, {"y", PointField::FLOAT32}}, 1, 2, any))
                .find("required field 'z'"),
            std::string::npos);
  const std::string integer_x =
      error(makeCloud({{"x", PointField::INT16}, {"y", PointField::FLOAT32}, {"z", PointField::FLOAT32}}, 1, 2, any));
  EXPECT_NE(integer_x.find("'x'"), std::string::npos) << integer_x;
  EXPECT_NE(integer_x.find("int16"), std::string::npos) << integer_x;
  const std::string float_ring =
      error(makeCloud({{"x", PointField::FLOAT32}, {"y", PointField::FLOAT32}, {"z", PointField::FLOAT32},
                       {"ring", PointField::FLOAT32}}, 1, 2, any));
  EXPECT_NE(float_ring.find("'ring' has type float32"), std::string::npos) << float_ring;

  auto good = makeCloud({{"x", PointField::FLOAT32}, {"y", PointField::FLOAT32}, {"z", PointField::FLOAT32}}, 2, 2, any);
  auto truncated = good;
  truncated.data.resize(truncated.data.size() - 1);
  EXPECT_NE(error(truncated).find("data has"), std::string::npos);
  auto outside = good;
  outside.fields[2].offset = 10;
  EXPECT_NE(error(outside).find("'z' at offset 10"), std::string::npos);
  auto short_rows = good;
  short_rows.row_step = 4;
  EXPECT_NE(error(short_rows).find("row_step"), std::string::npos);
  // The core reader's errors (point_cloud_layout.h) come as the message's.
  EXPECT_EQ(error(truncated).rfind("PointCloud2: ", 0), 0u) << error(truncated);
}

// ------------------------------------------------------------ Ouster packet messages

topic_tools::ShapeShifter makePacketMessage(const std::string& datatype, const std::string& md5,
                                            const std::vector<uint8_t>& serialized) {
  topic_tools::ShapeShifter message;
  message.morph(md5, datatype, "uint8[] buf\n", "0");
  std::vector<uint8_t> bytes = serialized;
  ros::serialization::IStream stream(bytes.data(), static_cast<uint32_t>(bytes.size()));
  message.read(stream);
  return message;
}

std::vector<uint8_t> lengthPrefixed(const std::vector<uint8_t>& payload, uint32_t length) {
  std::vector<uint8_t> bytes(4 + payload.size());
  std::memcpy(bytes.data(), &length, 4);
  std::copy(payload.begin(), payload.end(), bytes.begin() + 4);
  return bytes;
}

constexpr char kPacketMd5[] = "4f7b5949e76f86d01e96b0e33ba9b5e3";

TEST(OusterPacketMessage, BothDriversPacketTypesGiveThePayload) {
  const std::vector<uint8_t> payload = {1, 2, 3, 250, 0, 7};
  std::vector<uint8_t> buffer;
  for (const char* datatype : {"ouster_ros/PacketMsg", "ouster_sensor_msgs/PacketMsg"}) {
    const auto message = makePacketMessage(datatype, kPacketMd5, lengthPrefixed(payload, 6));
    const PacketBytes packet = ousterPacketBytes(message, buffer);
    ASSERT_EQ(packet.size, payload.size()) << datatype;
    EXPECT_TRUE(std::equal(payload.begin(), payload.end(), packet.data)) << datatype;
  }
}

TEST(OusterPacketMessage, OtherTypesAndBadLengthsAreRejected) {
  std::vector<uint8_t> buffer;
  const auto string_message =
      makePacketMessage("std_msgs/String", "992ce8a1687cec8c8bd883ec73ca41d1", lengthPrefixed({65, 66}, 2));
  const std::string wrong_type = errorOf([&] { ousterPacketBytes(string_message, buffer); });
  EXPECT_NE(wrong_type.find("'std_msgs/String'"), std::string::npos) << wrong_type;
  const auto other_definition = makePacketMessage("ouster_ros/PacketMsg", "0123456789abcdef0123456789abcdef",
                                                  lengthPrefixed({1}, 1));
  EXPECT_THROW(ousterPacketBytes(other_definition, buffer), MessageConversionError);
  const auto lying_length = makePacketMessage("ouster_ros/PacketMsg", kPacketMd5, lengthPrefixed({1, 2}, 5));
  const std::string bad_length = errorOf([&] { ousterPacketBytes(lying_length, buffer); });
  EXPECT_NE(bad_length.find("says buf has 5 bytes, the message carries 2"), std::string::npos) << bad_length;
  const auto too_short = makePacketMessage("ouster_ros/PacketMsg", kPacketMd5, {1, 2});
  EXPECT_THROW(ousterPacketBytes(too_short, buffer), MessageConversionError);
}

// ------------------------------------------------------------ motion

// The core orders twists [angular, linear] and covariances [rotation,
// translation]; geometry_msgs puts the linear part first in both.
TEST(MotionConversions, TwistsAndCovariancesChangeOrderNotValues) {
  Twist twist;
  twist << 0.1, 0.2, 0.3, 1.0, 2.0, 3.0;
  const geometry_msgs::Twist message = toTwistMessage(twist);
  EXPECT_EQ(message.angular.x, 0.1);
  EXPECT_EQ(message.angular.z, 0.3);
  EXPECT_EQ(message.linear.x, 1.0);
  EXPECT_EQ(message.linear.z, 3.0);
  EXPECT_EQ(fromTwistMessage(message), twist);

  Eigen::Matrix<double, 6, 6> covariance;
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) covariance(r, c) = 10 * r + c;
  boost::array<double, 36> ros_order;
  toCovarianceMessage(covariance, ros_order);
  EXPECT_EQ(ros_order[0 * 6 + 0], covariance(3, 3));  // x x
  EXPECT_EQ(ros_order[0 * 6 + 5], covariance(3, 2));  // x yaw
  EXPECT_EQ(ros_order[5 * 6 + 0], covariance(2, 3));  // yaw x
  EXPECT_EQ(ros_order[3 * 6 + 4], covariance(0, 1));  // roll pitch
  EXPECT_EQ(ros_order[2 * 6 + 1], covariance(5, 4));  // z y
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "range_image_conversions");
  ros::NodeHandle keep_node_alive;
  return RUN_ALL_TESTS();
}
