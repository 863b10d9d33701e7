#include "range_image_mapping/receive_time_stamps.h"

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

ReceiveTimeStamps::Stamp ReceiveTimeStamps::next(int64_t receipt_ns, int64_t sensor_ns) {
  Stamp stamp{receipt_ns, false};
  if (has_previous_ && receipt_ns <= previous_stamp_ns_ &&
      previous_stamp_ns_ - receipt_ns < kLongestRepair_ns) {
    const int64_t sensor_interval_ns = sensor_ns - previous_sensor_ns_;
    const bool usable = sensor_interval_ns > 0 && sensor_interval_ns < kLongestRepair_ns;
    stamp = {previous_stamp_ns_ + (usable ? sensor_interval_ns : nominal_period_ns_), true};
    ++repaired_;
  }
  has_previous_ = true;
  previous_stamp_ns_ = stamp.stamp_ns;
  previous_sensor_ns_ = sensor_ns;
  return stamp;
}

}  // namespace range_image_mapping
