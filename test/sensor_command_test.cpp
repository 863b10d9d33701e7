// rim sensor estimate and rim sensor check on a folder of plain .bin clouds
// made from known beam tables, and on a real KITTI folder.
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/sensor_file.h"
#include "rim_command.h"
#include "test_data.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <random>

namespace range_image_mapping::test {
namespace {

class SensorCommandTest : public RimCommandTest {
 protected:
  // Two scans of a 16-beam sensor with uneven beams and per-beam azimuth
  // offsets, every pixel at a random range, as KITTI .bin files.
  std::string writeScans() {
    LidarIntrinsics intrinsics;
    intrinsics.rows = 16;
    intrinsics.columns = 1800;
    for (int v = 0; v < 16; ++v) {
      intrinsics.altitude_rad.push_back((15.0 - 2.0 * v - 0.1 * v * v / 4) * M_PI / 180.0);
      intrinsics.azimuth_offset_rad.push_back((v % 2 ? 0.06 : -0.05) * M_PI / 180.0);
    }
    const LidarModel model(intrinsics);
    const std::string folder = path("velodyne");
    std::filesystem::create_directories(folder);
    std::mt19937 random(7);
    std::uniform_real_distribution<float> range(1.0f, 60.0f);
    for (int scan = 0; scan < 2; ++scan) {
      std::vector<Eigen::Vector3f> points;
      for (int v = 0; v < model.rows(); ++v)
        for (int u = 0; u < model.columns(); ++u) points.push_back(model.unproject(u, v, range(random)));
      io::writeKittiVelodyne(folder + "/00000" + std::to_string(scan) + ".bin", points, {});
    }
    altitude_rad_ = intrinsics.altitude_rad;
    return folder;
  }
  std::vector<double> altitude_rad_;
};

TEST_F(SensorCommandTest, EstimatesWritesAndChecks) {
  const std::string folder = writeScans();
  const RunResult estimate = rim("sensor estimate " + folder + " -o " + path("out/sensor.yaml"));
  ASSERT_EQ(estimate.exit_code, 0) << estimate.out << estimate.err;
  EXPECT_NE(estimate.out.find("16 beams from +15.00 to"), std::string::npos) << estimate.out;
  EXPECT_NE(estimate.out.find("1800 columns"), std::string::npos) << estimate.out;
  EXPECT_NE(estimate.out.find("100.00 % kept"), std::string::npos) << estimate.out;
  const io::SensorFile file = io::readSensorFile(path("out/sensor.yaml"));
  ASSERT_EQ(file.intrinsics.rows, 16);
  for (int v = 0; v < 16; ++v) EXPECT_NEAR(file.intrinsics.altitude_rad[v], altitude_rad_[v], 1e-5) << v;

  const RunResult check = rim("sensor check " + path("out/sensor.yaml") + " " + folder);
  ASSERT_EQ(check.exit_code, 0) << check.out << check.err;
  EXPECT_NE(check.out.find("100.00 % kept"), std::string::npos) << check.out;
  EXPECT_EQ(check.out.find("warning"), std::string::npos) << check.out;
}

TEST_F(SensorCommandTest, CheckWarnsWhenTheModelDoesNotFit) {
  const std::string folder = writeScans();
  // 4 beams over a fifth of the field of view: most points are outside or share a pixel.
  std::ofstream(path("wrong.yaml")) << "rows: 4\ncolumns: 512\naltitude_deg: [3, 1, -1, -3]\n";
  const RunResult check = rim("sensor check " + path("wrong.yaml") + " " + folder);
  ASSERT_EQ(check.exit_code, 0) << check.out << check.err;
  EXPECT_NE(check.out.find("warning: the sensor model explains only"), std::string::npos) << check.out;
}

TEST_F(SensorCommandTest, BadSensorFileIsNamed) {
  const std::string folder = writeScans();
  std::ofstream(path("bad.yaml")) << "rows: 2\ncolumns: 512\naltitude_deg: [1, -1]\nfov_up_deg: 3\n";
  const RunResult check = rim("sensor check " + path("bad.yaml") + " " + folder);
  EXPECT_NE(check.exit_code, 0);
  EXPECT_NE(check.err.find("bad.yaml: unknown key 'fov_up_deg' (line 4)"), std::string::npos) << check.err;
}

TEST_F(SensorCommandTest, KittiFolder) {
  RIM_REQUIRE_DATA(first, "kitti-raw-22/velodyne/000000.bin");
  const std::string folder = std::filesystem::path(first).parent_path().string();
  const RunResult estimate = rim("sensor estimate " + folder + " --frames 2 -o " + path("kitti.yaml"));
  ASSERT_EQ(estimate.exit_code, 0) << estimate.out << estimate.err;
  std::printf("%s", estimate.out.c_str());
  const io::SensorFile file = io::readSensorFile(path("kitti.yaml"));
  EXPECT_GE(file.intrinsics.rows, 64);
  EXPECT_NEAR(file.intrinsics.beam_origin_z_m, 0.2, 0.05);  // the HDL-64E's lasers sit above KITTI's origin
}

}  // namespace
}  // namespace range_image_mapping::test
