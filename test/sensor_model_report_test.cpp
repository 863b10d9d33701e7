// How a sensor model's fit is told: the warning appears under 95 % kept,
// names the larger loss and the fix it is given; the description carries the
// figures the README lists.
#include "range_image_mapping/sensor_catalog.h"
#include "range_image_mapping/sensor_model_report.h"

#include <gtest/gtest.h>

namespace range_image_mapping {
namespace {

SensorModelFit fitOf(std::size_t kept, std::size_t outside, std::size_t occluded) {
  SensorModelFit fit;
  fit.scans = 2;
  fit.kept = kept;
  fit.outside_model = outside;
  fit.occluded = occluded;
  fit.measured_points = kept + outside + occluded;
  return fit;
}

TEST(SensorModelReport, WarnsUnder95PercentNamingTheLargerLossAndTheFix) {
  EXPECT_FALSE(sensorModelFitWarning(fitOf(960, 30, 10), "fix it").has_value());
  EXPECT_FALSE(sensorModelFitWarning(SensorModelFit(), "fix it").has_value()) << "no points, nothing to say";
  const std::optional<std::string> outside = sensorModelFitWarning(fitOf(600, 300, 100), "set sensor: VLP-32C");
  ASSERT_TRUE(outside.has_value());
  EXPECT_NE(outside->find("explains only 60.0 %"), std::string::npos) << *outside;
  EXPECT_NE(outside->find("outside its field of view"), std::string::npos) << *outside;
  EXPECT_NE(outside->find("Fix: set sensor: VLP-32C"), std::string::npos) << *outside;
  const std::optional<std::string> shared = sensorModelFitWarning(fitOf(600, 100, 300), "x");
  ASSERT_TRUE(shared.has_value());
  EXPECT_NE(shared->find("sharing a pixel"), std::string::npos) << *shared;

  ProjectionStatistics statistics;
  statistics.input_points = 1200;
  statistics.non_finite = 150;  // no-return points are not part of the share
  statistics.no_return = 50;
  statistics.kept = 900;
  statistics.outside_model = 80;
  statistics.occluded = 20;
  const std::optional<std::string> projected = projectionWarning(statistics, "x");
  ASSERT_TRUE(projected.has_value());
  EXPECT_NE(projected->find("explains only 90.0 %"), std::string::npos) << *projected;
  statistics.kept = 980, statistics.outside_model = 0;
  EXPECT_FALSE(projectionWarning(statistics, "x").has_value());
}

TEST(SensorModelReport, DescriptionHoldsTheModelAndItsFit) {
  const std::string model = describeSensorModel(*catalogSensor("VLP-32C"));
  EXPECT_NE(model.find("32 beams from +15.00 to -25.00 deg, 1808 columns"), std::string::npos) << model;
  const std::string fit = describeSensorModelFit(fitOf(970, 20, 10));
  EXPECT_NE(fit.find("97.00 % kept, 2.00 % outside the field of view, 1.00 % lost"), std::string::npos) << fit;
}

}  // namespace
}  // namespace range_image_mapping
