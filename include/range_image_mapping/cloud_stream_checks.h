// Checks of a stream of point clouds against what the settings say about it,
// so that a wrong setting is reported rather than silently costing accuracy:
// clouds missing from the stream (seen in the stamps: clouds carry no frame
// counter), and whether an organized cloud's columns are destaggered.
#pragma once

#include "range_image_mapping/point_cloud_projection.h"

#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>

namespace range_image_mapping {

// Counts clouds missing between consecutive stamps: a gap of more than 1.5
// periods holds round(gap / period) - 1 missing clouds. The period is the
// median of the recent gaps, so it follows the sensor's rate (5-20 Hz)
// without a setting; a stamp going back (a bag loop) starts over.
class CloudGapCounter {
 public:
  // The clouds missing just before this one.
  std::size_t add(uint64_t stamp_ns);
  std::size_t missing() const { return missing_; }
  // Clouds stamped less than half a period after the previous one: stamps
  // that jitter (a driver stamping with the receive time, e.g. ouster-ros
  // timestamp_mode TIME_FROM_ROS_TIME), not the sensor's rate.
  std::size_t early() const { return early_; }
  // Median of the recent gaps; 0 until three gaps were seen.
  double periodSeconds() const;

 private:
  static constexpr std::size_t kGapWindow = 15;
  std::deque<double> recent_gaps_s_;
  uint64_t last_stamp_ns_ = 0;
  bool has_last_ = false;
  std::size_t missing_ = 0;
  std::size_t early_ = 0;
};

// Which column order an organized cloud of the model's H x W has, from its
// points: each point lies on its pixel's ray only in the right order (a
// wrong order puts it pixel_shift_by_row columns away). Nothing when the
// model's rows share one shift (the orders are the same), when the cloud has
// too few points to tell, or when neither order fits (another model).
std::optional<ColumnOrder> detectOrganizedColumnOrder(const PointCloudInput& cloud, const LidarModel& model);

}  // namespace range_image_mapping
