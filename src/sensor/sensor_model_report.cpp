#include "range_image_mapping/sensor_model_report.h"

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>

namespace range_image_mapping {
namespace {

std::string format(const char* pattern, ...) __attribute__((format(printf, 1, 2)));
std::string format(const char* pattern, ...) {
  char buffer[1024];
  va_list arguments;
  va_start(arguments, pattern);
  std::vsnprintf(buffer, sizeof buffer, pattern, arguments);
  va_end(arguments);
  return buffer;
}

// The warning for a model that keeps `kept` of `measured` points, with the
// shares lost outside its field of view and to shared pixels: the larger loss
// says what is wrong.
std::optional<std::string> lossWarning(double kept, double outside, double shared, const std::string& fix) {
  if (kept >= kMinimumKeptShare) return std::nullopt;
  const std::string cause =
      outside >= shared ? "most of the loss is outside its field of view: a different sensor (beams, field of view) "
                          "or the clouds are not in the sensor's frame"
                        : "most of the loss is to points sharing a pixel: too few columns, or beams the model merges";
  return format("the sensor model explains only %.1f %% of the points (under %.0f %%: %.1f %% outside the field of "
                "view, %.1f %% lost to a nearer point in the same pixel); %s. Fix: %s",
                100.0 * kept, 100.0 * kMinimumKeptShare, 100.0 * outside, 100.0 * shared, cause.c_str(),
                fix.c_str());
}

}  // namespace

std::string describeSensorModel(const LidarIntrinsics& intrinsics) {
  double highest = -90.0, lowest = 90.0;
  for (const double altitude : intrinsics.altitude_rad) {
    highest = std::max(highest, altitude * 180.0 / M_PI);
    lowest = std::min(lowest, altitude * 180.0 / M_PI);
  }
  return format("%d beams from %+.2f to %+.2f deg, %d columns (%.4f deg), beam origin %.1f mm from the axis and "
                "%.1f mm up",
                intrinsics.rows, highest, lowest, intrinsics.columns, 360.0 / std::max(intrinsics.columns, 1),
                intrinsics.beam_origin_radius_m * 1e3, intrinsics.beam_origin_z_m * 1e3);
}

std::string describeSensorModelFit(const SensorModelFit& fit) {
  return format("%zu clouds, %zu measured points: %.2f %% kept, %.2f %% outside the field of view, %.2f %% lost to "
                "a nearer point in the same pixel; residual %.4f deg in elevation, %.4f deg in azimuth (RMS)",
                fit.scans, fit.measured_points, 100.0 * fit.keptShare(), 100.0 * fit.outsideShare(),
                100.0 * fit.occludedShare(), fit.elevation_residual_deg, fit.azimuth_residual_deg);
}

std::string describeSensorEstimate(const SensorEstimate& estimate) {
  return describeSensorModel(estimate.intrinsics) +
         (estimate.ring_to_row.empty() ? "" : ", rows from the ring field") + "; " +
         describeSensorModelFit(estimate.fit);
}

std::optional<std::string> sensorModelFitWarning(const SensorModelFit& fit, const std::string& fix) {
  if (fit.measured_points == 0) return std::nullopt;
  return lossWarning(fit.keptShare(), fit.outsideShare(), fit.occludedShare(), fix);
}

std::optional<std::string> projectionWarning(const ProjectionStatistics& statistics, const std::string& fix) {
  const std::size_t measured = statistics.measured();
  if (measured == 0) return std::nullopt;
  return lossWarning(statistics.keptFraction(), double(statistics.outside_model) / double(measured),
                     double(statistics.occluded) / double(measured), fix);
}

}  // namespace range_image_mapping
