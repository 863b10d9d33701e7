// rim odometry end to end: a short simulated sequence (from rim simulate)
// comes out within centimetres of its ground truth, in both pose formats
// with per-frame statistics, and bad requests fail with a named error.
#include "range_image_mapping/evaluation/trajectory_metrics.h"
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/pose_file.h"
#include "rim_command.h"

#include <gtest/gtest.h>

#include <fstream>

namespace range_image_mapping {
namespace {

using OdometryCommand = test::RimCommandTest;

TEST_F(OdometryCommand, IndoorCartComesOutWithinTwoCentimetres) {
  ASSERT_EQ(rim("simulate --preset indoor_cart --frames 15 --out " + path("ic")).exit_code, 0);
  const test::RunResult run = rim("odometry " + path("ic") + " --kernel-scale 0.2 --out " + path("ic/est.txt"));
  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_NE(run.err.find("15/15 frames"), std::string::npos) << run.err;  // the progress bar
  const auto estimate = io::readKittiPosesWithTimes(path("ic/est.txt"));
  const auto tum = io::readTumPoses(path("ic/est_tum.txt"));
  const auto truth = io::readKittiPosesWithTimes(path("ic/poses_kitti.txt"));
  ASSERT_EQ(estimate.size(), 15u);
  ASSERT_EQ(tum.size(), 15u);
  ASSERT_EQ(truth.size(), 15u);
  for (std::size_t k = 0; k < estimate.size(); ++k) {
    EXPECT_NEAR(estimate[k].time_s, truth[k].time_s, 1e-6);
    EXPECT_TRUE(estimate[k].pose.isApprox(tum[k].pose, 1e-6));
  }
  const auto result = evaluation::evaluateTrajectory(io::posesOf(estimate), io::posesOf(truth));
  EXPECT_LT(result.absolute_translation_m.maximum, 0.02);  // measured about 5 mm
  // One CSV line per scan after the header.
  std::ifstream csv(path("ic/est_frames.csv"));
  int lines = 0;
  for (std::string line; std::getline(csv, line);) ++lines;
  EXPECT_EQ(lines, 16);
  EXPECT_NE(test::readText(path("ic/est_summary.json")).find("\"degenerate\" : 0"), std::string::npos);

  // Sensor-frame poses are the lidar poses moved by lidar_to_sensor.
  ASSERT_EQ(rim("odometry " + path("ic") + " --frames 3 --frame sensor --out " + path("ic/sensor.txt")).exit_code, 0);
  EXPECT_EQ(io::readKittiPosesWithTimes(path("ic/sensor.txt")).size(), 3u);
}

TEST_F(OdometryCommand, BadRequestsNameTheProblem) {
  test::RunResult run = rim("odometry " + path("missing") + " --out " + path("est.txt"));
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("does not exist"), std::string::npos) << run.err;
  std::ofstream(path("capture.pcap")) << "not a capture";
  run = rim("odometry " + path("capture.pcap") + " --out " + path("est.txt"));
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("--metadata"), std::string::npos) << run.err;
  std::filesystem::create_directories(path("empty/velodyne"));
  run = rim("odometry " + path("empty") + " --out " + path("est.txt"));
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("no KITTI scans"), std::string::npos) << run.err;
  std::filesystem::create_directories(path("one/velodyne"));
  io::writeKittiVelodyne(path("one/velodyne/000000.bin"), {Eigen::Vector3f(10.0f, 0.0f, 0.0f)}, {});
  run = rim("odometry " + path("one") + " --sensor " + path("no_such_sensor.yaml") + " --out " + path("est.txt"));
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("no_such_sensor.yaml"), std::string::npos) << run.err;
}

// A KITTI folder read with a sensor file instead of the synthetic HDL-64E:
// the file's model is the one the odometry gets (its rows and columns).
TEST_F(OdometryCommand, AKittiFolderTakesASensorFile) {
  ASSERT_EQ(rim("simulate --preset kitti_like --frames 3 --out " + path("k")).exit_code, 0);
  std::ofstream(path("sensor.yaml")) << "rows: 2\ncolumns: 360\naltitude_deg: [-5.0, -15.0]\n";
  const test::RunResult run =
      rim("odometry " + path("k") + " --kitti --sensor " + path("sensor.yaml") + " --out " + path("k/est.txt"));
  // Two beams see almost nothing of a 64-beam scan: the health says so.
  EXPECT_NE(run.err.find("degenerate"), std::string::npos) << run.err;
  const std::string summary = test::readText(path("k/est_summary.json"));
  EXPECT_NE(summary.find("\"frames\" : 3"), std::string::npos);
  // Rows 10 deg apart: the area weight's cap in use is 0.0045 / d^2, not the 25 m option.
  EXPECT_NE(summary.find("\"area_weight_range_in_use_m\" : 0.1477"), std::string::npos) << summary;
}

// --sensor takes a catalog name as well as a file: KITTI's HDL-64E by name is
// the model a KITTI folder gets anyway, to the bit; a name that is neither a
// file nor in the catalog is refused with the names that are.
TEST_F(OdometryCommand, ANamedSensorIsTheCatalogModel) {
  ASSERT_EQ(rim("simulate --preset kitti_like --frames 3 --out " + path("n")).exit_code, 0);
  ASSERT_EQ(rim("odometry " + path("n") + " --kitti --out " + path("n/default.txt")).exit_code, 0);
  test::RunResult run = rim("odometry " + path("n") + " --kitti --sensor hdl-64e --out " + path("n/named.txt"));
  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_EQ(test::readText(path("n/named.txt")), test::readText(path("n/default.txt")));
  // The HDL-64E's rows are dense enough for the whole 25 m cap.
  EXPECT_NE(test::readText(path("n/named_summary.json")).find("\"area_weight_range_in_use_m\" : 25"), std::string::npos);
  run = rim("odometry " + path("n") + " --kitti --sensor VLP-99 --out " + path("n/unknown.txt"));
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("VLP-99"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("VLP-16"), std::string::npos) << run.err;
}

}  // namespace
}  // namespace range_image_mapping
