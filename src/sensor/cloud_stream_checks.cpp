#include "range_image_mapping/cloud_stream_checks.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace range_image_mapping {

std::size_t CloudGapCounter::add(uint64_t stamp_ns) {
  if (has_last_ && stamp_ns <= last_stamp_ns_) {
    // Time went back (a bag loop) or stood still: the stream starts over.
    if (stamp_ns < last_stamp_ns_) recent_gaps_s_.clear();
    last_stamp_ns_ = stamp_ns;
    return 0;
  }
  std::size_t missing_here = 0;
  if (has_last_) {
    const double gap_s = double(stamp_ns - last_stamp_ns_) * 1e-9;
    const double period_s = periodSeconds();
    if (period_s > 0.0 && gap_s < 0.5 * period_s) ++early_;
    if (period_s > 0.0 && gap_s > 1.5 * period_s)
      missing_here = std::max<std::size_t>(1, static_cast<std::size_t>(std::lround(gap_s / period_s)) - 1);
    else {
      recent_gaps_s_.push_back(gap_s);  // a gap with missing clouds does not change the period
      if (recent_gaps_s_.size() > kGapWindow) recent_gaps_s_.pop_front();
    }
  }
  has_last_ = true;
  last_stamp_ns_ = stamp_ns;
  missing_ += missing_here;
  return missing_here;
}

double CloudGapCounter::periodSeconds() const {
  if (recent_gaps_s_.size() < 3) return 0.0;
  std::vector<double> gaps(recent_gaps_s_.begin(), recent_gaps_s_.end());
  std::nth_element(gaps.begin(), gaps.begin() + gaps.size() / 2, gaps.end());
  return gaps[gaps.size() / 2];
}

std::optional<ColumnOrder> detectOrganizedColumnOrder(const PointCloudInput& cloud, const LidarModel& model) {
  const std::vector<int>& shifts = model.intrinsics().pixel_shift_by_row;
  if (shifts.empty() || std::all_of(shifts.begin(), shifts.end(), [&](int s) { return s == shifts[0]; }))
    return std::nullopt;
  const double staggered = organizedOffRayAngle(cloud, model, ColumnOrder::kStaggered);
  const double destaggered = organizedOffRayAngle(cloud, model, ColumnOrder::kDestaggered);
  if (!std::isfinite(staggered) || !std::isfinite(destaggered)) return std::nullopt;
  // The right order puts points on their rays (to the cloud's float rounding);
  // the wrong one several columns off them.
  constexpr double kOnRay = 1e-3;  // rad
  if (staggered < kOnRay && destaggered > 3 * staggered) return ColumnOrder::kStaggered;
  if (destaggered < kOnRay && staggered > 3 * destaggered) return ColumnOrder::kDestaggered;
  return std::nullopt;
}

}  // namespace range_image_mapping
