// Receive-time scan stamps stay strictly increasing when ROS time stands
// still, spaced by the sensor clock, and follow ROS time otherwise.
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/range_image.h"
#include "range_image_mapping/receive_time_stamps.h"
#include "test_data.h"

#include <gtest/gtest.h>

#include <vector>

namespace range_image_mapping {
namespace {

constexpr int64_t kPeriod_ns = 100'000'000;

TEST(ReceiveTimeStamps, AStandingClockIsBridgedWithTheSensorClockOfARealCapture) {
  RIM_REQUIRE_DATA(pcap, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(json, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  const OusterMetadata metadata = loadOusterMetadata(json);
  const auto model = std::make_shared<const LidarModel>(metadata.intrinsics);
  std::vector<int64_t> sensor_ns;
  io::readOusterScans(pcap, metadata, [&](const LidarScan& scan) {
    sensor_ns.push_back(static_cast<int64_t>(toRangeImage(scan, model).stamp_ns));
  });
  ASSERT_EQ(sensor_ns.size(), 3u);

  // Every revolution received at the same ROS time, as when /clock is starved.
  ReceiveTimeStamps stamps(kPeriod_ns);
  const int64_t frozen_ns = 1'000'000'000'000;
  std::vector<ReceiveTimeStamps::Stamp> out;
  for (const int64_t sensor : sensor_ns) out.push_back(stamps.next(frozen_ns, sensor));
  EXPECT_EQ(out[0].stamp_ns, frozen_ns);
  EXPECT_FALSE(out[0].repaired);
  for (std::size_t i = 1; i < out.size(); ++i) {
    EXPECT_TRUE(out[i].repaired);
    EXPECT_EQ(out[i].stamp_ns - out[i - 1].stamp_ns, sensor_ns[i] - sensor_ns[i - 1]);
    EXPECT_GT(sensor_ns[i] - sensor_ns[i - 1], 0);
  }
  EXPECT_EQ(stamps.repaired(), 2u);

  // ROS time moves on past the repaired stamps: its own times again.
  const int64_t later_ns = out.back().stamp_ns + 30'000'000;
  const ReceiveTimeStamps::Stamp caught_up = stamps.next(later_ns, sensor_ns.back() + kPeriod_ns);
  EXPECT_EQ(caught_up.stamp_ns, later_ns);
  EXPECT_FALSE(caught_up.repaired);
}

TEST(ReceiveTimeStamps, ALaggingClockIsRepairedAJumpBackIsNot) {
  ReceiveTimeStamps stamps(kPeriod_ns);
  EXPECT_EQ(stamps.next(5'000'000'000, 0).stamp_ns, 5'000'000'000);
  // 20 ms behind the previous stamp: a lagging clock. The sensor clock did not
  // move (no time synchronisation, or a broken clock): the nominal period.
  const ReceiveTimeStamps::Stamp lagging = stamps.next(4'980'000'000, 0);
  EXPECT_TRUE(lagging.repaired);
  EXPECT_EQ(lagging.stamp_ns, 5'000'000'000 + kPeriod_ns);
  // Two seconds back: a bag loop, taken as it is.
  const ReceiveTimeStamps::Stamp looped = stamps.next(3'100'000'000, 200'000'000);
  EXPECT_FALSE(looped.repaired);
  EXPECT_EQ(looped.stamp_ns, 3'100'000'000);
  // A jump back of less than a second, once the nodelet saw ROS time go back.
  stamps.restart();
  EXPECT_EQ(stamps.next(2'900'000'000, 300'000'000).stamp_ns, 2'900'000'000);
  EXPECT_EQ(stamps.repaired(), 1u);
}

TEST(ReceiveTimeStamps, ANominalPeriodOutsideASecondIsRefused) {
  EXPECT_THROW(ReceiveTimeStamps(0), std::invalid_argument);
  EXPECT_THROW(ReceiveTimeStamps(1'000'000'000), std::invalid_argument);
}

}  // namespace
}  // namespace range_image_mapping
