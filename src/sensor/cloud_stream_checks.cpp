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
  const int rows = model.rows(), columns = model.columns();
  if (!cloud.isOrganized() || cloud.organized_height != rows || cloud.organized_width != columns ||
      cloud.size() != std::size_t(rows) * columns)
    return std::nullopt;
  const std::vector<int>& shifts = model.intrinsics().pixel_shift_by_row;
  if (shifts.empty() || std::all_of(shifts.begin(), shifts.end(), [&](int s) { return s == shifts[0]; }))
    return std::nullopt;
  // The angle between each point and its pixel's ray, under each order, over
  // a sample of the points (every 7th column of every row).
  std::vector<double> staggered_error, destaggered_error;
  const auto angleOffRay = [&](const Eigen::Vector3f& point, int column, int row) {
    const float range = model.direction(column, row).dot(point - model.offset(column, row));
    return double((model.unproject(column, row, range) - point).norm()) / double(point.norm());
  };
  for (int row = 0; row < rows; ++row) {
    const int shift = ((shifts[row] % columns) + columns) % columns;
    for (int input_column = 0; input_column < columns; input_column += 7) {
      const Eigen::Vector3f& point = cloud.points[std::size_t(row) * columns + input_column];
      if (!point.allFinite() || point.squaredNorm() < 1e-6f) continue;
      staggered_error.push_back(angleOffRay(point, input_column, row));
      destaggered_error.push_back(angleOffRay(point, (input_column - shift + columns) % columns, row));
    }
  }
  if (staggered_error.size() < 100) return std::nullopt;
  const auto median = [](std::vector<double>& values) {
    std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
    return values[values.size() / 2];
  };
  const double staggered = median(staggered_error), destaggered = median(destaggered_error);
  // The right order puts points on their rays (to the cloud's float rounding);
  // the wrong one several columns off them.
  constexpr double kOnRay = 1e-3;  // rad
  if (staggered < kOnRay && destaggered > 3 * staggered) return ColumnOrder::kStaggered;
  if (destaggered < kOnRay && staggered > 3 * destaggered) return ColumnOrder::kDestaggered;
  return std::nullopt;
}

}  // namespace range_image_mapping
