// Checks of a cloud stream against its settings: clouds missing from the
// stamps, and the column order of organized clouds read from the points (on a
// real Ouster scan, organized as ouster-ros publishes it either way).
#include "range_image_mapping/cloud_stream_checks.h"
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/sensor_catalog.h"
#include "test_data.h"

#include <gtest/gtest.h>

#include <cmath>

namespace range_image_mapping {
namespace {

constexpr uint64_t kMs = 1'000'000;

TEST(CloudGapCounter, CountsTheCloudsMissingFromA10HzStream) {
  CloudGapCounter gaps;
  uint64_t stamp = 1'000'000 * kMs;
  for (int i = 0; i < 5; ++i, stamp += 100 * kMs) EXPECT_EQ(gaps.add(stamp), 0u);
  EXPECT_NEAR(gaps.periodSeconds(), 0.1, 1e-9);
  EXPECT_EQ(gaps.add(stamp + 200 * kMs), 2u);  // the clouds at +0 and +100 ms are missing
  EXPECT_EQ(gaps.add(stamp + 300 * kMs), 0u);
  EXPECT_EQ(gaps.missing(), 2u);
  // A bag loop: the stamps go back and the stream starts over without a count.
  EXPECT_EQ(gaps.add(1'000'000 * kMs), 0u);
  EXPECT_EQ(gaps.missing(), 2u);
}

TEST(CloudGapCounter, JitterIsNoGapAndThePeriodFollowsTheSensor) {
  CloudGapCounter gaps;
  uint64_t stamp = 0;
  // 20 Hz with +-20 % jitter in the stamps.
  const int jitter_ms[] = {0, 10, -10, 8, -6, 10, 0, -10, 5};
  for (const int jitter : jitter_ms) {
    stamp += (50 + jitter) * kMs;
    EXPECT_EQ(gaps.add(stamp), 0u);
  }
  EXPECT_NEAR(gaps.periodSeconds(), 0.05, 0.011);
  EXPECT_EQ(gaps.early(), 0u);
  EXPECT_EQ(gaps.add(stamp + 100 * kMs), 1u);
}

// Stamps 2-3 ms apart in a 10 Hz stream (a driver stamping with the receive
// time): early clouds, counted, and no missing ones.
TEST(CloudGapCounter, CountsCloudsStampedFarTooEarly) {
  CloudGapCounter gaps;
  uint64_t stamp = 0;
  for (int i = 0; i < 5; ++i) gaps.add(stamp += 100 * kMs);
  EXPECT_EQ(gaps.add(stamp += 3 * kMs), 0u);
  EXPECT_EQ(gaps.add(stamp += 2 * kMs), 0u);
  EXPECT_EQ(gaps.early(), 2u);
  EXPECT_EQ(gaps.missing(), 0u);
}

// The lb_n3 capture's first scan as an organized cloud in lidar-frame x, y, z,
// staggered or destaggered: the order is read back from the points.
TEST(OrganizedColumnOrder, ReadFromARealOusterScan) {
  RIM_REQUIRE_DATA(pcap, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(metadata_path, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  const OusterMetadata metadata = loadOusterMetadata(metadata_path);
  const std::vector<RangeImage> images = io::readOusterRangeImages(pcap, metadata);
  ASSERT_FALSE(images.empty());
  const RangeImage& staggered = images.front();
  const LidarModel& model = *staggered.model;
  const auto organized = [&](const RangeImage& image) {
    PointCloudInput cloud;
    cloud.organized_height = image.rows();
    cloud.organized_width = image.columns();
    const RangeImage as_staggered = image.staggered();
    const bool destaggered = image.column_order == ColumnOrder::kDestaggered;
    const auto& shifts = model.intrinsics().pixel_shift_by_row;
    for (int v = 0; v < image.rows(); ++v)
      for (int c = 0; c < image.columns(); ++c) {
        // Destaggered column c shows staggered column c - shift.
        const int u = destaggered ? ((c - shifts[v]) % image.columns() + image.columns()) % image.columns() : c;
        cloud.points.push_back(as_staggered.valid(v, u)
                                   ? model.unproject(u, v, as_staggered.at(v, u))
                                   : Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN()));
      }
    return cloud;
  };
  EXPECT_EQ(detectOrganizedColumnOrder(organized(staggered), model), ColumnOrder::kStaggered);
  EXPECT_EQ(detectOrganizedColumnOrder(organized(staggered.destaggered()), model), ColumnOrder::kDestaggered);

  // Rows that share one shift: both orders are the same, nothing to tell.
  LidarIntrinsics unshifted = model.intrinsics();
  unshifted.pixel_shift_by_row.assign(unshifted.rows, 0);
  EXPECT_FALSE(detectOrganizedColumnOrder(organized(staggered), LidarModel(unshifted)).has_value());
  // Another model of the same size fits neither order.
  LidarIntrinsics other = model.intrinsics();
  for (double& altitude : other.altitude_rad) altitude *= 0.5;
  EXPECT_FALSE(detectOrganizedColumnOrder(organized(staggered), LidarModel(other)).has_value());
  // An unorganized cloud has no column order.
  PointCloudInput plain = organized(staggered);
  plain.organized_height = 1;
  plain.organized_width = int(plain.points.size());
  EXPECT_FALSE(detectOrganizedColumnOrder(plain, model).has_value());
}

}  // namespace
}  // namespace range_image_mapping
