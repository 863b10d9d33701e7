// Sensor files: any model round-trips through YAML, an Ouster metadata JSON
// reads as one, and every mistake in a hand-written file is named with its
// key (and line).
#include "range_image_mapping/io/sensor_file.h"
#include "range_image_mapping/ouster_metadata.h"
#include "test_data.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

namespace range_image_mapping::io {
namespace {

LidarIntrinsics exampleIntrinsics() {
  LidarIntrinsics intrinsics;
  intrinsics.rows = 4;
  intrinsics.columns = 2000;
  intrinsics.altitude_rad = {0.05, 0.01, -0.1, -0.3};
  intrinsics.azimuth_offset_rad = {0.001, -0.07, 0.0, 0.12345678901};
  intrinsics.pixel_shift_by_row = {3, 0, 0, 1997};
  intrinsics.beam_origin_radius_m = 0.0158;
  intrinsics.beam_origin_z_m = 0.2;
  intrinsics.column_window = {10, 1500};
  intrinsics.lidar_to_sensor.translation() = Eigen::Vector3d(0.0, 0.0, 0.03618);
  intrinsics.lidar_to_sensor.linear() = Eigen::Vector3d(-1, -1, 1).asDiagonal();
  intrinsics.sensor_model = "my \"LiDAR\"";
  return intrinsics;
}

void expectSameIntrinsics(const LidarIntrinsics& a, const LidarIntrinsics& b) {
  EXPECT_EQ(a.rows, b.rows);
  EXPECT_EQ(a.columns, b.columns);
  ASSERT_EQ(a.altitude_rad.size(), b.altitude_rad.size());
  for (std::size_t v = 0; v < a.altitude_rad.size(); ++v) {
    EXPECT_NEAR(a.altitude_rad[v], b.altitude_rad[v], 1e-12) << v;
    EXPECT_NEAR(a.azimuth_offset_rad[v], b.azimuth_offset_rad[v], 1e-12) << v;
  }
  EXPECT_EQ(a.pixel_shift_by_row, b.pixel_shift_by_row);
  EXPECT_NEAR(a.beam_origin_radius_m, b.beam_origin_radius_m, 1e-12);
  EXPECT_NEAR(a.beam_origin_z_m, b.beam_origin_z_m, 1e-12);
  EXPECT_EQ(a.column_window, b.column_window);
  EXPECT_TRUE(a.lidar_to_sensor.isApprox(b.lidar_to_sensor, 1e-12));
}

std::string errorOf(const std::string& yaml) {
  try {
    parseSensorYaml(yaml, "test.yaml");
  } catch (const SensorFileError& error) {
    return error.what();
  }
  return "";
}

TEST(SensorFile, RoundTripsAnyModel) {
  const LidarIntrinsics intrinsics = exampleIntrinsics();
  const SensorFile file = parseSensorYaml(sensorYaml(intrinsics, {3, 2, 1, 0}));
  expectSameIntrinsics(file.intrinsics, intrinsics);
  EXPECT_EQ(file.intrinsics.sensor_model, "my 'LiDAR'");
  EXPECT_EQ(file.ring_to_row, (std::vector<int>{3, 2, 1, 0}));
}

TEST(SensorFile, WritesTheEstimateAndReadsPastIt) {
  SensorEstimate estimate;
  estimate.intrinsics = exampleIntrinsics();
  estimate.fit.scans = 3;
  estimate.fit.measured_points = 1000;
  estimate.fit.kept = 990;
  estimate.points_per_row = {250, 250, 250, 250};
  const std::string path = (std::filesystem::temp_directory_path() / "rim_sensor_file_test.yaml").string();
  writeSensorFile(path, estimate.intrinsics, {}, &estimate);
  std::ifstream stream(path);
  const std::string text((std::istreambuf_iterator<char>(stream)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("kept_share: 0.99"), std::string::npos) << text;
  expectSameIntrinsics(readSensorFile(path).intrinsics, estimate.intrinsics);
  std::filesystem::remove(path);
}

TEST(SensorFile, HandWrittenMinimalFile) {
  const SensorFile file = parseSensorYaml(
      "# a VLP-16 from its data sheet\n"
      "rows: 3\ncolumns: 1800\n"
      "altitude_deg:\n  - 15\n  - 0\n  - -15\n");
  EXPECT_EQ(file.intrinsics.rows, 3);
  EXPECT_NEAR(file.intrinsics.altitude_rad[2], -15.0 * M_PI / 180.0, 1e-12);
  EXPECT_EQ(file.intrinsics.azimuth_offset_rad, std::vector<double>(3, 0.0));
  EXPECT_EQ(file.intrinsics.beam_origin_radius_m, 0.0);
  EXPECT_NO_THROW(LidarModel{file.intrinsics});
}

TEST(SensorFile, MistakesAreNamed) {
  const std::string base = "rows: 2\ncolumns: 1024\n";
  EXPECT_NE(errorOf(base + "altitude_deg: [1, -1]\naltitudes_deg: [1]\n").find("unknown key 'altitudes_deg' (line 4)"),
            std::string::npos);
  EXPECT_NE(errorOf(base).find("missing altitude_deg"), std::string::npos);
  EXPECT_NE(errorOf(base + "altitude_deg: [1, x]\n").find("altitude_deg[1] is not a number: 'x' (line 3)"),
            std::string::npos);
  EXPECT_NE(errorOf(base + "altitude_deg: 1\n").find("altitude_deg must be a list"), std::string::npos);
  EXPECT_NE(errorOf(base + "altitude_deg: [1, -1, -2]\n").find("altitude_deg has 3 entries, rows is 2"),
            std::string::npos);
  EXPECT_NE(errorOf("rows: 2.5\ncolumns: 1024\naltitude_deg: [1, -1]\n").find("rows is not a whole number"),
            std::string::npos);
  EXPECT_NE(errorOf(base + "altitude_deg: [1, -1\n").find("not valid YAML at line"), std::string::npos);
  EXPECT_NE(errorOf("- 1\n- 2\n").find("expected a YAML mapping"), std::string::npos);
  EXPECT_NE(errorOf(base + "altitude_deg: [1, -1]\nring_to_row: [0, 2]\n").find("ring_to_row[1] = 2 is no row"),
            std::string::npos);
  EXPECT_NE(errorOf(base + "altitude_deg: [1, -1]\nlidar_to_sensor: [1, 0, 0]\n").find("16 numbers"),
            std::string::npos);
  EXPECT_NE(errorOf(base + "altitude_deg: [1, -1]\nbeam_origin_radius_m: -1\n").find("beam_origin_radius_m"),
            std::string::npos);
  EXPECT_THROW(readSensorFile("/nonexistent/sensor.yaml"), SensorFileError);
  for (const std::string& message : {errorOf(base), errorOf(base + "altitude_deg: [1, x]\n")})
    EXPECT_EQ(message.rfind("test.yaml: ", 0), 0u) << message;
}

TEST(SensorFile, OusterMetadataIsASensorFile) {
  RIM_REQUIRE_DATA(path, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  const SensorFile file = readSensorFile(path);
  expectSameIntrinsics(file.intrinsics, loadOusterMetadata(path).intrinsics);
  // And through YAML unchanged.
  expectSameIntrinsics(parseSensorYaml(sensorYaml(file.intrinsics)).intrinsics, file.intrinsics);
}

}  // namespace
}  // namespace range_image_mapping::io
