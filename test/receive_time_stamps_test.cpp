// Receive-time scan stamps: the sensor clock mapped onto ROS time. A stalled
// process's backlog, a standing /clock and clock drift leave the stamps on the
// sensor clock's spacing; clock steps re-anchor them and are counted.
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/range_image.h"
#include "range_image_mapping/receive_time_stamps.h"
#include "test_data.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

constexpr int64_t kPeriod_ns = 100'000'000;
constexpr int64_t kSecond_ns = 1'000'000'000;

// A 10 Hz sensor whose clock started at 3.2 s, received 4 ms after each scan
// starts plus up to 3 ms of deterministic jitter, from ROS time 1000 s on.
struct Sequence {
  std::vector<int64_t> sensor_ns, receipt_ns;
  explicit Sequence(int scans, double drift = 0.0) {
    for (int i = 0; i < scans; ++i) {
      const int64_t sensor = 3'200'000'000 + i * kPeriod_ns;
      sensor_ns.push_back(sensor);
      const auto true_time = static_cast<int64_t>(1000 * kSecond_ns + (1.0 + drift) * double(i * kPeriod_ns));
      receipt_ns.push_back(true_time + 4'000'000 + (i * 7919 % 31) * 100'000);
    }
  }
  // Stamps of every scan, read in order.
  std::vector<ReceiveTimeStamps::Stamp> stamp(ReceiveTimeStamps& stamps) const {
    std::vector<ReceiveTimeStamps::Stamp> out;
    for (std::size_t i = 0; i < sensor_ns.size(); ++i) out.push_back(stamps.next(receipt_ns[i], sensor_ns[i]));
    return out;
  }
};

void expectIncreasing(const std::vector<ReceiveTimeStamps::Stamp>& stamps) {
  for (std::size_t i = 1; i < stamps.size(); ++i)
    ASSERT_GT(stamps[i].stamp_ns, stamps[i - 1].stamp_ns) << "scan " << i;
}

TEST(ReceiveTimeStamps, AStandingClockKeepsTheSpacingOfARealCapture) {
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
  expectIncreasing(out);
  for (std::size_t i = 1; i < out.size(); ++i) {
    const int64_t sensor_interval_ns = sensor_ns[i] - sensor_ns[i - 1];
    EXPECT_GT(sensor_interval_ns, 0);
    EXPECT_NEAR(double(out[i].stamp_ns - out[i - 1].stamp_ns), double(sensor_interval_ns),
                ReceiveTimeStamps::kDriftRate * double(sensor_interval_ns))
        << "spaced by the sensor clock";
    EXPECT_FALSE(out[i].repaired);
  }
  EXPECT_EQ(stamps.counts().early, 2u) << "counted: ROS time stood still";
  EXPECT_EQ(stamps.counts().restamped, 0u);
  EXPECT_EQ(stamps.counts().clock_steps, 0u);
}

TEST(ReceiveTimeStamps, ABacklogReadAtOnceAfterAStallKeepsItsStamps) {
  Sequence sequence(400);
  const std::vector<int64_t> undisturbed = sequence.receipt_ns;
  // The process stopped for 6 s: scans 100 to 159 are read 1 ms apart once it
  // runs again, after scan 160 would have come.
  const int64_t resumed_ns = sequence.receipt_ns[160];
  for (int i = 100; i < 160; ++i) sequence.receipt_ns[i] = resumed_ns + (i - 100) * 1'000'000;
  for (int i = 160; i < 170; ++i) sequence.receipt_ns[i] = resumed_ns + (60 + i - 160) * 1'000'000;

  ReceiveTimeStamps stamps(kPeriod_ns);
  const std::vector<ReceiveTimeStamps::Stamp> out = sequence.stamp(stamps);
  expectIncreasing(out);
  for (std::size_t i = 0; i < out.size(); ++i) {
    // The undisturbed receipt's time, within its jitter and 1 % of the stall.
    EXPECT_NEAR(double(out[i].stamp_ns), double(undisturbed[i]), 3e6 + 0.01 * 6e9) << "scan " << i;
    if (i > 0) EXPECT_NEAR(double(out[i].stamp_ns - out[i - 1].stamp_ns), double(kPeriod_ns), 4e6) << "scan " << i;
  }
  EXPECT_LT(std::llabs(out.back().stamp_ns - undisturbed.back()), 4'000'000) << "back on the receipts after it";
  // Scans 100-155 are read 0.5 s or more late, less the offset's rise of up
  // to 1 ms a scan over the stall.
  EXPECT_GE(stamps.counts().late, 50u);
  EXPECT_LE(stamps.counts().late, 56u);
  EXPECT_EQ(stamps.counts().clock_steps, 0u) << "a stall is not a clock step";
  EXPECT_EQ(stamps.counts().restamped, 0u);
  // The receipts themselves bunch the backlog's scans 1 ms apart.
  EXPECT_EQ(sequence.receipt_ns[101] - sequence.receipt_ns[100], 1'000'000);
}

TEST(ReceiveTimeStamps, ABacklogReadWhileROSTimeStoodStillKeepsItsStamps) {
  // As a replay's manager saw it after a 6 s stop: the packets were read
  // before the bag's /clock was, so ROS time stood at the stall's start.
  Sequence sequence(400);
  const std::vector<int64_t> undisturbed = sequence.receipt_ns;
  for (int i = 101; i < 160; ++i) sequence.receipt_ns[i] = sequence.receipt_ns[100] + (i - 100) * 1'000;

  ReceiveTimeStamps stamps(kPeriod_ns);
  const std::vector<ReceiveTimeStamps::Stamp> out = sequence.stamp(stamps);
  expectIncreasing(out);
  for (std::size_t i = 0; i < out.size(); ++i)
    EXPECT_NEAR(double(out[i].stamp_ns), double(undisturbed[i]), 3e6 + 0.01 * 6e9) << "scan " << i;
  EXPECT_EQ(stamps.counts().clock_steps, 0u) << "a standing clock is not a step";
  EXPECT_EQ(stamps.counts().restamped, 0u);
  EXPECT_GE(stamps.counts().early, 50u);
}

TEST(ReceiveTimeStamps, ROSTimeSteppedForwardIsFollowedAndCounted) {
  Sequence sequence(300);
  for (int i = 100; i < 300; ++i) sequence.receipt_ns[i] += 5 * kSecond_ns;
  ReceiveTimeStamps stamps(kPeriod_ns);
  const std::vector<ReceiveTimeStamps::Stamp> out = sequence.stamp(stamps);
  expectIncreasing(out);
  EXPECT_EQ(stamps.counts().clock_steps, 1u);
  int step = -1;
  for (int i = 0; i < 300; ++i)
    if (out[i].clock_step) step = i;
  // Confirmed once the receipts kept the sensor's pace for 2 s off the mapping.
  EXPECT_GE(step, 100 + 20);
  EXPECT_LE(step, 100 + 22);
  for (int i = step; i < 300; ++i) EXPECT_LT(std::llabs(out[i].stamp_ns - sequence.receipt_ns[i]), 4'000'000);
}

TEST(ReceiveTimeStamps, ROSTimeSteppedBackAndABagLoopGoBack) {
  Sequence sequence(300);
  for (int i = 100; i < 300; ++i) sequence.receipt_ns[i] -= kSecond_ns / 2;  // host clock set back 0.5 s
  ReceiveTimeStamps stamps(kPeriod_ns);
  std::vector<ReceiveTimeStamps::Stamp> out = sequence.stamp(stamps);
  EXPECT_EQ(stamps.counts().clock_steps, 1u);
  EXPECT_EQ(stamps.counts().restamped, 0u) << "the step is taken as it is, not bridged";
  EXPECT_LT(std::llabs(out.back().stamp_ns - sequence.receipt_ns.back()), 4'000'000);

  // A bag loop: ROS time and the sensor clock both back to the start.
  const ReceiveTimeStamps::Stamp looped = stamps.next(sequence.receipt_ns[0], sequence.sensor_ns[0]);
  EXPECT_TRUE(looped.clock_step);
  EXPECT_EQ(looped.stamp_ns, sequence.receipt_ns[0]);
  // A sensor clock set to the epoch (PTP locked): a leap, taken at once.
  const ReceiveTimeStamps::Stamp leapt = stamps.next(sequence.receipt_ns[1], 1'700'000'000 * kSecond_ns);
  EXPECT_TRUE(leapt.clock_step);
  EXPECT_EQ(leapt.stamp_ns, sequence.receipt_ns[1]);
  // The nodelet restarts the sequence when it sees ROS time go back: no step.
  stamps.restart();
  EXPECT_FALSE(stamps.next(sequence.receipt_ns[0], sequence.sensor_ns[5]).clock_step);
  EXPECT_EQ(stamps.counts().clock_steps, 3u);
}

TEST(ReceiveTimeStamps, ASensorClockResetIsAStepAStandingOneFallsBackOnTheReceipts) {
  Sequence sequence(100);
  for (int i = 50; i < 100; ++i) sequence.sensor_ns[i] -= 3 * kSecond_ns;  // the sensor's clock reset
  ReceiveTimeStamps stamps(kPeriod_ns);
  const std::vector<ReceiveTimeStamps::Stamp> out = sequence.stamp(stamps);
  EXPECT_TRUE(out[50].clock_step);
  EXPECT_EQ(stamps.counts().clock_steps, 1u);
  expectIncreasing(out);
  for (int i = 50; i < 100; ++i) EXPECT_LT(std::llabs(out[i].stamp_ns - sequence.receipt_ns[i]), 4'000'000);

  // No sensor clock at all (every scan stamped 0): the receipts, kept increasing.
  ReceiveTimeStamps unclocked(kPeriod_ns);
  EXPECT_EQ(unclocked.next(5'000'000'000, 0).stamp_ns, 5'000'000'000);
  EXPECT_EQ(unclocked.next(5'100'000'000, 0).stamp_ns, 5'100'000'000);
  const ReceiveTimeStamps::Stamp lagging = unclocked.next(5'080'000'000, 0);  // ROS time 20 ms behind
  EXPECT_TRUE(lagging.repaired);
  EXPECT_EQ(lagging.stamp_ns, 5'100'000'000 + kPeriod_ns) << "the nominal period after the previous stamp";
  EXPECT_EQ(unclocked.counts().clock_steps, 0u);
  EXPECT_EQ(unclocked.counts().restamped, 1u);
}

TEST(ReceiveTimeStamps, ASensorClockDriftingAgainstROSTimeIsTracked) {
  // 200 ppm (a poor quartz's drift is tens): 10 minutes at 10 Hz.
  const Sequence sequence(6000, 200e-6);
  ReceiveTimeStamps stamps(kPeriod_ns);
  const std::vector<ReceiveTimeStamps::Stamp> out = sequence.stamp(stamps);
  expectIncreasing(out);
  for (std::size_t i = 0; i < out.size(); ++i)
    ASSERT_LT(std::llabs(out[i].stamp_ns - sequence.receipt_ns[i]), 4'000'000) << "scan " << i;
  EXPECT_EQ(stamps.counts().clock_steps + stamps.counts().restamped + stamps.counts().late + stamps.counts().early, 0u);
}

TEST(ReceiveTimeStamps, ANominalPeriodOutsideASecondIsRefused) {
  EXPECT_THROW(ReceiveTimeStamps(0), std::invalid_argument);
  EXPECT_THROW(ReceiveTimeStamps(1'000'000'000), std::invalid_argument);
}

}  // namespace
}  // namespace range_image_mapping
