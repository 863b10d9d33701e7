#include "range_image_mapping/receive_time_stamps.h"

#include <algorithm>
#include <cstdlib>
#include <stdexcept>
#include <string>

namespace range_image_mapping {

ReceiveTimeStamps::ReceiveTimeStamps(int64_t nominal_period_ns) { setNominalPeriod(nominal_period_ns); }

void ReceiveTimeStamps::setNominalPeriod(int64_t nominal_period_ns) {
  if (nominal_period_ns <= 0 || nominal_period_ns >= kLongestRepair_ns)
    throw std::invalid_argument("ReceiveTimeStamps: the nominal period must lie in (0, 1) s, got " +
                                std::to_string(nominal_period_ns) + " ns");
  nominal_period_ns_ = nominal_period_ns;
}

void ReceiveTimeStamps::anchor(int64_t receipt_ns, int64_t sensor_ns) {
  offset_ns_ = receipt_ns - sensor_ns;
  step_evidence_ns_ = 0;
}

ReceiveTimeStamps::Stamp ReceiveTimeStamps::next(int64_t receipt_ns, int64_t sensor_ns) {
  Stamp stamp;
  const int64_t sensor_interval_ns = sensor_ns - previous_sensor_ns_;
  if (!has_previous_ || sensor_interval_ns == 0) {
    // The first scan, or a sensor clock that stands still (unset): the receipt.
    anchor(receipt_ns, sensor_ns);
  } else {
    const int64_t excess_ns = receipt_ns - sensor_ns - offset_ns_;  // > 0: read late; < 0: ROS time behind
    stamp.receipt_delay_ns = excess_ns;
    const int64_t receipt_interval_ns = receipt_ns - previous_receipt_ns_;
    const bool keeps_pace =
        std::llabs(receipt_interval_ns - sensor_interval_ns) <= std::llabs(sensor_interval_ns) / 4;
    const bool off_at_pace = std::llabs(excess_ns) > kStep_ns && keeps_pace && sensor_interval_ns > 0;
    step_evidence_ns_ = off_at_pace ? step_evidence_ns_ + sensor_interval_ns : 0;
    // A sensor clock that went back or leapt (seconds that the receipts did
    // not keep pace with), or receipts off the mapping at the sensor's pace
    // for kStepConfirm: a clock step. Receipts far off the mapping but not at
    // the sensor's pace are a stall, a backlog or a standing /clock.
    const bool sensor_leapt = sensor_interval_ns >= kLongestRepair_ns && !keeps_pace;
    if (sensor_interval_ns < 0 || sensor_leapt || step_evidence_ns_ >= kStepConfirm_ns) {
      anchor(receipt_ns, sensor_ns);
      stamp.clock_step = true;
      ++counts_.clock_steps;
    } else {
      const auto limit_ns =
          static_cast<int64_t>(kDriftRate * static_cast<double>(std::min(sensor_interval_ns, kLongestRepair_ns)));
      offset_ns_ += std::clamp(excess_ns, -limit_ns, limit_ns);
      if (excess_ns >= kLateReceipt_ns) ++counts_.late;
      if (excess_ns <= -kEarlyReceipt_ns) ++counts_.early;
    }
  }
  stamp.stamp_ns = sensor_ns + offset_ns_;
  // Kept increasing, except across a clock step or ROS time going back a
  // second or more (a bag loop), which downstream nodes see as time going back.
  if (has_previous_ && !stamp.clock_step && stamp.stamp_ns <= previous_stamp_ns_ &&
      previous_stamp_ns_ - stamp.stamp_ns < kLongestRepair_ns) {
    const bool usable = sensor_interval_ns > 0 && sensor_interval_ns < kLongestRepair_ns;
    stamp.stamp_ns = previous_stamp_ns_ + (usable ? sensor_interval_ns : nominal_period_ns_);
    stamp.repaired = true;
    ++counts_.restamped;
  }
  has_previous_ = true;
  previous_stamp_ns_ = stamp.stamp_ns;
  previous_sensor_ns_ = sensor_ns;
  previous_receipt_ns_ = receipt_ns;
  return stamp;
}

}  // namespace range_image_mapping
