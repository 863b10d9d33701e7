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

// The row from the first guess of the beam origin is re-checked once the
// origin is known; a second change would need beams closer than r0 / range.
constexpr int kRowAttempts = 3;

// Points nearer the z axis than this many r0 are not projected: the series
// for the beam-origin correction need r0 / distance <= 1/4.
constexpr float kNearestAxisDistance = 4.0f;

// atan2 without the library call, as exact as float allows (3e-9 rad before
// rounding): fold the ratio into [0, 1], then past tan(15 deg) shift it by
// 30 deg with atan(t) = pi/6 + atan((sqrt(3) t - 1) / (t + sqrt(3))), and sum
// the Taylor series of atan up to t^11 on |t| <= tan(15 deg). Pixels on
// column borders then fall on the same side as with std::atan2.
inline float fastAtan2(float y, float x) {
  const float ax = std::abs(x), ay = std::abs(y);
  // 0 / tiny = 0 at the origin, without a branch that would stop vectorising.
  const float larger = std::max(std::max(ax, ay), std::numeric_limits<float>::min());
  const float ratio = std::min(ax, ay) / larger;
  constexpr float kSqrt3 = 1.7320508075688772f;
  constexpr float kTan15 = 0.2679491924311227f;
  const float shifted = (kSqrt3 * ratio - 1.0f) / (ratio + kSqrt3);
  // Selections as arithmetic, not branches: the signs and octants of real
  // scans change from point to point and would defeat the branch predictor.
  const float reduce = static_cast<float>(ratio > kTan15);
  const float t = ratio + reduce * (shifted - ratio);
  const float t2 = t * t;
  float angle = t * (1.0f + t2 * (-1.0f / 3 + t2 * (1.0f / 5 + t2 * (-1.0f / 7 +
                t2 * (1.0f / 9 + t2 * (-1.0f / 11))))));
  angle += reduce * static_cast<float>(M_PI / 6);
  const float swapped = static_cast<float>(ay > ax);   // angle -> pi/2 - angle
  angle += swapped * (static_cast<float>(M_PI / 2) - 2.0f * angle);
  const float behind = static_cast<float>(x < 0.0f);   // angle -> pi - angle
  angle += behind * (static_cast<float>(M_PI) - 2.0f * angle);
  return std::copysign(angle, y);
}

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

double LidarIntrinsics::medianRowSpacingRad() const {
  std::vector<double> spacing;
  for (std::size_t row = 1; row < altitude_rad.size(); ++row)
    spacing.push_back(std::abs(altitude_rad[row - 1] - altitude_rad[row]));
  if (spacing.empty()) return 0.0;
  std::nth_element(spacing.begin(), spacing.begin() + spacing.size() / 2, spacing.end());
  return spacing[spacing.size() / 2];
}

LidarModel::LidarModel(LidarIntrinsics intrinsics) : intrinsics_(std::move(intrinsics)) {
  intrinsics_.validate();
  const int rows = intrinsics_.rows;
  const int columns = intrinsics_.columns;
  if (intrinsics_.pixel_shift_by_row.empty()) intrinsics_.pixel_shift_by_row.assign(rows, 0);
  if (intrinsics_.column_window[1] < 0) intrinsics_.column_window = {0, columns - 1};

  column_per_radian_ = static_cast<float>(-columns / kTwoPi);
  const double radius = intrinsics_.beam_origin_radius_m;
  const double height = intrinsics_.beam_origin_z_m;
  // The beam origin lies at distance n from the lidar origin, and the sensor
  // reports ranges from the lidar origin's side: p = (r - n) d + origin.
  const double origin_norm = std::hypot(radius, height);
  beam_origin_radius_ = static_cast<float>(radius);
  beam_origin_z_ = static_cast<float>(height);
  beam_origin_norm_ = static_cast<float>(origin_norm);

  azimuth_offset_.assign(intrinsics_.azimuth_offset_rad.begin(), intrinsics_.azimuth_offset_rad.end());
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

  // Rank r covers [cell_bound_[r], cell_bound_[r + 1]); the outer bounds lie
  // beyond any sine so the neighbour check needs no range test.
  cell_bound_.assign(rows + 1, 0.0f);
  cell_bound_.front() = -2.0f;
  cell_bound_.back() = 2.0f;
  double smallest_gap = std::numeric_limits<double>::infinity();
  for (int rank = 1; rank < rows; ++rank) {
    cell_bound_[rank] = static_cast<float>(std::sin(0.5 * (sorted(rank - 1) + sorted(rank))));
    if (rank > 1) {
      const double gap = double(cell_bound_[rank]) - cell_bound_[rank - 1];
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
    while (rank + 1 < rows && centre >= cell_bound_[rank + 1]) ++rank;
    inverse_altitude_[bin] = rank;
  }
}

inline int LidarModel::nearestRow(float sin_altitude) const {
  if (!(sin_altitude >= accept_sin_low_ && sin_altitude <= accept_sin_high_)) return -1;
  const int last_bin = static_cast<int>(inverse_altitude_.size()) - 1;
  const int bin =
      std::min(last_bin, static_cast<int>((sin_altitude - accept_sin_low_) * table_bins_per_unit_));
  const int rank = inverse_altitude_[bin];
  // Neighbour check in altitude order (paper section 3.2), without branches:
  // which side of a midpoint a point falls is random from point to point.
  const int nearest = rank + (sin_altitude >= cell_bound_[rank + 1]) - (sin_altitude < cell_bound_[rank]);
  return rows_by_altitude_[nearest];
}

float LidarModel::columnOfEncoderAngle(float encoder_angle_rad) const {
  // theta_e = 2 pi - 2 pi u / W  =>  u = -theta_e W / (2 pi)  (mod W)
  const float columns = static_cast<float>(intrinsics_.columns);
  float u = encoder_angle_rad * column_per_radian_;
  if (u < -columns || u >= 2.0f * columns) u -= columns * std::floor(u / columns);  // rare: far outside
  u += columns * static_cast<float>(u < 0.0f);  // arithmetic: the sign is random per point
  u -= columns * static_cast<float>(u >= columns);
  return u;
}

std::optional<ProjectedPixel> LidarModel::project(const Eigen::Vector3f& point) const {
  return solveProjection(point, -1);
}

std::optional<ProjectedPixel> LidarModel::projectOnRow(const Eigen::Vector3f& point, int row) const {
  if (row < 0 || row >= intrinsics_.rows) return std::nullopt;
  return solveProjection(point, row);
}

// Paper section 3.2, with the r0 compensation solved in closed form. In the
// xy plane the beam starts at B = r0 e(theta_e) and runs along
// e(theta_e + theta_lut[v]) to the point P at azimuth alpha, distance rho.
// Crossing both sides with that direction gives
//   sin(alpha - theta_e - theta_lut[v]) = -r0 sin(theta_lut[v]) / rho,
// so theta_e = alpha - theta_lut[v] + delta with sin(delta) = r0 sin(theta_lut[v]) / rho.
// The row is found from the elevation of P - B; B depends on the row only
// through theta_lut, so one re-check of the row settles it.
namespace {

struct BeamOriginCorrection {
  float sin_delta;
  float ray_length;  // |P - B|
};

inline BeamOriginCorrection correctForBeamOrigin(float rho_squared, float rho, float dz, float r0,
                                                 float offset_cos, float offset_sin) {
  const float sin_delta = r0 * offset_sin / rho;
  const float sin_delta2 = sin_delta * sin_delta;
  const float cos_delta = 1.0f - sin_delta2 * (0.5f + 0.125f * sin_delta2);  // series, as asin below
  // cos(alpha - theta_e) = cos(theta_lut - delta)
  const float cos_point_to_origin = offset_cos * cos_delta + offset_sin * sin_delta;
  const float ray_length =
      std::sqrt(std::max(0.0f, rho_squared + r0 * r0 - 2.0f * r0 * rho * cos_point_to_origin + dz * dz));
  return {sin_delta, ray_length};
}

// asin by its series: |sin_delta| <= r0 / rho <= 1/4, where three terms are
// within 3e-6 rad (5e-9 rad below 0.1, i.e. beyond 10 r0).
inline float encoderAngleOf(float x, float y, float azimuth_offset, float sin_delta) {
  const float delta2 = sin_delta * sin_delta;
  const float delta = sin_delta * (1.0f + delta2 * (1.0f / 6.0f + delta2 * (3.0f / 40.0f)));
  return fastAtan2(y, x) - azimuth_offset + delta;
}

// Nearest column of an encoder angle within (-2 pi - 0.3, 2 pi + 0.3), the
// range encoderAngleOf returns; column_per_radian is -W / (2 pi).
inline int nearestColumn(float encoder_angle, float column_per_radian, float columns) {
  float u = encoder_angle * column_per_radian + 0.5f;
  // Arithmetic, as bit masks (the sign is random per point; a product with
  // the comparison would be a branch that keeps the loops from vectorising).
  u += zeroUnless(columns, int(u < 0.0f));
  u -= zeroUnless(columns, int(u >= columns));
  const int column = static_cast<int>(u);
  return column - static_cast<int>(columns) * (column >= static_cast<int>(columns));  // seam
}

}  // namespace

std::optional<ProjectedPixel> LidarModel::solveProjection(const Eigen::Vector3f& point,
                                                          int fixed_row) const {
  const float rho_squared = point.x() * point.x() + point.y() * point.y();
  if (!(rho_squared > 0.0f)) return std::nullopt;  // on the axis, or NaN
  const float rho = std::sqrt(rho_squared);
  // Inside the beam-origin circle, or so close that the series fail.
  if (rho <= kNearestAxisDistance * beam_origin_radius_) return std::nullopt;
  const float dz = point.z() - beam_origin_z_;
  const float r0 = beam_origin_radius_;
  int row = fixed_row;
  if (row < 0) {
    // First guess: the beam origin straight between the axis and the point.
    const float planar = rho - r0;
    row = nearestRow(dz / std::sqrt(planar * planar + dz * dz));
    if (row < 0) return std::nullopt;
  }
  BeamOriginCorrection correction{};
  for (int attempt = 0; attempt < kRowAttempts; ++attempt) {
    correction = correctForBeamOrigin(rho_squared, rho, dz, r0, azimuth_offset_cos_[row],
                                      azimuth_offset_sin_[row]);
    if (fixed_row >= 0 || r0 == 0.0f) break;
    const int better_row = nearestRow(dz / correction.ray_length);
    if (better_row < 0) return std::nullopt;
    if (better_row == row) break;
    row = better_row;
  }
  const float encoder_angle =
      encoderAngleOf(point.x(), point.y(), azimuth_offset_[row], correction.sin_delta);
  return ProjectedPixel{nearestColumn(encoder_angle, column_per_radian_, float(intrinsics_.columns)),
                        row, correction.ray_length + beam_origin_norm_};
}

// The same arithmetic as solveProjection, in passes over blocks of points so
// that the compiler vectorises the square roots, divisions and table look-ups
// (as gathers). A point whose row changes on the re-check (rare) takes the
// scalar path. Cloned for AVX2 and AVX-512 (eight or sixteen lanes instead of
// four; without FMA, so every operation rounds as in solveProjection and the
// pixels are the same).
RANGE_IMAGE_MAPPING_SIMD_CLONES
void LidarModel::projectMany(const float* x_all, const float* y_all, const float* z_all, std::size_t count,
                             ProjectedPixel* pixels, uint8_t* hits) const {
  constexpr std::size_t kBlock = 256;
  alignas(32) float rho_squared[kBlock], rho[kBlock], dz[kBlock];
  alignas(32) float sin_elevation[kBlock], offset_cos[kBlock], offset_sin[kBlock], offset[kBlock];
  alignas(32) float ray_length[kBlock], encoder_angle[kBlock], cell_low[kBlock], cell_high[kBlock];
  alignas(32) float range[kBlock];
  alignas(32) int row[kBlock], same_row[kBlock], column[kBlock];
  const int last_bin = static_cast<int>(inverse_altitude_.size()) - 1;
  const float r0 = beam_origin_radius_;
  const float nearest_rho = kNearestAxisDistance * r0;
  const float columns = static_cast<float>(intrinsics_.columns);
  for (std::size_t start = 0; start < count; start += kBlock) {
    const std::size_t n = std::min(kBlock, count - start);
    const float* x = x_all + start;
    const float* y = y_all + start;
    const float* z = z_all + start;
    for (std::size_t i = 0; i < n; ++i) {  // vectorised
      dz[i] = z[i] - beam_origin_z_;
      rho_squared[i] = x[i] * x[i] + y[i] * y[i];
      rho[i] = std::sqrt(rho_squared[i]);
      const float planar = rho[i] - r0;
      sin_elevation[i] = dz[i] / std::sqrt(planar * planar + dz[i] * dz[i]);
    }
    // nearestRow, and the tables of the row found. Conditions combine as
    // integers and bit masks, not with && or ?: (branches and selects the
    // vectoriser does not take).
    for (std::size_t i = 0; i < n; ++i) {  // vectorised
      const float sine = sin_elevation[i];
      const int usable = int(rho_squared[i] > 0.0f) & int(rho[i] > nearest_rho) & int(sine >= accept_sin_low_) &
                         int(sine <= accept_sin_high_);  // 0 for NaN
      // The table position where usable, else 0 (never NaN or out of range).
      const float position = zeroUnless((sine - accept_sin_low_) * table_bins_per_unit_, usable);
      const int rank = inverse_altitude_[std::min(static_cast<int>(position), last_bin)];
      const int nearest = rank + int(sine >= cell_bound_[rank + 1]) - int(sine < cell_bound_[rank]);
      const int table_row = rows_by_altitude_[nearest] * usable;
      row[i] = (table_row + 1) * usable - 1;  // -1 unless usable
      cell_low[i] = cell_bound_[nearest];
      cell_high[i] = cell_bound_[nearest + 1];
      offset_cos[i] = azimuth_offset_cos_[table_row];
      offset_sin[i] = azimuth_offset_sin_[table_row];
      offset[i] = azimuth_offset_[table_row];
    }
    for (std::size_t i = 0; i < n; ++i) {  // vectorised
      const BeamOriginCorrection correction =
          correctForBeamOrigin(rho_squared[i], rho[i], dz[i], r0, offset_cos[i], offset_sin[i]);
      ray_length[i] = correction.ray_length;
      encoder_angle[i] = encoderAngleOf(x[i], y[i], offset[i], correction.sin_delta);
      // The re-check of the row: nearestRow of the new elevation is this row
      // exactly when the elevation is within the accepted band and this row's cell.
      const float sine = dz[i] / correction.ray_length;
      same_row[i] = int(r0 == 0.0f) | (int(sine >= accept_sin_low_) & int(sine <= accept_sin_high_) &
                                       int(sine >= cell_low[i]) & int(sine < cell_high[i]));
    }
    // The pixels of the points kept (the angle of the others, possibly NaN
    // or far out of range, is not converted).
    int all_kept = 1;
    for (std::size_t i = 0; i < n; ++i) {  // vectorised
      const int kept = int(row[i] >= 0) & same_row[i];
      all_kept &= kept;
      column[i] = nearestColumn(zeroUnless(encoder_angle[i], kept), column_per_radian_, columns);
      range[i] = ray_length[i] + beam_origin_norm_;
    }
    if (all_kept) {  // the usual case: every point hits, on the row first found
      for (std::size_t i = 0; i < n; ++i) {
        hits[start + i] = 1;
        pixels[start + i] = {column[i], row[i], range[i]};
      }
      continue;
    }
    for (std::size_t i = 0; i < n; ++i) {
      if (row[i] < 0) {
        hits[start + i] = 0;
        continue;
      }
      if (!same_row[i]) {
        const std::optional<ProjectedPixel> pixel = solveProjection(Eigen::Vector3f(x[i], y[i], z[i]), -1);
        hits[start + i] = pixel.has_value();
        if (pixel) pixels[start + i] = *pixel;
        continue;
      }
      hits[start + i] = 1;
      pixels[start + i] = {column[i], row[i], range[i]};
    }
  }
}

void LidarModel::projectMany(const Eigen::Vector3f* points, std::size_t count, ProjectedPixel* pixels,
                             uint8_t* hits) const {
  constexpr std::size_t kChunk = 256;
  float x[kChunk], y[kChunk], z[kChunk];
  for (std::size_t start = 0; start < count; start += kChunk) {
    const std::size_t n = std::min(kChunk, count - start);
    for (std::size_t i = 0; i < n; ++i) {
      x[i] = points[start + i].x();
      y[i] = points[start + i].y();
      z[i] = points[start + i].z();
    }
    projectMany(x, y, z, n, pixels + start, hits + start);
  }
}

}  // namespace range_image_mapping
