#include "range_image_mapping/lidar_intrinsics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <sstream>

namespace range_image_mapping {
namespace {

constexpr double kTwoPi = 2.0 * M_PI;

[[noreturn]] void fail(const std::string& field, const std::string& problem) {
  throw IntrinsicsError("lidar intrinsics: " + field + " " + problem);
}

// Encoder angle of column u: column 0 looks along +x and the azimuth
// decreases as u grows (Ouster lidar frame; paper eq. 2 up to that sign).
double encoderAngle(int column, int columns) { return kTwoPi - kTwoPi * column / columns; }

// Fewer iterations than this always converge for points farther than a few r0
// from the axis: each one shrinks the azimuth error by about r0 / distance.
constexpr int kBeamOriginIterations = 3;

}  // namespace

void LidarIntrinsics::validate() const {
  if (rows <= 0) fail("rows", "must be positive, got " + std::to_string(rows));
  if (columns <= 0) fail("columns", "must be positive, got " + std::to_string(columns));
  const auto check_table = [&](const std::vector<double>& table, const std::string& name,
                               double limit) {
    if (static_cast<int>(table.size()) != rows)
      fail(name, "has " + std::to_string(table.size()) + " entries, rows is " + std::to_string(rows));
    for (std::size_t v = 0; v < table.size(); ++v)
      if (!std::isfinite(table[v]) || std::abs(table[v]) > limit)
        fail(name, "entry " + std::to_string(v) + " is out of range");
  };
  check_table(altitude_rad, "altitude_rad", M_PI / 2);
  check_table(azimuth_offset_rad, "azimuth_offset_rad", M_PI);
  if (!pixel_shift_by_row.empty() && static_cast<int>(pixel_shift_by_row.size()) != rows)
    fail("pixel_shift_by_row", "has " + std::to_string(pixel_shift_by_row.size()) +
                                   " entries, rows is " + std::to_string(rows));
  if (!std::isfinite(beam_origin_radius_m) || beam_origin_radius_m < 0 || beam_origin_radius_m > 1)
    fail("beam_origin_radius_m", "must be within [0, 1] m");
  if (!std::isfinite(beam_origin_z_m) || std::abs(beam_origin_z_m) > 1)
    fail("beam_origin_z_m", "must be within [-1, 1] m");
  if (!lidar_to_sensor.matrix().allFinite()) fail("lidar_to_sensor", "is not finite");
  const bool full_window = column_window[0] == 0 && column_window[1] == -1;
  if (!full_window && (column_window[0] < 0 || column_window[0] >= columns ||
                       column_window[1] < 0 || column_window[1] >= columns))
    fail("column_window", "must lie within [0, " + std::to_string(columns - 1) + "]");
}

LidarIntrinsics LidarIntrinsics::synthetic(int rows, int columns, double fov_up_rad,
                                           double fov_down_rad) {
  if (rows <= 0 || columns <= 0) fail("rows/columns", "must be positive for synthetic intrinsics");
  if (!(fov_up_rad > fov_down_rad)) fail("fov_up", "must be above fov_down");
  LidarIntrinsics intrinsics;
  intrinsics.rows = rows;
  intrinsics.columns = columns;
  intrinsics.altitude_rad.resize(rows);
  // Beam centres spread evenly from fov_up (row 0) down to fov_down (last row).
  const double step = rows > 1 ? (fov_up_rad - fov_down_rad) / (rows - 1) : 0.0;
  for (int v = 0; v < rows; ++v) intrinsics.altitude_rad[v] = fov_up_rad - v * step;
  intrinsics.azimuth_offset_rad.assign(rows, 0.0);
  intrinsics.pixel_shift_by_row.assign(rows, 0);
  intrinsics.sensor_model = "synthetic";
  intrinsics.validate();
  return intrinsics;
}

bool LidarIntrinsics::columnInWindow(int column) const {
  const int first = column_window[0];
  const int last = column_window[1] < 0 ? columns - 1 : column_window[1];
  return first <= last ? (column >= first && column <= last) : (column >= first || column <= last);
}

int LidarIntrinsics::columnWindowWidth() const {
  const int first = column_window[0];
  const int last = column_window[1] < 0 ? columns - 1 : column_window[1];
  return first <= last ? last - first + 1 : columns - first + last + 1;
}

LidarModel::LidarModel(LidarIntrinsics intrinsics) : intrinsics_(std::move(intrinsics)) {
  intrinsics_.validate();
  const int rows = intrinsics_.rows;
  const int columns = intrinsics_.columns;
  if (intrinsics_.pixel_shift_by_row.empty()) intrinsics_.pixel_shift_by_row.assign(rows, 0);
  if (intrinsics_.column_window[1] < 0) intrinsics_.column_window = {0, columns - 1};

  const double radius = intrinsics_.beam_origin_radius_m;
  const double height = intrinsics_.beam_origin_z_m;
  // The beam origin lies at distance n from the lidar origin, and the sensor
  // reports ranges from the lidar origin's side: p = (r - n) d + origin.
  const double origin_norm = std::hypot(radius, height);
  beam_origin_radius_ = static_cast<float>(radius);
  beam_origin_z_ = static_cast<float>(height);
  beam_origin_norm_ = static_cast<float>(origin_norm);

  azimuth_offset_cos_.resize(rows);
  azimuth_offset_sin_.resize(rows);
  for (int v = 0; v < rows; ++v) {
    azimuth_offset_cos_[v] = static_cast<float>(std::cos(intrinsics_.azimuth_offset_rad[v]));
    azimuth_offset_sin_[v] = static_cast<float>(std::sin(intrinsics_.azimuth_offset_rad[v]));
  }

  // Per-pixel tables of Pi^-1 (paper eq. 1-2, linear in r).
  direction_.resize(static_cast<std::size_t>(rows) * columns);
  offset_.resize(direction_.size());
  for (int v = 0; v < rows; ++v) {
    const double phi = intrinsics_.altitude_rad[v];
    for (int u = 0; u < columns; ++u) {
      const double theta_e = encoderAngle(u, columns);
      const double theta = theta_e + intrinsics_.azimuth_offset_rad[v];
      const Eigen::Vector3d d(std::cos(theta) * std::cos(phi), std::sin(theta) * std::cos(phi),
                              std::sin(phi));
      const Eigen::Vector3d origin(radius * std::cos(theta_e), radius * std::sin(theta_e), height);
      const std::size_t i = static_cast<std::size_t>(v) * columns + u;
      direction_[i] = d.cast<float>();
      offset_[i] = (origin - origin_norm * d).cast<float>();
    }
  }
  buildInverseAltitudeTable();
}

// Inverse altitude LUT over sin(altitude), so the projection needs no asin.
// "Nearest beam" means nearest in angle (paper section 3.2), decided against
// the sines of the angular midpoints between neighbouring beams. Bins are at
// most a quarter of the smallest gap between midpoints wide: an elevation and
// its bin's centre are then never more than one midpoint apart, so the bin's
// beam or its neighbour in altitude order is the nearest one.
void LidarModel::buildInverseAltitudeTable() {
  const int rows = intrinsics_.rows;
  const auto& altitude = intrinsics_.altitude_rad;
  rows_by_altitude_.resize(rows);
  std::iota(rows_by_altitude_.begin(), rows_by_altitude_.end(), 0);
  std::stable_sort(rows_by_altitude_.begin(), rows_by_altitude_.end(),
                   [&](int a, int b) { return altitude[a] < altitude[b]; });
  const auto sorted = [&](int rank) { return altitude[rows_by_altitude_[rank]]; };

  sin_midpoint_above_.resize(std::max(rows - 1, 0));
  double smallest_gap = std::numeric_limits<double>::infinity();
  for (int rank = 0; rank + 1 < rows; ++rank) {
    sin_midpoint_above_[rank] = static_cast<float>(std::sin(0.5 * (sorted(rank) + sorted(rank + 1))));
    if (rank > 0) {
      const double gap = double(sin_midpoint_above_[rank]) - sin_midpoint_above_[rank - 1];
      if (gap > 1e-9) smallest_gap = std::min(smallest_gap, gap);
    }
  }
  // Points count as seen up to half a beam spacing beyond the outermost beams
  // (a single beam sees +-0.5 deg).
  const double low_spacing = rows > 1 ? sorted(1) - sorted(0) : M_PI / 180.0;
  const double high_spacing = rows > 1 ? sorted(rows - 1) - sorted(rows - 2) : M_PI / 180.0;
  const double accept_low = std::max(-M_PI / 2, sorted(0) - 0.5 * low_spacing);
  const double accept_high = std::min(M_PI / 2, sorted(rows - 1) + 0.5 * high_spacing);
  accept_sin_low_ = static_cast<float>(std::sin(accept_low));
  accept_sin_high_ = static_cast<float>(std::sin(accept_high));
  const double span = double(accept_sin_high_) - accept_sin_low_;
  if (!std::isfinite(smallest_gap)) smallest_gap = span;

  constexpr std::size_t kMaximumBins = std::size_t(1) << 20;
  const std::size_t bins = std::clamp<std::size_t>(
      static_cast<std::size_t>(std::ceil(span / (0.25 * smallest_gap))) + 1, 2 * std::size_t(rows),
      kMaximumBins);
  inverse_altitude_.resize(bins);
  table_bins_per_unit_ = static_cast<float>(bins / span);
  int rank = 0;
  for (std::size_t bin = 0; bin < bins; ++bin) {
    const double centre = accept_sin_low_ + (bin + 0.5) / table_bins_per_unit_;
    while (rank + 1 < rows && centre > sin_midpoint_above_[rank]) ++rank;
    inverse_altitude_[bin] = static_cast<int16_t>(rank);
  }
}

int LidarModel::nearestRow(float sin_altitude) const {
  if (!(sin_altitude >= accept_sin_low_ && sin_altitude <= accept_sin_high_)) return -1;
  const int last_bin = static_cast<int>(inverse_altitude_.size()) - 1;
  const int bin =
      std::min(last_bin, static_cast<int>((sin_altitude - accept_sin_low_) * table_bins_per_unit_));
  int rank = inverse_altitude_[bin];
  // Neighbour check in altitude order (paper section 3.2).
  if (rank > 0 && sin_altitude < sin_midpoint_above_[rank - 1]) --rank;
  else if (rank + 1 < intrinsics_.rows && sin_altitude > sin_midpoint_above_[rank]) ++rank;
  return rows_by_altitude_[rank];
}

float LidarModel::columnOfEncoderAngle(float encoder_angle_rad) const {
  // theta_e = 2 pi - 2 pi u / W  =>  u = -theta_e W / (2 pi)  (mod W)
  const float columns = static_cast<float>(intrinsics_.columns);
  float u = -encoder_angle_rad * columns / static_cast<float>(kTwoPi);
  u -= columns * std::floor(u / columns);
  return u >= columns ? u - columns : u;
}

std::optional<ProjectedPixel> LidarModel::project(const Eigen::Vector3f& point) const {
  // Paper section 3.2: estimate the encoder angle, remove the beam origin it
  // implies, and repeat; cos/sin come from normalised vectors, not trig calls.
  float planar = std::hypot(point.x(), point.y());
  if (!(planar > 0.0f)) return std::nullopt;
  float encoder_cos = point.x() / planar;  // first guess: no r0, no theta_lut
  float encoder_sin = point.y() / planar;
  Eigen::Vector3f ray;
  float ray_length = 0.0f;
  int row = -1;
  for (int iteration = 0; iteration < kBeamOriginIterations; ++iteration) {
    ray = point - Eigen::Vector3f(beam_origin_radius_ * encoder_cos, beam_origin_radius_ * encoder_sin,
                                  beam_origin_z_);
    ray_length = ray.norm();
    planar = std::hypot(ray.x(), ray.y());
    if (!(planar > 0.0f)) return std::nullopt;
    row = nearestRow(ray.z() / ray_length);
    if (row < 0) return std::nullopt;
    // Encoder direction = ray azimuth rotated back by theta_lut[row] (eq. 2).
    const float ray_cos = ray.x() / planar, ray_sin = ray.y() / planar;
    const float c = azimuth_offset_cos_[row], s = azimuth_offset_sin_[row];
    encoder_cos = ray_cos * c + ray_sin * s;
    encoder_sin = ray_sin * c - ray_cos * s;
    if (beam_origin_radius_ == 0.0f) break;  // no origin offset: one pass is exact
  }
  const float u = columnOfEncoderAngle(std::atan2(encoder_sin, encoder_cos));
  int column = static_cast<int>(std::lround(u));
  if (column >= intrinsics_.columns) column -= intrinsics_.columns;  // seam
  return ProjectedPixel{column, row, ray_length + beam_origin_norm_};
}

}  // namespace range_image_mapping
