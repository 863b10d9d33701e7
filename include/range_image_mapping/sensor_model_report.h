// How well a sensor model explains a sensor's clouds, told to people: one line
// for the log (rim, the Adapter) and, when the model explains too little, the
// warning that names the problem and the fix.
#pragma once

#include "range_image_mapping/point_cloud_projection.h"
#include "range_image_mapping/sensor_model_estimation.h"

#include <optional>
#include <string>

namespace range_image_mapping {

// Under this share of kept points a model does not explain the data (issue 14: 95 %).
constexpr double kMinimumKeptShare = 0.95;

// "64 beams from +2.0 to -24.9 deg, 4000 columns (azimuth step 0.0900 deg), beam origin 2.0 mm from the axis and
// 215.0 mm up"
std::string describeSensorModel(const LidarIntrinsics& intrinsics);
// "3 clouds, 360000 measured points: 97.70 % kept, 0.10 % outside the field of view, 2.20 % lost to a nearer point
// in the same pixel; residual 0.0300 deg in elevation, 0.0200 deg in azimuth (RMS)"
std::string describeSensorModelFit(const SensorModelFit& fit);
// The estimate: the model, how it was found and its fit.
std::string describeSensorEstimate(const SensorEstimate& estimate);

// Where the model explains under kMinimumKeptShare of the points: what is
// lost and how to fix it (`fix` names the setting, e.g. "the Adapter's sensor
// parameter"). Nothing when the model explains enough.
std::optional<std::string> sensorModelFitWarning(const SensorModelFit& fit, const std::string& fix);
// The same for the counts of projected clouds (the Adapter's running totals).
std::optional<std::string> projectionWarning(const ProjectionStatistics& statistics, const std::string& fix);

}  // namespace range_image_mapping
