// Sensor files: any model round-trips through YAML, an Ouster metadata JSON
// reads as one, and every mistake in a hand-written file is named with its
// key (and line).
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/recording.h"
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

// A folder of .bin clouds read through a sensor file: every point gets the
// pixel it came from, where the synthetic HDL-64E model would lose them.
TEST(SensorFile, RecordingProjectsKittiFoldersWithIt) {
  LidarIntrinsics intrinsics = exampleIntrinsics();
  intrinsics.column_window = {0, -1};
  intrinsics.lidar_to_sensor = Eigen::Isometry3d::Identity();
  const LidarModel model(intrinsics);
  const std::filesystem::path folder = std::filesystem::temp_directory_path() / "rim_sensor_file_recording";
  std::filesystem::remove_all(folder);
  std::filesystem::create_directories(folder);
  std::vector<Eigen::Vector3f> points;
  for (int v = 0; v < model.rows(); ++v)
    for (int u = 0; u < model.columns(); u += 3) points.push_back(model.unproject(u, v, 5.0f + 0.01f * v));
  writeKittiVelodyne((folder / "000000.bin").string(), points, {});
  writeSensorFile((folder / "sensor.yaml").string(), intrinsics);

  RecordingOptions options;
  options.input = folder.string();
  options.kitti = true;
  options.sensor = (folder / "sensor.yaml").string();
  const Recording recording = openRecording(options);
  EXPECT_EQ(recording.model->rows(), 4);
  EXPECT_NE(recording.description.find("sensor.yaml: 4 x 2000"), std::string::npos) << recording.description;
  std::size_t valid = 0;
  forEachScan(recording, [&](const RangeImage& image) {
    valid = image.validCount();
    for (int v = 0; v < image.rows(); ++v) EXPECT_TRUE(image.valid(v, 0)) << v;
    return true;
  });
  EXPECT_EQ(valid, points.size());

  options.sensor.clear();  // the default stays the synthetic HDL-64E
  EXPECT_EQ(openRecording(options).model->rows(), 64);
  std::filesystem::remove_all(folder);
}

TEST(SensorFile, OusterCaptureRefusesASensorFile) {
  RIM_REQUIRE_DATA(pcap, "ouster-pcaps/OS-1-32-G_v2.1.1_1024x10.pcap");
  RIM_REQUIRE_DATA(metadata, "ouster-pcaps/OS-1-32-G_v2.1.1_1024x10.json");
  RecordingOptions options;
  options.input = pcap;
  options.metadata = metadata;
  options.sensor = metadata;
  try {
    openRecording(options);
    FAIL() << "expected RecordingError";
  } catch (const RecordingError& error) {
    EXPECT_NE(std::string(error.what()).find("whose sensor model is its metadata"), std::string::npos) << error.what();
  }
}

}  // namespace
}  // namespace range_image_mapping::io
