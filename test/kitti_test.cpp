#include "range_image_mapping/io/kitti.h"

#include "test_data.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

namespace range_image_mapping::io {
namespace {

std::string temporaryPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("rim_kitti_test_" + name)).string();
}

void writeFile(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

template <typename Function>
std::string errorOf(Function&& function) {
  try {
    function();
  } catch (const KittiFormatError& error) { return error.what(); }
  return "no KittiFormatError";
}

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

TEST(KittiVelodyne, ReadsScan94) {
  RIM_REQUIRE_DATA(scan_path, "kitti00/velodyne/000094.bin");
  const PointCloudInput cloud = readKittiVelodyne(scan_path);
  ASSERT_EQ(cloud.size(), 1945888u / 16u);  // file size stated in SOURCE.md
  EXPECT_EQ(cloud.intensity.size(), cloud.size());
  EXPECT_TRUE(cloud.ring.empty());
  EXPECT_FALSE(cloud.isOrganized());
  EXPECT_NO_THROW(cloud.validate());
  // The same bytes read independently.
  std::ifstream file(scan_path, std::ios::binary);
  float first[4], last[4];
  file.read(reinterpret_cast<char*>(first), sizeof(first));
  file.seekg(-16, std::ios::end);
  file.read(reinterpret_cast<char*>(last), sizeof(last));
  EXPECT_EQ(cloud.points.front(), Eigen::Vector3f(first[0], first[1], first[2]));
  EXPECT_EQ(cloud.intensity.front(), first[3]);
  EXPECT_EQ(cloud.points.back(), Eigen::Vector3f(last[0], last[1], last[2]));
  for (const float reflectance : cloud.intensity) {
    ASSERT_GE(reflectance, 0.0f);
    ASSERT_LE(reflectance, 1.0f);
  }
}

TEST(KittiVelodyne, ClearErrors) {
  EXPECT_TRUE(contains(errorOf([] { readKittiVelodyne("/nonexistent/000000.bin"); }),
                       "cannot open /nonexistent/000000.bin"));
  const std::string path = temporaryPath("truncated.bin");
  writeFile(path, std::string(17, '\0'));
  EXPECT_TRUE(
      contains(errorOf([&] { readKittiVelodyne(path); }), "17 bytes, not a multiple of 16"));
  std::remove(path.c_str());
}

TEST(KittiPoses, GroundTruthInTheVelodyneFrame) {
  RIM_REQUIRE_DATA(poses_path, "kitti00/poses_00_full_evo.txt");
  RIM_REQUIRE_DATA(calibration_path, "kitti00/calib.txt");
  const std::vector<Eigen::Isometry3d> camera_poses = readKittiPoses(poses_path);
  ASSERT_EQ(camera_poses.size(), 4541u);  // frames 0..4540 (SOURCE.md)
  const Eigen::Isometry3d velodyne_to_camera = readKittiVelodyneToCamera(calibration_path);
  // Tr maps velodyne x (forward) onto camera z (forward).
  EXPECT_GT(velodyne_to_camera.linear()(2, 0), 0.99);
  const std::vector<Eigen::Isometry3d> velodyne_poses =
      velodynePosesFromCameraPoses(camera_poses, velodyne_to_camera);
  EXPECT_TRUE(velodyne_poses[0].isApprox(Eigen::Isometry3d::Identity(), 1e-6));
  // SOURCE.md: GT relative translation 94 -> 95 (velodyne frame) ~ (0.474, -0.015, 0.009) m.
  const Eigen::Isometry3d relative = velodyne_poses[94].inverse() * velodyne_poses[95];
  EXPECT_NEAR(relative.translation().x(), 0.474, 0.0015);
  EXPECT_NEAR(relative.translation().y(), -0.015, 0.0015);
  EXPECT_NEAR(relative.translation().z(), 0.009, 0.0015);
  const Eigen::Isometry3d relative_198 = velodyne_poses[198].inverse() * velodyne_poses[199];
  EXPECT_NEAR(relative_198.translation().x(), 0.514, 0.0015);
  EXPECT_NEAR(relative_198.translation().y(), 0.039, 0.0015);
  EXPECT_NEAR(relative_198.translation().z(), 0.014, 0.0015);
}

TEST(KittiPoses, WriteReadRoundTripAndErrors) {
  std::vector<Eigen::Isometry3d> poses(3, Eigen::Isometry3d::Identity());
  poses[1].rotate(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()));
  poses[1].translation() = Eigen::Vector3d(1.5, -2.25, 1e-4);
  poses[2].translation() = Eigen::Vector3d(-100.0, 3.0, 0.5);
  const std::string path = temporaryPath("poses.txt");
  writeKittiPoses(path, poses);
  const std::vector<Eigen::Isometry3d> read = readKittiPoses(path);
  ASSERT_EQ(read.size(), poses.size());
  for (std::size_t i = 0; i < poses.size(); ++i)
    EXPECT_TRUE(read[i].matrix().isApprox(poses[i].matrix(), 1e-8)) << "pose " << i;

  writeFile(path, "1 0 0 0 0 1 0 0 0 0 1 0\n\n1 0 0 0 0 1 0 0 0 0 1\n");
  EXPECT_TRUE(
      contains(errorOf([&] { readKittiPoses(path); }), "line 3 does not hold 12 finite numbers"));
  writeFile(path, "P0: 1 2 3\n");
  EXPECT_TRUE(contains(errorOf([&] { readKittiVelodyneToCamera(path); }), "has no Tr: line"));
  writeFile(path, "Tr: 1 2 3\n");
  EXPECT_TRUE(
      contains(errorOf([&] { readKittiVelodyneToCamera(path); }), "Tr: line does not hold"));
  std::remove(path.c_str());
  EXPECT_TRUE(contains(errorOf([&] { readKittiPoses(path); }), "cannot open"));
}

TEST(KittiIntrinsics, Hdl64) {
  const LidarIntrinsics intrinsics = kittiHdl64Intrinsics();
  EXPECT_EQ(intrinsics.rows, 64);
  EXPECT_EQ(intrinsics.columns, 2048);
  EXPECT_NEAR(intrinsics.altitude_rad.front(), 3.0 * M_PI / 180.0, 1e-12);
  EXPECT_NEAR(intrinsics.altitude_rad.back(), -25.0 * M_PI / 180.0, 1e-12);
  EXPECT_EQ(intrinsics.beam_origin_radius_m, 0.0);
  EXPECT_EQ(kittiHdl64Intrinsics(4096).columns, 4096);
  EXPECT_THROW(kittiHdl64Intrinsics(0), IntrinsicsError);
}

}  // namespace
}  // namespace range_image_mapping::io
