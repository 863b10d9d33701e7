// ScanToMapPipeline: the story every front end tells (rim run, rim map, the
// nodelets) gives exactly what its parts give when chained by hand with the
// documented conventions, on a simulated OS0-128 sequence with exact poses;
// given poses, restarts, the mesh cadence and bad input.
#include "range_image_mapping/pipeline/scan_to_map_pipeline.h"

#include "simulated_mapping_sequence.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace range_image_mapping::pipeline {
namespace {

const test::SimulatedMappingSequence& sequence() {
  static const test::SimulatedMappingSequence simulated =
      test::simulateMappingSequence(test::indoorCartPreset(), 12, 1);
  return simulated;
}

mapping::TsdfMapOptions indoorMap() {
  mapping::TsdfMapOptions options;
  options.grid.voxel_size_m = 0.04;
  options.integrator.max_range_m = 10.0;
  return options;
}

PipelineOptions odometryAndMap() {
  PipelineOptions options;
  options.odometry = registration::OdometryOptions{};
  options.odometry->registration.kernel.scale_m = 0.2;
  options.map = indoorMap();
  return options;
}

// The same mesh: same size and the same vertices (the grid is deterministic).
void expectSameMesh(mapping::TsdfMap& a, mapping::TsdfMap& b) {
  const TriangleMesh mesh_a = a.fullMesh(), mesh_b = b.fullMesh();
  ASSERT_EQ(mesh_a.vertices.size(), mesh_b.vertices.size());
  ASSERT_EQ(mesh_a.triangles.size(), mesh_b.triangles.size());
  EXPECT_GT(mesh_a.triangles.size(), 10000u);
  std::size_t different = 0;
  for (std::size_t i = 0; i < mesh_a.vertices.size(); ++i) different += mesh_a.vertices[i] != mesh_b.vertices[i];
  EXPECT_EQ(different, 0u);
}

TEST(ScanToMapPipeline, TellsTheSameStoryAsItsPartsChainedByHand) {
  ScanToMapPipeline pipeline(odometryAndMap());
  registration::LidarOdometry odometry(*odometryAndMap().odometry);
  mapping::TsdfMap map(indoorMap());
  std::vector<std::size_t> meshed;
  for (std::size_t k = 0; k < sequence().scans.size(); ++k) {
    const RangeImage& scan = sequence().scans[k];
    const ScanResult result = pipeline.process(scan);
    // By hand: the first valid column's time, the odometry's pose and twist of
    // this scan, the map's own normals ...
    const uint64_t time = scanTime(scan, ScanTimeSource::kFirstValidColumn);
    const registration::OdometryUpdate update = odometry.process(scan, time);
    mapping::ScanPose pose;
    pose.world_from_lidar = update.pose;
    pose.twist << update.angular_velocity, update.linear_velocity;
    pose.scan_time_ns = time;
    // ... and the scan without the pixels the odometry found moving.
    RangeImage mapped = scan;
    const std::vector<uint8_t>& moving = odometry.movingPixels();
    for (std::size_t i = 0; i < moving.size(); ++i)
      if (moving[i]) mapped.range[i] = std::numeric_limits<float>::quiet_NaN();
    const mapping::MapUpdate map_update = map.integrate(mapped, pose);

    ASSERT_TRUE(result.has_pose);
    ASSERT_TRUE(result.odometry && result.map);
    EXPECT_EQ(result.scan_time_ns, time);
    // To the bit: the registration's sums are deterministic.
    EXPECT_EQ(result.world_from_lidar.matrix(), update.pose.matrix()) << "scan " << k;
    EXPECT_EQ(result.twist.head<3>(), update.angular_velocity);
    EXPECT_EQ(result.twist.tail<3>(), update.linear_velocity);
    EXPECT_EQ(result.map->integration.voxels_updated, map_update.integration.voxels_updated) << "scan " << k;
    EXPECT_EQ(result.restart, k == 0 ? Restart::kFirstScan : Restart::kNone);
    EXPECT_TRUE(result.warnings.empty()) << result.warnings.front();
    if (result.mesh) meshed.push_back(k);
  }
  // One second of scan time at 10 Hz: the mesh after scan 10, once.
  EXPECT_EQ(meshed, std::vector<std::size_t>{10});
  expectSameMesh(*pipeline.map(), map);
}

TEST(ScanToMapPipeline, GivenPosesAndTwistsAreMappedAsGiven) {
  PipelineOptions options;
  options.map = indoorMap();
  ScanToMapPipeline pipeline(options);
  mapping::TsdfMap map(indoorMap());
  for (std::size_t k = 0; k < sequence().scans.size(); ++k) {
    const mapping::ScanPose& truth = sequence().poses[k];
    GivenPose given;
    given.world_from_lidar = truth.world_from_lidar;
    given.twist = truth.twist;
    const ScanResult result = pipeline.process(sequence().scans[k], given);
    ASSERT_TRUE(result.has_pose && result.map);
    EXPECT_FALSE(result.odometry);
    EXPECT_EQ(result.twist, truth.twist);
    map.integrate(sequence().scans[k], truth);
  }
  expectSameMesh(*pipeline.map(), map);
}

// Without a twist the sweep's motion is the backward difference of the given
// poses over the scan times; none across a gap.
TEST(ScanToMapPipeline, GivenPosesWithoutTwistGetTheTwistFromThePreviousPose) {
  PipelineOptions options;
  options.map = indoorMap();
  ScanToMapPipeline pipeline(options);
  const auto given = [&](std::size_t k) {
    GivenPose pose;
    pose.world_from_lidar = sequence().poses[k].world_from_lidar;
    return pipeline.process(sequence().scans[k], pose);
  };
  EXPECT_TRUE(given(0).twist.isZero());
  const ScanResult second = given(1);
  const double dt_s = double(second.scan_time_ns - pipeline.scanTime(sequence().scans[0])) * 1e-9;
  EXPECT_NEAR(dt_s, 0.1, 1e-3);
  const Twist expected =
      twistBetween(sequence().poses[0].world_from_lidar, sequence().poses[1].world_from_lidar, dt_s);
  EXPECT_TRUE(second.twist.isApprox(expected, 1e-12));
  // The true sweep twist, to the cart's change of speed over a scan.
  EXPECT_LT((second.twist - sequence().poses[1].twist).norm(), 0.1);
  EXPECT_TRUE(given(8).twist.isZero());  // 0.7 s after scan 1: a gap (more than 0.5 s)
}

TEST(ScanToMapPipeline, ANonFiniteGivenPoseIsRefusedAndSaid) {
  PipelineOptions options;
  options.map = indoorMap();
  ScanToMapPipeline pipeline(options);
  GivenPose bad;
  bad.world_from_lidar.translation().x() = std::numeric_limits<double>::quiet_NaN();
  const ScanResult result = pipeline.process(sequence().scans[0], bad);
  EXPECT_FALSE(result.has_pose);
  EXPECT_FALSE(result.map);
  ASSERT_EQ(result.warnings.size(), 1u);
  EXPECT_NE(result.warnings[0].find("not finite"), std::string::npos) << result.warnings[0];
  EXPECT_EQ(pipeline.map()->statistics().blocks, 0u);
}

// A replay that starts over: told so, the odometry starts again at the
// identity; not told, it goes on from the pose it reached (a clock step).
TEST(ScanToMapPipeline, ASourceThatStartsOverRestartsAtTheIdentity) {
  for (const bool told : {true, false}) {
    PipelineOptions options = odometryAndMap();
    options.map.reset();
    ScanToMapPipeline pipeline(options);
    ScanResult last;
    for (int k = 0; k < 5; ++k) last = pipeline.process(sequence().scans[k]);
    ASSERT_GT(last.world_from_lidar.translation().norm(), 0.05);
    const ScanResult again = pipeline.process(sequence().scans[0], told);
    ASSERT_TRUE(again.has_pose);
    EXPECT_FALSE(again.map);
    ASSERT_EQ(again.warnings.size(), 1u);
    if (told) {
      EXPECT_EQ(again.restart, Restart::kSourceStartedOver);
      EXPECT_TRUE(again.world_from_lidar.isApprox(Eigen::Isometry3d::Identity()));
      EXPECT_NE(again.warnings[0].find("identity"), std::string::npos) << again.warnings[0];
    } else {
      EXPECT_EQ(again.restart, Restart::kTimeWentBack);
      EXPECT_TRUE(again.world_from_lidar.isApprox(last.world_from_lidar));
    }
  }
}

TEST(ScanToMapPipeline, PosesOfTheBaseComposeWithTheLidarMount) {
  PipelineOptions options = odometryAndMap();
  options.map.reset();
  options.base_from_lidar.translation() = Eigen::Vector3d(0.3, 0.0, 1.2);
  options.base_from_lidar.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  ScanToMapPipeline pipeline(options);
  ScanResult result = pipeline.process(sequence().scans[0]);
  EXPECT_TRUE(result.world_from_base.isApprox(Eigen::Isometry3d::Identity(), 1e-12));  // odom: the base at the start
  for (int k = 1; k < 3; ++k) result = pipeline.process(sequence().scans[k]);
  EXPECT_TRUE((result.world_from_base * options.base_from_lidar).isApprox(result.world_from_lidar, 1e-12));
  EXPECT_GT(result.world_from_base.translation().norm(), 0.05);
}

TEST(ScanToMapPipeline, RefusesOptionsThatCannotWork) {
  const auto error = [](const PipelineOptions& options) {
    try {
      ScanToMapPipeline pipeline(options);
    } catch (const std::exception& caught) {
      return std::string(caught.what());
    }
    return std::string();
  };
  EXPECT_NE(error(PipelineOptions{}).find("neither odometry nor map"), std::string::npos);
  PipelineOptions options = odometryAndMap();
  options.mesh_period_s = -1.0;
  EXPECT_NE(error(options).find("mesh_period_s"), std::string::npos);
  options = odometryAndMap();
  options.base_from_lidar.linear() *= 2.0;
  EXPECT_NE(error(options).find("base_from_lidar"), std::string::npos);
  options = odometryAndMap();
  options.map->grid.voxel_size_m = -1.0;
  EXPECT_FALSE(error(options).empty());
  PipelineOptions map_only;
  map_only.map = indoorMap();
  ScanToMapPipeline pipeline(map_only);
  EXPECT_THROW(pipeline.process(sequence().scans[0]), std::logic_error);
}

}  // namespace
}  // namespace range_image_mapping::pipeline
