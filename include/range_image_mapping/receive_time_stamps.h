// Scan stamps taken from the time a revolution's first packet was received,
// kept strictly increasing. ROS time can stand still between two revolutions:
// a bag replay's /clock is a topic like any other, and on a loaded machine its
// updates are delivered late, so two revolutions 0.1 s apart were both stamped
// with the same clock value and the Odometry refused the second as out of
// order. Such a scan is stamped the sensor clock's interval after the previous
// one instead, and counted, so that the cause can be named.
#pragma once

#include <cstddef>
#include <cstdint>

namespace range_image_mapping {

class ReceiveTimeStamps {
 public:
  // nominal_period_ns: the revolution period, used where the sensor clock's
  // interval is unusable (not positive, or a second or more).
  explicit ReceiveTimeStamps(int64_t nominal_period_ns);

  struct Stamp {
    int64_t stamp_ns = 0;
    bool repaired = false;  // the receive time did not advance past the previous stamp
  };
  // receipt_ns: ROS time of the revolution's first packet; sensor_ns: the
  // scan's stamp on the sensor's clock. A receipt a second or more behind the
  // previous stamp is ROS time going back (a bag loop): taken as it is.
  Stamp next(int64_t receipt_ns, int64_t sensor_ns);
  // A new sensor setting (metadata): the sequence goes on with another period.
  void setNominalPeriod(int64_t nominal_period_ns);
  // ROS time jumped back: the next receipt starts a new sequence.
  void restart() { has_previous_ = false; }
  std::size_t repaired() const { return repaired_; }

 private:
  static constexpr int64_t kLongestRepair_ns = 1'000'000'000;
  int64_t nominal_period_ns_;
  bool has_previous_ = false;
  int64_t previous_stamp_ns_ = 0;
  int64_t previous_sensor_ns_ = 0;
  std::size_t repaired_ = 0;
};

}  // namespace range_image_mapping
