#include "range_image_mapping/point_cloud_layout.h"

#include "error_text.h"
#include "point_cloud_buffer.h"
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/ouster_metadata.h"
#include "test_data.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace range_image_mapping {
namespace {

using test::contains;
using test::errorOf;
using test::PointCloudBuffer;
using Type = PointFieldType;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// A real KITTI scan written as velodyne_pointcloud writes a cloud: x, y, z,
// intensity (float32), ring (uint16) and time (float32 seconds after the
// header stamp). KITTI has neither rings nor times: ring is the point's index
// modulo 64 and time grows with the index, both only for reading them back.
PointCloudBuffer velodyneCloud(const PointCloudInput& scan, bool big_endian) {
  PointCloudBuffer cloud(1, static_cast<uint32_t>(scan.size()));
  cloud.layout.is_bigendian = big_endian;
  cloud.field("x", Type::kFloat32).field("y", Type::kFloat32).field("z", Type::kFloat32);
  cloud.field("intensity", Type::kFloat32).field("ring", Type::kUint16).field("time", Type::kFloat32);
  cloud.finish(0, 0, 16);
  for (std::size_t i = 0; i < scan.size(); ++i) {
    cloud.set(i, "x", scan.points[i].x());
    cloud.set(i, "y", scan.points[i].y());
    cloud.set(i, "z", scan.points[i].z());
    cloud.set(i, "intensity", scan.intensity[i]);
    cloud.set(i, "ring", static_cast<double>(i % 64));
    cloud.set(i, "time", 1e-6 * static_cast<double>(i));
  }
  return cloud;
}

TEST(PointCloudLayout, KittiScanAsVelodyneCloudReadsBackEveryValue) {
  RIM_REQUIRE_DATA(path, "kitti00/velodyne/000094.bin");
  const PointCloudInput scan = io::readKittiVelodyne(path);
  for (const bool big_endian : {false, true}) {
    SCOPED_TRACE(big_endian ? "big-endian" : "little-endian");
    const PointCloudBuffer cloud = velodyneCloud(scan, big_endian);
    const uint64_t header_stamp_ns = 1317384520000000000ull;
    PointCloudInput input;
    PointCloudReadReport report;
    readPointCloud(cloud.layout, cloud.data.data(), cloud.data.size(), header_stamp_ns, input, &report);
    ASSERT_EQ(input.size(), scan.size());
    std::size_t differing = 0;
    for (std::size_t i = 0; i < scan.size(); ++i)
      differing += input.points[i] != scan.points[i] || input.intensity[i] != scan.intensity[i] ||
                   input.ring[i] != i % 64;
    EXPECT_EQ(differing, 0u);
    EXPECT_EQ(report.time_field, "time");
    EXPECT_EQ(report.time_reference, PointTimeReference::kRelative);
    EXPECT_EQ(report.ring_field, "ring");
    EXPECT_EQ(input.intensity_field, "intensity");
    EXPECT_FALSE(input.isOrganized());
    // KITTI marks nothing as no-return; the first measured point is at 0 s.
    EXPECT_EQ(report.noReturn(), 0u);
    EXPECT_EQ(input.stamp_ns, header_stamp_ns);
    EXPECT_NEAR(input.time_offset_s.back(), 1e-6 * double(scan.size() - 1), 1e-6);
    EXPECT_NEAR(report.time_span_s, 1e-6 * double(scan.size() - 1), 1e-6);
  }
}

TEST(PointCloudLayout, Float64CoordinatesPaddingAndRowGapsReadTheSamePoints) {
  RIM_REQUIRE_DATA(path, "kitti00/velodyne/000095.bin");
  const PointCloudInput scan = io::readKittiVelodyne(path);
  // Two rows with bytes between them and padding inside each point; reflectivity
  // (uint16, Ouster) stands in for intensity, channel for ring.
  const uint32_t width = static_cast<uint32_t>(scan.size() / 2);
  PointCloudBuffer cloud(2, width);
  cloud.field("reflectivity", Type::kUint16).field("x", Type::kFloat64).field("y", Type::kFloat64);
  cloud.field("z", Type::kFloat64).field("channel", Type::kUint8);
  cloud.finish(5, 7, 8);
  for (std::size_t i = 0; i < 2 * std::size_t(width); ++i) {
    cloud.set(i, "x", scan.points[i].x());
    cloud.set(i, "y", scan.points[i].y());
    cloud.set(i, "z", scan.points[i].z());
    cloud.set(i, "reflectivity", std::round(scan.intensity[i] * 100.0f));
    cloud.set(i, "channel", static_cast<double>(i % 64));
  }
  PointCloudInput input;
  PointCloudReadReport report;
  readPointCloud(cloud.layout, cloud.data.data(), cloud.data.size(), 7, input, &report);
  ASSERT_EQ(input.size(), 2 * std::size_t(width));
  EXPECT_EQ(input.organized_height, 2);
  EXPECT_EQ(input.organized_width, static_cast<int>(width));
  std::size_t differing = 0;
  for (std::size_t i = 0; i < input.size(); ++i)
    differing += input.points[i] != scan.points[i] ||
                 input.intensity[i] != std::round(scan.intensity[i] * 100.0f) || input.ring[i] != i % 64;
  EXPECT_EQ(differing, 0u);
  EXPECT_EQ(input.intensity_field, "reflectivity");
  EXPECT_EQ(report.ring_field, "channel");
  EXPECT_EQ(report.time_field, "");
  EXPECT_TRUE(input.time_offset_s.empty());
  EXPECT_EQ(input.stamp_ns, 7u);  // no times: the header stamp
}

// A real Ouster scan (OS-1-128, decoded from its capture) as ouster-ros
// publishes it: organized H x W, destaggered, no-return pixels NaN, and t the
// column's time in nanoseconds after the header stamp.
struct OusterScan {
  RangeImage image;
  PointCloudBuffer cloud{1, 1};
};

OusterScan ousterRosCloud(const RangeImage& image) {
  const LidarModel& model = *image.model;
  const int rows = image.rows(), columns = image.columns();
  OusterScan scan{image, PointCloudBuffer(rows, columns)};
  PointCloudBuffer& cloud = scan.cloud;
  cloud.field("x", Type::kFloat32).field("y", Type::kFloat32).field("z", Type::kFloat32, 8);
  cloud.field("intensity", Type::kFloat32, 16).field("t", Type::kUint32).field("reflectivity", Type::kUint16);
  cloud.field("ring", Type::kUint16).field("ambient", Type::kUint16).field("range", Type::kUint32);
  cloud.finish(0, 0, 16);
  for (int v = 0; v < rows; ++v) {
    const int shift = model.intrinsics().pixel_shift_by_row[v];
    for (int u = 0; u < columns; ++u) {
      const std::size_t i = std::size_t(v) * columns + ((u + shift) % columns + columns) % columns;
      const Eigen::Vector3f point =
          image.valid(v, u) ? model.unproject(u, v, image.at(v, u)) : Eigen::Vector3f::Constant(kNaN);
      cloud.set(i, "x", point.x());
      cloud.set(i, "y", point.y());
      cloud.set(i, "z", point.z());
      cloud.set(i, "ring", v);
      const uint64_t column_time = image.column_timestamp_ns[u];
      cloud.set(i, "t", column_time >= image.stamp_ns ? double(column_time - image.stamp_ns) : 0.0);
    }
  }
  return scan;
}

RangeImage firstOusterScan(const std::string& pcap, const std::string& json) {
  std::vector<RangeImage> images = io::readOusterRangeImages(pcap, loadOusterMetadata(json));
  if (images.empty()) return {};
  return images.front();
}

TEST(PointCloudLayout, OusterRosCloudGivesTheDecodedImageAndItsColumnTimes) {
  RIM_REQUIRE_DATA(pcap, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(json, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  const RangeImage decoded = firstOusterScan(pcap, json);
  ASSERT_TRUE(decoded.model);
  const OusterScan scan = ousterRosCloud(decoded);
  PointCloudInput input;
  PointCloudReadReport report;
  readPointCloud(scan.cloud.layout, scan.cloud.data.data(), scan.cloud.data.size(), decoded.stamp_ns, input,
                 &report);
  EXPECT_EQ(report.time_field, "t");
  EXPECT_DOUBLE_EQ(report.time_unit_s, 1e-9);
  EXPECT_EQ(report.time_reference, PointTimeReference::kRelative);
  // No-return pixels are NaN points: counted as no-return, none lost.
  const std::size_t pixels = std::size_t(decoded.rows()) * decoded.columns();
  EXPECT_EQ(report.non_finite, pixels - decoded.validCount());
  EXPECT_EQ(report.measured(), decoded.validCount());
  EXPECT_GT(report.measured(), pixels / 2);

  input.organized_column_order = ColumnOrder::kDestaggered;
  ProjectionStatistics statistics;
  const RangeImage image = projectPointCloud(input, decoded.model, &statistics);
  EXPECT_EQ(statistics.kept, decoded.validCount());
  std::size_t range_mismatches = 0;
  for (std::size_t i = 0; i < pixels; ++i)
    range_mismatches += isValidRange(decoded.range[i]) != isValidRange(image.range[i]) ||
                        (isValidRange(decoded.range[i]) && std::abs(decoded.range[i] - image.range[i]) > 1e-4f);
  EXPECT_EQ(range_mismatches, 0u);
  // Every column with a return has its decoded time back, to the resolution of
  // PointCloudInput's float offsets (7.5 ns at 0.1 s).
  std::size_t time_mismatches = 0, columns_with_points = 0;
  for (int u = 0; u < decoded.columns(); ++u) {
    bool any = false;
    for (int v = 0; v < decoded.rows(); ++v) any |= decoded.valid(v, u);
    if (!any) continue;
    ++columns_with_points;
    time_mismatches +=
        std::abs(double(image.column_timestamp_ns[u]) - double(decoded.column_timestamp_ns[u])) > 8.0;

  }
  EXPECT_GT(columns_with_points, 0u);
  EXPECT_EQ(time_mismatches, 0u);
}

// The same real scan with the times other drivers write: absolute float64
// seconds (Hesai, RoboSense) under a header stamp a few milliseconds off, and
// float32 seconds relative to a header stamped at the end of the sweep
// (negative offsets). The scan time comes from the points either way.
TEST(PointCloudLayout, ScanTimeComesFromThePointsNotTheHeader) {
  RIM_REQUIRE_DATA(pcap, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(json, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  const RangeImage decoded = firstOusterScan(pcap, json);
  ASSERT_TRUE(decoded.model);
  const LidarModel& model = *decoded.model;
  std::vector<Eigen::Vector3f> points;
  std::vector<uint64_t> times_ns;
  for (int v = 0; v < decoded.rows(); ++v)
    for (int u = 0; u < decoded.columns(); ++u)
      if (decoded.valid(v, u)) {
        points.push_back(model.unproject(u, v, decoded.at(v, u)));
        times_ns.push_back(decoded.column_timestamp_ns[u]);
      }
  const uint64_t first_ns = *std::min_element(times_ns.begin(), times_ns.end());
  const uint64_t last_ns = *std::max_element(times_ns.begin(), times_ns.end());
  ASSERT_GT(first_ns, uint64_t(1e8));  // the check below needs a clock well past zero

  for (const bool absolute : {true, false}) {
    SCOPED_TRACE(absolute ? "timestamp float64 absolute" : "time float32 relative to the sweep's end");
    PointCloudBuffer cloud(1, static_cast<uint32_t>(points.size()));
    cloud.field("x", Type::kFloat32).field("y", Type::kFloat32).field("z", Type::kFloat32);
    cloud.field(absolute ? "timestamp" : "time", absolute ? Type::kFloat64 : Type::kFloat32).finish();
    const uint64_t header_ns = absolute ? first_ns + 2700000 : last_ns;  // jitter of 2.7 ms / stamped at the end
    for (std::size_t i = 0; i < points.size(); ++i) {
      cloud.set(i, "x", points[i].x());
      cloud.set(i, "y", points[i].y());
      cloud.set(i, "z", points[i].z());
      if (absolute)
        cloud.set(i, "timestamp", double(times_ns[i]) * 1e-9);
      else
        cloud.set(i, "time", (double(times_ns[i]) - double(header_ns)) * 1e-9);
    }
    PointCloudInput input;
    PointCloudReadReport report;
    readPointCloud(cloud.layout, cloud.data.data(), cloud.data.size(), header_ns, input, &report);
    EXPECT_EQ(report.time_reference, absolute ? PointTimeReference::kAbsolute : PointTimeReference::kRelative);
    EXPECT_NEAR(double(input.stamp_ns), double(first_ns), 1000.0);  // 1 us: float64 seconds' resolution
    EXPECT_NEAR(double(report.stamp_from_header_ns), double(first_ns) - double(header_ns), 1000.0);
    EXPECT_NEAR(report.time_span_s, double(last_ns - first_ns) * 1e-9, 1e-6);
    double worst_s = 0.0;
    for (std::size_t i = 0; i < points.size(); ++i)
      worst_s = std::max(worst_s, std::abs(double(input.stamp_ns) + input.time_offset_s[i] * 1e9 -
                                           double(times_ns[i])) * 1e-9);
    EXPECT_LT(worst_s, 2e-6);
  }
}

TEST(PointCloudLayout, NoReturnPointsAreCountedNotLost) {
  PointCloudBuffer cloud(2, 3);
  cloud.field("x", Type::kFloat32).field("y", Type::kFloat32).field("z", Type::kFloat32).finish();
  const float values[6][3] = {{1, 2, 3}, {0, 0, 0}, {kNaN, kNaN, kNaN}, {4, 5, 6}, {0, 0, 0}, {0, 0, 1}};
  for (std::size_t i = 0; i < 6; ++i)
    for (int a = 0; a < 3; ++a) cloud.set(i, std::string(1, "xyz"[a]), values[i][a]);
  PointCloudInput input;
  PointCloudReadReport report;
  readPointCloud(cloud.layout, cloud.data.data(), cloud.data.size(), 0, input, &report);
  ASSERT_EQ(input.size(), 6u);  // the organized shape keeps every point
  EXPECT_EQ(report.at_origin, 2u);
  EXPECT_EQ(report.non_finite, 1u);
  EXPECT_EQ(report.measured(), 3u);
  EXPECT_TRUE(std::isnan(input.points[2].x()));
  EXPECT_EQ(input.points[5], Eigen::Vector3f(0, 0, 1));
}

TEST(PointCloudLayout, BrokenLayoutsNameTheFieldAndTheProblem) {
  const auto read = [](const PointCloudBuffer& cloud) {
    return errorOf([&] {
      PointCloudInput input;
      readPointCloud(cloud.layout, cloud.data.data(), cloud.data.size(), 0, input);
    });
  };
  {
    PointCloudBuffer cloud(1, 4);
    cloud.field("x", Type::kFloat32).field("y", Type::kFloat32).finish();
    const std::string error = read(cloud);
    EXPECT_TRUE(contains(error, "'z'") && contains(error, "missing")) << error;
  }
  {
    PointCloudBuffer cloud(1, 4);
    cloud.field("x", Type::kFloat32).field("y", Type::kFloat32).field("z", Type::kInt16).finish();
    const std::string error = read(cloud);
    EXPECT_TRUE(contains(error, "'z'") && contains(error, "int16")) << error;
  }
  {
    PointCloudBuffer cloud(1, 4);
    cloud.field("x", Type::kFloat32).field("y", Type::kFloat32).field("z", Type::kFloat32);
    cloud.field("ring", Type::kFloat32).finish();
    const std::string error = read(cloud);
    EXPECT_TRUE(contains(error, "'ring'") && contains(error, "float32") && contains(error, "integer")) << error;
  }
  {
    PointCloudBuffer cloud(1, 4);
    cloud.field("x", Type::kFloat32).field("y", Type::kFloat32).field("z", Type::kFloat32).finish();
    cloud.layout.fields.push_back({"t", cloud.layout.point_step - 2, static_cast<uint8_t>(Type::kUint32), 1});
    const std::string error = read(cloud);
    EXPECT_TRUE(contains(error, "'t'") && contains(error, "point_step")) << error;
  }
  {
    PointCloudBuffer cloud(3, 4);
    cloud.field("x", Type::kFloat32).field("y", Type::kFloat32).field("z", Type::kFloat32).finish();
    cloud.data.resize(cloud.data.size() - 1);
    const std::string error = read(cloud);
    EXPECT_TRUE(contains(error, "bytes") && contains(error, "row_step")) << error;
  }
  {
    PointCloudBuffer cloud(1, 4);
    cloud.field("x", Type::kFloat32).field("y", Type::kFloat32).field("z", Type::kFloat32).finish();
    cloud.layout.row_step = cloud.layout.point_step * 3;
    const std::string error = read(cloud);
    EXPECT_TRUE(contains(error, "row_step") && contains(error, "width")) << error;
  }
  {
    PointCloudBuffer cloud(1, 1);
    cloud.field("x", Type::kFloat32).field("y", Type::kFloat32).field("z", Type::kFloat32);
    cloud.field("ring", Type::kInt16).finish();
    cloud.set(0, "ring", -3);
    const std::string error = read(cloud);
    EXPECT_TRUE(contains(error, "'ring'") && contains(error, "-3")) << error;
  }
}

}  // namespace
}  // namespace range_image_mapping
