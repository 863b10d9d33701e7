// rim simulate end to end: its packets decode back to exactly the simulated
// scans, its ground truth (poses, surface) agrees with its own data, it is
// deterministic per seed, and bad requests fail with a named error.
#include "range_image_mapping/evaluation/surface_metrics.h"
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/pcd.h"
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/io/pcap_writer.h"
#include "range_image_mapping/io/ply.h"
#include "range_image_mapping/io/pose_file.h"
#include "range_image_mapping/ouster_packet_encoder.h"
#include "range_image_mapping/sensor_catalog.h"
#include "range_image_mapping/simulation/lidar_simulator.h"
#include "range_image_mapping/simulation/scene_generator.h"
#include "range_image_mapping/simulation/sensor_presets.h"
#include "json_file.h"
#include "rim_command.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

namespace range_image_mapping::simulation {
namespace {

using SimulateCommand = test::RimCommandTest;

// Simulated scans of every profile, written as a pcap and read back by the
// front end, are the simulated scans field for field.
TEST_F(SimulateCommand, PacketsDecodeBackToTheSimulatedScansBitForBit) {
  SceneOptions scene_options;
  scene_options.kind = SceneKind::kIndoor;
  const Scene scene = generateScene(scene_options);
  const RayCaster caster(scene.mesh);
  MotionOptions motion;
  motion.profile = MotionProfile::kHandheld;
  motion.duration_s = 2.0;
  motion.sensor_height_m = 1.2;
  const auto trajectory = makeTrajectory(scene, motion);
  SensorEffects effects;
  effects.range_noise_sigma_m = 0.02;
  effects.dropout_probability = 0.05;
  for (const UdpProfile profile : {UdpProfile::kLegacy, UdpProfile::kRng19Rfl8Sig16Nir16,
                                   UdpProfile::kRng19Rfl8Sig16Nir16Dual, UdpProfile::kRng15Rfl8Nir8}) {
    SCOPED_TRACE(toString(profile));
    const OusterMetadata metadata = parseOusterMetadata(ousterLikeMetadataJson("OS-0-128", profile));
    const auto model = std::make_shared<const LidarModel>(metadata.intrinsics);
    const LidarSimulator simulator(model, caster, effects, 3);
    std::vector<LidarScan> simulated;
    {
      io::OusterPcapWriter writer(path("capture.pcap"), metadata);
      for (uint32_t frame = 0; frame < 3; ++frame) {
        SimulatedScan scan = simulator.simulate(*trajectory, 0.5 + 0.1 * frame, frame);
        quantizeForProfile(scan.raw, profile);
        writer.writeScan(scan.raw);
        simulated.push_back(scan.raw);
      }
      writer.close();
    }
    std::vector<LidarScan> decoded;
    io::readOusterScans(path("capture.pcap"), metadata,
                        [&](const LidarScan& scan) { decoded.push_back(scan); });
    ASSERT_EQ(decoded.size(), simulated.size());
    for (std::size_t i = 0; i < decoded.size(); ++i) {
      EXPECT_EQ(decoded[i].frame_id, simulated[i].frame_id);
      EXPECT_EQ(decoded[i].range, simulated[i].range);
      EXPECT_EQ(decoded[i].reflectivity, simulated[i].reflectivity);
      EXPECT_EQ(decoded[i].timestamp_ns, simulated[i].timestamp_ns);
      EXPECT_EQ(decoded[i].measurement_id, simulated[i].measurement_id);
      EXPECT_EQ(decoded[i].status, simulated[i].status);
      EXPECT_EQ(decoded[i].encoder_count, simulated[i].encoder_count);
      if (profile != UdpProfile::kRng15Rfl8Nir8) EXPECT_EQ(decoded[i].signal, simulated[i].signal);
      EXPECT_GT(std::count_if(decoded[i].range.begin(), decoded[i].range.end(),
                              [](uint32_t r) { return r != 0; }),
                100000);
    }
  }
}

// Without noise or motion distortion, the decoded scans moved by the
// ground-truth poses lie on the ground-truth surface.
TEST_F(SimulateCommand, GroundTruthPosesPutTheScansOnTheGroundTruthSurface) {
  const std::string out = path("run");
  const test::RunResult run = rim("simulate --sensor OS-1-128 --scene indoor --motion cart --frames 4 "
                                  "--noise 0 --no-motion-distortion --seed 2 --out '" + out + "'");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const OusterMetadata metadata = loadOusterMetadata(out + "/metadata.json");
  const auto model = std::make_shared<const LidarModel>(metadata.intrinsics);
  const std::vector<io::StampedPose> poses = io::readPoseFile(out + "/poses_tum.txt");
  ASSERT_EQ(poses.size(), 4u);
  const std::vector<Eigen::Vector3f> surface = io::readPlyPoints(out + "/surface.ply");
  std::vector<Eigen::Vector3f> points;
  std::size_t frame = 0;
  io::readOusterScans(out + "/capture.pcap", metadata, [&](const LidarScan& scan) {
    ASSERT_LT(frame, poses.size());
    const Eigen::Isometry3f world_from_lidar = poses[frame++].pose.cast<float>();
    for (const Eigen::Vector3f& point : toRangeImage(scan, model).unprojectAll())
      points.push_back(world_from_lidar * point);
  });
  ASSERT_EQ(frame, 4u);
  std::vector<float> distances = evaluation::nearestDistances(points, surface);
  std::nth_element(distances.begin(), distances.begin() + distances.size() / 2, distances.end());
  // Samples 2 cm apart: a point on the surface is within about 1.5 cm of one.
  EXPECT_LT(distances[distances.size() / 2], 0.012f);
  std::nth_element(distances.begin(), distances.begin() + distances.size() * 99 / 100, distances.end());
  EXPECT_LT(distances[distances.size() * 99 / 100], 0.03f);
  // And the sensor-frame poses are the lidar-frame poses moved by lidar_to_sensor.
  const auto sensor_poses = io::readPoseFile(out + "/poses_sensor_tum.txt");
  ASSERT_EQ(sensor_poses.size(), poses.size());
  for (std::size_t i = 0; i < poses.size(); ++i)
    EXPECT_TRUE((sensor_poses[i].pose * metadata.intrinsics.lidar_to_sensor)
                    .isApprox(poses[i].pose, 1e-5));
}

TEST_F(SimulateCommand, SameSeedSameBytesOtherSeedOtherBytes) {
  const std::string arguments = "simulate --sensor OS-0-128 --scene indoor --motion handheld --frames 2 ";
  ASSERT_EQ(rim(arguments + "--seed 7 --out '" + path("a") + "'").exit_code, 0);
  ASSERT_EQ(rim(arguments + "--seed 7 --out '" + path("b") + "'").exit_code, 0);
  ASSERT_EQ(rim(arguments + "--seed 8 --out '" + path("c") + "'").exit_code, 0);
  for (const char* file : {"capture.pcap", "poses_kitti.txt", "surface.ply", "scene.ply"}) {
    EXPECT_EQ(test::readText(path("a/") + file), test::readText(path("b/") + file)) << file;
    EXPECT_NE(test::readText(path("a/") + file), test::readText(path("c/") + file)) << file;
  }
}

TEST_F(SimulateCommand, KittiLikeWritesVelodyneScans) {
  const test::RunResult run =
      rim("simulate --preset kitti_like --frames 2 --out '" + path("kitti") + "'");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  for (const char* scan : {"000000.bin", "000001.bin"}) {
    const PointCloudInput cloud = io::readKittiVelodyne(path("kitti/velodyne/") + scan);
    EXPECT_GT(cloud.points.size(), 60000u) << scan;
  }
  EXPECT_EQ(io::readKittiPoses(path("kitti/poses_kitti.txt")).size(), 2u);
  EXPECT_FALSE(std::filesystem::exists(path("kitti/capture.pcap")));
}

// A named sensor's scans are plain PCD clouds (no ring) in clouds/: every
// point lies on one of the catalog's beams at its azimuth offset, its time
// is its column's firing time, and times.txt holds the ground truth's times.
TEST_F(SimulateCommand, NamedSensorsWritePlainCloudsOnTheirBeams) {
  for (const char* name : {"VLP-32C", "Pandar64"}) {
    SCOPED_TRACE(name);
    const std::string out = path(name);
    const test::RunResult run = rim(std::string("simulate --preset outdoor_car --sensor ") + name +
                                    " --frames 2 --noise 0 --out '" + out + "'");
    ASSERT_EQ(run.exit_code, 0) << run.err;
    EXPECT_FALSE(std::filesystem::exists(out + "/capture.pcap"));
    const LidarIntrinsics intrinsics = *catalogSensor(name);
    const double column_rad = 2.0 * M_PI / intrinsics.columns;
    const std::vector<double> times_s = io::readTimes(out + "/clouds/times.txt");
    const std::vector<io::StampedPose> poses = io::readPoseFile(out + "/poses_tum.txt");
    ASSERT_EQ(times_s.size(), 2u);
    ASSERT_EQ(poses.size(), 2u);
    for (std::size_t frame = 0; frame < 2; ++frame) EXPECT_NEAR(times_s[frame], poses[frame].time_s, 1e-6);
    const PointCloudInput cloud = io::readPcd(out + "/clouds/000001.pcd");
    EXPECT_TRUE(cloud.ring.empty());
    ASSERT_EQ(cloud.time_offset_s.size(), cloud.size());
    ASSERT_GT(cloud.size(), 10000u);
    std::size_t off_beam = 0;
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      const Eigen::Vector3f& p = cloud.points[i];
      const double elevation = std::atan2(p.z(), std::hypot(p.x(), p.y()));
      int row = 0;
      for (int v = 1; v < intrinsics.rows; ++v)
        if (std::abs(intrinsics.altitude_rad[v] - elevation) < std::abs(intrinsics.altitude_rad[row] - elevation))
          row = v;
      // Azimuth = encoder angle of the point's column + the beam's offset; the
      // column fires at u / (W * 10 Hz), encoder angle -2 pi u / W (Ouster's sense).
      const double encoder = std::atan2(p.y(), p.x()) - intrinsics.azimuth_offset_rad[row];
      const double column = -encoder / column_rad;
      const double wrapped = column - intrinsics.columns * std::floor(column / intrinsics.columns);
      const long u = std::lround(wrapped) % intrinsics.columns;
      const bool on_beam = std::abs(intrinsics.altitude_rad[row] - elevation) < 1e-4 &&
                           std::abs(wrapped - std::round(wrapped)) < 0.01 &&
                           std::abs(cloud.time_offset_s[i] - u / (intrinsics.columns * 10.0)) < 1e-6;
      off_beam += !on_beam;
    }
    EXPECT_EQ(off_beam, 0u) << "of " << cloud.size();
    // The folder itself is a recording of its clouds/ (scene.ply and
    // surface.ply beside them are no scans), with its ground truth.
    const test::RunResult odometry = rim("odometry '" + out + "' --out '" + out + "/est.txt'");
    ASSERT_EQ(odometry.exit_code, 0) << odometry.err;
    EXPECT_NE((odometry.out + odometry.err).find("2 .pcd scans in"), std::string::npos) << odometry.err;
  }
}

// The drivers' PointCloud2 layouts in points.bag, read back by rim with no
// sensor option: the model is estimated and must place every point, and the
// odometry must follow the ground truth of the clouds' own frame (ouster-ros
// publishes in os_sensor, half a turn from os_lidar: its organized pixels are
// not the estimate's, which once left every point outside the model).
TEST_F(SimulateCommand, DriverCloudLayoutsReadBackWithAnEstimatedModel) {
  struct Case {
    const char* layout;
    const char* sensor;
    const char* truth;
  };
  for (const Case& c : {Case{"ouster-ros", "OS-1-128", "poses_sensor_kitti.txt"},
                        Case{"velodyne", "VLP-16", "poses_kitti.txt"}, Case{"hesai", "Pandar64", "poses_kitti.txt"}}) {
    SCOPED_TRACE(c.layout);
    const std::string out = path(c.layout);
    const test::RunResult simulate =
        rim(std::string("simulate --scene outdoor --motion car --frames 6 --noise 0 --formats points-bag --sensor ") +
            c.sensor + " --cloud-layout " + c.layout + " --out '" + out + "'");
    if (simulate.err.find("bags need the catkin build") != std::string::npos)
      GTEST_SKIP() << "this rim has no bag support (core-only build)";
    ASSERT_EQ(simulate.exit_code, 0) << simulate.err;
    const test::RunResult odometry = rim("odometry '" + out + "/points.bag' --out '" + out + "/est.txt'");
    ASSERT_EQ(odometry.exit_code, 0) << odometry.out << odometry.err;
    EXPECT_NE((odometry.out + odometry.err).find("100.00 % kept"), std::string::npos) << odometry.err;
    const test::RunResult eval = rim("eval traj '" + out + "/est.txt' '" + out + "/" + c.truth + "' --json '" + out +
                                     "/eval.json'");
    ASSERT_EQ(eval.exit_code, 0) << eval.err;
    const double ate_m = test::readJsonFile(out + "/eval.json")["ate"]["translation_m"]["rmse"].asDouble();
    EXPECT_LT(ate_m, 0.06);
  }
}

TEST_F(SimulateCommand, BadRequestsFailWithANamedError) {
  const struct {
    const char* arguments;
    const char* message;
  } cases[] = {
      {"simulate --frames 2", "give --preset, or all of --sensor, --scene and --motion"},
      {"simulate --preset kitti_like --formats pcap --frames 1", "needs an Ouster sensor"},
      {"simulate --preset indoor_cart --formats tape --frames 1", "unknown format 'tape'"},
      {"simulate --sensor OS-9 --scene indoor --motion cart --frames 1", "--sensor OS-9"},
      {"simulate --preset outdoor_vlp16 --formats kitti --frames 1", "read as KITTI's HDL-64E, not VLP-16"},
      {"simulate --preset outdoor_vlp16 --cloud-layout ouster-ros --frames 1", "VLP-16 is no Ouster sensor"},
      {"simulate --sensor OS-0-128 --scene /nonexistent.ply --motion cart --frames 1", "nonexistent.ply"},
  };
  for (const auto& c : cases) {
    const test::RunResult run = rim(std::string(c.arguments) + " --out '" + path("bad") + "'");
    EXPECT_NE(run.exit_code, 0) << c.arguments;
    EXPECT_NE(run.err.find(c.message), std::string::npos) << c.arguments << "\n" << run.err;
  }
}

}  // namespace
}  // namespace range_image_mapping::simulation
