// The named sensor models: each against its data sheet's summary (beams,
// vertical field of view, finest beam spacing, azimuth resolution at 10 Hz),
// each recovered by the estimation from plain clouds of it (what the Adapter
// and rim do by default), the HDL-64E against real KITTI scans, and the names
// through --sensor NAME.
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/sensor_file.h"
#include "range_image_mapping/sensor_catalog.h"
#include "range_image_mapping/sensor_model_estimation.h"
#include "test_data.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace range_image_mapping {
namespace {

constexpr double kDeg = M_PI / 180.0;

// What the data sheets say, written down apart from the laser tables. Per-unit
// calibrations (Pandar64, RS-LiDAR-32) sit within 0.2 deg of the nominal ends.
struct DataSheet {
  const char* name;
  int beams;
  double top_deg, bottom_deg;
  double finest_spacing_deg;  // smallest step between neighbouring beams
  double azimuth_resolution_deg;  // at 10 Hz
  double largest_azimuth_offset_deg;  // 0: all lasers fire at one azimuth
};

const DataSheet kDataSheets[] = {
    {"VLP-16", 16, 15.0, -15.0, 2.0, 0.2, 0.0},
    {"VLP-32C", 32, 15.0, -25.0, 0.333, 0.2, 4.2},
    {"HDL-32E", 32, 10.67, -30.67, 1.33, 0.166, 0.0},
    {"HDL-64E", 64, 3.0, -25.0, 0.444, 0.176, 0.0},  // KITTI's synthetic model
    {"PandarXT-32", 32, 15.0, -16.0, 1.0, 0.18, 0.0},
    {"Pandar64", 64, 15.0, -25.0, 0.167, 0.2, 5.6},
    {"RS-LiDAR-16", 16, 15.0, -15.0, 2.0, 0.2, 0.0},
    {"RS-LiDAR-32", 32, 15.0, -25.0, 0.333, 0.2, 8.4},
};

std::vector<double> sortedDegrees(const std::vector<double>& radians) {
  std::vector<double> degrees;
  for (const double value : radians) degrees.push_back(value / kDeg);
  std::sort(degrees.begin(), degrees.end());
  return degrees;
}

TEST(SensorCatalog, EveryDataSheetIsInTheCatalogAndNothingElse) {
  ASSERT_EQ(sensorCatalog().size(), std::size(kDataSheets));
  for (const DataSheet& sheet : kDataSheets) EXPECT_TRUE(catalogSensor(sheet.name).has_value()) << sheet.name;
}

class CatalogModel : public ::testing::TestWithParam<DataSheet> {};

TEST_P(CatalogModel, MatchesItsDataSheet) {
  const DataSheet& sheet = GetParam();
  const std::optional<LidarIntrinsics> model = catalogSensor(sheet.name);
  ASSERT_TRUE(model.has_value());
  ASSERT_EQ(model->rows, sheet.beams);
  const std::vector<double> altitude = sortedDegrees(model->altitude_rad);
  EXPECT_NEAR(altitude.back(), sheet.top_deg, 0.2);
  EXPECT_NEAR(altitude.front(), sheet.bottom_deg, 0.2);
  double finest = 180.0;
  for (std::size_t i = 1; i < altitude.size(); ++i) finest = std::min(finest, altitude[i] - altitude[i - 1]);
  // Per-unit calibrations bring neighbours closer than the nominal step (the
  // Pandar64 unit's -5.78 and -5.88 deg beams: 0.098 deg for 0.167).
  EXPECT_GT(finest, 0.5 * sheet.finest_spacing_deg);
  EXPECT_LT(finest, 1.05 * sheet.finest_spacing_deg);
  // Row 0 is the highest beam.
  for (int v = 1; v < model->rows; ++v) EXPECT_GT(model->altitude_rad[v - 1], model->altitude_rad[v]) << "row " << v;
  EXPECT_NEAR(360.0 / model->columns, sheet.azimuth_resolution_deg, 0.005);
  double largest_offset = 0.0;
  for (const double offset : model->azimuth_offset_rad) largest_offset = std::max(largest_offset, std::abs(offset) / kDeg);
  EXPECT_NEAR(largest_offset, sheet.largest_azimuth_offset_deg, 0.1);
  EXPECT_EQ(model->sensor_model.rfind(sheet.name, 0), 0u) << model->sensor_model;
}

// Every pixel unprojected at a random range: a plain cloud as a driver gives it.
PointCloudInput everyPixel(const LidarModel& model, unsigned seed) {
  PointCloudInput cloud;
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> range(1.0f, 60.0f);
  for (int v = 0; v < model.rows(); ++v)
    for (int u = 0; u < model.columns(); ++u) cloud.points.push_back(model.unproject(u, v, range(random)));
  return cloud;
}

// The estimation, the default for clouds without a model, finds the catalog's
// beams within 0.02 deg, its columns, and its azimuth offsets (up to whole
// columns, which only renumber the columns), keeping every point.
TEST_P(CatalogModel, IsWhatTheEstimationFindsInItsClouds) {
  const auto model = std::make_shared<const LidarModel>(*catalogSensor(GetParam().name));
  const SensorEstimate estimate = estimateSensorModel({everyPixel(*model, 1), everyPixel(*model, 2)});
  const LidarIntrinsics& found = estimate.intrinsics;
  ASSERT_EQ(found.rows, model->rows());
  EXPECT_EQ(found.columns, model->columns());
  const double column_step = 2 * M_PI / model->columns();
  double altitude_error = 0.0, azimuth_error = 0.0;
  for (int v = 0; v < found.rows; ++v) {
    altitude_error = std::max(altitude_error, std::abs(found.altitude_rad[v] - model->intrinsics().altitude_rad[v]));
    const double offset = found.azimuth_offset_rad[v] - model->intrinsics().azimuth_offset_rad[v];
    azimuth_error = std::max(azimuth_error, std::abs(std::remainder(offset, column_step)));
  }
  std::printf("%s: estimated %d x %d, largest error %.1e deg in altitude, %.1e deg in azimuth, kept %.4f\n",
              GetParam().name, found.rows, found.columns, altitude_error / kDeg, azimuth_error / kDeg,
              estimate.fit.keptShare());
  EXPECT_LT(altitude_error / kDeg, 0.02);
  EXPECT_LT(azimuth_error / kDeg, 0.02);
  EXPECT_GE(estimate.fit.keptShare(), 0.999);
}

INSTANTIATE_TEST_SUITE_P(Named, CatalogModel, ::testing::ValuesIn(kDataSheets),
                         [](const ::testing::TestParamInfo<DataSheet>& info) {
                           std::string name = info.param.name;
                           for (char& c : name)
                             if (c == '-') c = '_';
                           return name;
                         });

// KITTI's real scans: the catalog's HDL-64E sees nearly all their points (its
// field of view covers the lasers) and keeps most of them.
TEST(SensorCatalog, Hdl64eExplainsRealKittiScans) {
  RIM_REQUIRE_DATA(first, "kitti00/velodyne/000094.bin");
  RIM_REQUIRE_DATA(second, "kitti-raw-22/velodyne/000000.bin");
  const std::vector<PointCloudInput> scans{io::readKittiVelodyne(first), io::readKittiVelodyne(second)};
  const SensorModelFit fit = measureSensorModelFit(scans, std::make_shared<const LidarModel>(*catalogSensor("KITTI")));
  std::printf("HDL-64E on 2 real KITTI scans: kept %.4f, outside %.4f, shared pixel %.4f\n", fit.keptShare(),
              fit.outsideShare(), fit.occludedShare());
  EXPECT_LT(fit.outsideShare(), 0.01);
  EXPECT_GT(fit.keptShare(), 0.75);
  // A model with the wrong field of view is told apart: a VLP-16's +-15 deg
  // loses KITTI's lower beams.
  const SensorModelFit wrong = measureSensorModelFit(scans, std::make_shared<const LidarModel>(*catalogSensor("VLP-16")));
  EXPECT_GT(wrong.outsideShare(), 0.05);
}

TEST(SensorCatalog, NamesIgnoreCaseAndPunctuation) {
  for (const char* name : {"VLP-16", "vlp16", "Vlp_16", "vlp 16"}) {
    const std::optional<LidarIntrinsics> model = catalogSensor(name);
    ASSERT_TRUE(model.has_value()) << name;
    EXPECT_EQ(model->sensor_model, "VLP-16");
  }
  EXPECT_EQ(catalogSensor("kitti")->altitude_rad, kittiHdl64Intrinsics().altitude_rad);
  EXPECT_EQ(catalogSensor("xt32")->sensor_model, "PandarXT-32");
  EXPECT_EQ(catalogSensor("rs32")->sensor_model, "RS-LiDAR-32");
  EXPECT_FALSE(catalogSensor("VLP-17").has_value());
  EXPECT_FALSE(catalogSensor("").has_value());
}

TEST(SensorCatalog, SensorOptionTakesANameAndListsTheNamesOnError) {
  const io::SensorFile named = io::readSensorFile("Pandar64");
  EXPECT_EQ(named.intrinsics.rows, 64);
  EXPECT_EQ(named.intrinsics.sensor_model, "Pandar64");
  try {
    io::readSensorFile("VLP-17");
    FAIL() << "expected SensorFileError";
  } catch (const io::SensorFileError& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find("VLP-17"), std::string::npos) << message;
    for (const DataSheet& sheet : kDataSheets) EXPECT_NE(message.find(sheet.name), std::string::npos) << message;
  }
}

}  // namespace
}  // namespace range_image_mapping
