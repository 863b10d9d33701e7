// Scan stamps on ROS time for a sensor whose clock is not synchronised to it
// (stamp_source receive_time): the sensor clock mapped onto ROS time,
//   stamp = sensor time + offset,
// where the offset (ROS time minus sensor time) follows the receipt of each
// revolution's first packet. Against a running ROS clock a receipt can only be
// late: a process that stalled (heavy load, a paused machine) reads its
// backlog at once, and the receipts would stamp scans 0.1 s apart within
// milliseconds of each other. It is early only when ROS time itself lags (a
// bag's /clock delivered late). So the offset moves towards a receipt by at
// most kDriftRate of the sensor time passed (1 %, far beyond any quartz
// clock's drift), and a late or early receipt shifts the stamps by at most
// that much. Two cases re-anchor the offset to the receipt, counted as clock
// steps: the sensor clock went back or leapt ahead of the receipts, or the
// receipts stayed more than kStep off the mapping while keeping the sensor
// clock's pace for kStepConfirm (ROS time was stepped). Stamps are kept
// strictly increasing: a stamp that would not advance (a sensor clock that
// stands still, so the receipts are all there is) is put the sensor clock's
// interval, or the nominal period, after the previous one, and counted as
// repaired.
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
    int64_t receipt_delay_ns = 0;  // receipt minus the mapped sensor time: how late the scan was read
    bool repaired = false;         // the mapped stamp did not advance past the previous one
    bool clock_step = false;       // the offset was set anew (not on the first scan)
  };
  // receipt_ns: ROS time of the revolution's first packet; sensor_ns: the
  // scan's stamp on the sensor's clock. A stamp a second or more behind the
  // previous one is ROS time going back (a bag loop): taken as it is.
  Stamp next(int64_t receipt_ns, int64_t sensor_ns);
  // A new sensor setting (metadata): the sequence goes on with another period.
  void setNominalPeriod(int64_t nominal_period_ns);
  // ROS time jumped back: the next receipt starts a new sequence.
  void restart() { has_previous_ = false; }
  struct Counts {
    std::size_t restamped = 0;    // stamps repaired to keep them increasing
    std::size_t clock_steps = 0;  // offsets set anew
    // Scans read kLateReceipt or more after the mapping says they were sent
    // (a stall or a backlog), and kEarlyReceipt or more before it (ROS time
    // stood still or lagged: a late /clock).
    std::size_t late = 0, early = 0;
  };
  const Counts& counts() const { return counts_; }

  static constexpr double kDriftRate = 0.01;
  static constexpr int64_t kStep_ns = 250'000'000;
  static constexpr int64_t kStepConfirm_ns = 2'000'000'000;
  static constexpr int64_t kLateReceipt_ns = 500'000'000;
  static constexpr int64_t kEarlyReceipt_ns = 50'000'000;

 private:
  static constexpr int64_t kLongestRepair_ns = 1'000'000'000;
  void anchor(int64_t receipt_ns, int64_t sensor_ns);

  int64_t nominal_period_ns_;
  bool has_previous_ = false;
  int64_t offset_ns_ = 0;
  int64_t previous_stamp_ns_ = 0;
  int64_t previous_sensor_ns_ = 0;
  int64_t previous_receipt_ns_ = 0;
  int64_t step_evidence_ns_ = 0;  // sensor time over which the receipts kept pace kStep away
  Counts counts_;
};

}  // namespace range_image_mapping
