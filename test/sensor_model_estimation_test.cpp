// Sensor models estimated from plain clouds: exact on synthetic tables, the
// Ouster captures' metadata recovered from their unprojected x, y, z, and
// KITTI's HDL-64E scans kept far better than by the synthetic 64 x 2048 model.
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/sensor_model_estimation.h"
#include "test_data.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

namespace range_image_mapping {
namespace {

constexpr double kDeg = M_PI / 180.0;

// A 16-beam sensor with uneven spacing, per-beam azimuth offsets of several
// columns and an Ouster-like beam origin.
LidarIntrinsics unevenSensor() {
  LidarIntrinsics intrinsics;
  intrinsics.rows = 16;
  intrinsics.columns = 1024;
  const double altitude_deg[16] = {15.0, 12.1, 9.5, 7.2, 5.0, 3.1, 1.4, 0.0,
                                   -1.3, -2.9, -4.6, -6.8, -9.1, -11.7, -14.2, -17.0};
  for (int v = 0; v < 16; ++v) {
    intrinsics.altitude_rad.push_back(altitude_deg[v] * kDeg);
    intrinsics.azimuth_offset_rad.push_back(((v % 4) - 1.5) * 2.8 * kDeg + 0.013 * kDeg * v);
  }
  intrinsics.beam_origin_radius_m = 0.0158;
  intrinsics.sensor_model = "uneven";
  return intrinsics;
}

// Every pixel unprojected at a random range (0.8-40 m), as a plain cloud and
// with the pixel each point came from.
struct PixelCloud {
  PointCloudInput cloud;
  std::vector<std::pair<int, int>> pixels;  // row, column
};

PixelCloud unprojectEveryPixel(const LidarModel& model, unsigned seed, bool with_rings = false) {
  PixelCloud result;
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> range(0.8f, 40.0f);
  for (int v = 0; v < model.rows(); ++v)
    for (int u = 0; u < model.columns(); ++u) {
      result.cloud.points.push_back(model.unproject(u, v, range(random)));
      result.pixels.push_back({v, u});
      // Velodyne's ring order: ring 0 is the lowest beam.
      if (with_rings) result.cloud.ring.push_back(static_cast<uint16_t>(model.rows() - 1 - v));
    }
  return result;
}

double ownPixelShare(const std::vector<PixelCloud>& clouds, const LidarModel& model) {
  std::size_t own = 0, total = 0;
  for (const PixelCloud& c : clouds)
    for (std::size_t i = 0; i < c.cloud.size(); ++i) {
      const auto pixel = model.project(c.cloud.points[i]);
      ++total;
      own += pixel && pixel->row == c.pixels[i].first && pixel->column == c.pixels[i].second;
    }
  return total ? double(own) / double(total) : 0.0;
}

double largestDifferenceDeg(const std::vector<double>& a, const std::vector<double>& b) {
  double largest = 0.0;
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i)
    largest = std::max(largest, std::abs(std::remainder(a[i] - b[i], 2 * M_PI)));
  return largest / kDeg;
}

TEST(SensorModelEstimation, RecoversUnevenBeamsOffsetsAndBeamOrigin) {
  const LidarModel truth(unevenSensor());
  const std::vector<PixelCloud> clouds{unprojectEveryPixel(truth, 1), unprojectEveryPixel(truth, 2)};
  const SensorEstimate estimate = estimateSensorModel({clouds[0].cloud, clouds[1].cloud});
  const LidarIntrinsics& found = estimate.intrinsics;
  ASSERT_EQ(found.rows, 16);
  EXPECT_EQ(found.columns, 1024);
  EXPECT_NEAR(found.beam_origin_radius_m, 0.0158, 1e-5);
  EXPECT_NEAR(found.beam_origin_z_m, 0.0, 1e-5);
  EXPECT_LT(largestDifferenceDeg(found.altitude_rad, truth.intrinsics().altitude_rad), 1e-3);
  EXPECT_LT(largestDifferenceDeg(found.azimuth_offset_rad, truth.intrinsics().azimuth_offset_rad), 1e-3);
  EXPECT_NEAR(estimate.azimuth_step_deg, 360.0 / 1024, 0.002);
  EXPECT_EQ(ownPixelShare(clouds, LidarModel(found)), 1.0);
  EXPECT_EQ(estimate.fit.measured_points, 2u * 16 * 1024);
  EXPECT_EQ(estimate.fit.kept, estimate.fit.measured_points);
  EXPECT_LT(estimate.fit.elevation_residual_deg, 1e-3);
  EXPECT_LT(estimate.fit.azimuth_residual_deg, 1e-3);
}

TEST(SensorModelEstimation, RingFieldGivesTheRowsAndTheRingMap) {
  const LidarModel truth(unevenSensor());
  const PixelCloud cloud = unprojectEveryPixel(truth, 3, true);
  const SensorEstimate estimate = estimateSensorModel({cloud.cloud});
  EXPECT_EQ(estimate.intrinsics.sensor_model, "estimated from rings");
  ASSERT_EQ(estimate.intrinsics.rows, 16);
  ASSERT_EQ(estimate.ring_to_row.size(), 16u);
  for (int ring = 0; ring < 16; ++ring) EXPECT_EQ(estimate.ring_to_row[ring], 15 - ring) << "ring " << ring;
  EXPECT_LT(largestDifferenceDeg(estimate.intrinsics.altitude_rad, truth.intrinsics().altitude_rad), 1e-3);
  EXPECT_EQ(estimate.fit.kept, estimate.fit.measured_points);
}

TEST(SensorModelEstimation, FixedColumnCountAndNoBeamOrigin) {
  LidarIntrinsics intrinsics = unevenSensor();
  intrinsics.beam_origin_radius_m = 0.0;
  const LidarModel truth(intrinsics);
  const PixelCloud cloud = unprojectEveryPixel(truth, 4);
  SensorEstimationOptions options;
  options.columns = 2048;
  options.estimate_beam_origin = false;
  const SensorEstimate estimate = estimateSensorModel({cloud.cloud}, options);
  EXPECT_EQ(estimate.intrinsics.columns, 2048);
  EXPECT_EQ(estimate.intrinsics.beam_origin_radius_m, 0.0);
  EXPECT_LT(largestDifferenceDeg(estimate.intrinsics.altitude_rad, intrinsics.altitude_rad), 1e-3);
  EXPECT_EQ(estimate.fit.kept, estimate.fit.measured_points);
}

TEST(SensorModelEstimation, RefusesCloudsWithoutEnoughPoints) {
  PointCloudInput cloud;
  for (int i = 0; i < 500; ++i) cloud.points.emplace_back(10.0f, 0.01f * i, 0.0f);
  cloud.points.emplace_back(std::nanf(""), 0.0f, 0.0f);
  try {
    estimateSensorModel({cloud});
    FAIL() << "expected SensorEstimationError";
  } catch (const SensorEstimationError& error) {
    EXPECT_NE(std::string(error.what()).find("500 usable points"), std::string::npos) << error.what();
  }
  EXPECT_THROW(estimateSensorModel({}), SensorEstimationError);
}

// The Ouster captures decoded by the project's reader, unprojected to plain
// x, y, z in the lidar frame (what a driver gives): the beam tables within
// 0.02 deg of the metadata, and 99 % of the points back in their own pixel.
struct OusterCapture {
  const char* pcap;
  const char* metadata;
};

class OusterCaptureEstimation : public ::testing::TestWithParam<OusterCapture> {};

TEST_P(OusterCaptureEstimation, MatchesTheMetadata) {
  RIM_REQUIRE_DATA(pcap, std::string("ouster-pcaps/") + GetParam().pcap);
  RIM_REQUIRE_DATA(metadata_path, std::string("ouster-pcaps/") + GetParam().metadata);
  const OusterMetadata metadata = loadOusterMetadata(metadata_path);
  std::vector<PixelCloud> clouds;
  for (const RangeImage& image : io::readOusterRangeImages(pcap, metadata)) {
    PixelCloud cloud;
    for (int v = 0; v < image.rows(); ++v)
      for (int u = 0; u < image.columns(); ++u)
        if (image.valid(v, u)) {
          cloud.cloud.points.push_back(image.model->unproject(u, v, image.at(v, u)));
          cloud.pixels.push_back({v, u});
        }
    clouds.push_back(std::move(cloud));
  }
  ASSERT_FALSE(clouds.empty());
  std::vector<PointCloudInput> plain;
  for (const PixelCloud& c : clouds) plain.push_back(c.cloud);
  const SensorEstimate estimate = estimateSensorModel(plain);
  const LidarIntrinsics& found = estimate.intrinsics;
  const LidarIntrinsics& truth = metadata.intrinsics;
  ASSERT_EQ(found.rows, truth.rows);
  ASSERT_EQ(found.columns, truth.columns);
  const double altitude_error = largestDifferenceDeg(found.altitude_rad, truth.altitude_rad);
  const double azimuth_error = largestDifferenceDeg(found.azimuth_offset_rad, truth.azimuth_offset_rad);
  const double own = ownPixelShare(clouds, LidarModel(found));
  std::printf("%s: %d x %d, r0 %.3f mm (metadata %.3f), largest error altitude %.2e deg, azimuth %.2e deg, "
              "own pixel %.4f, kept %.4f, residual %.1e / %.1e deg\n",
              GetParam().pcap, found.rows, found.columns, found.beam_origin_radius_m * 1e3,
              truth.beam_origin_radius_m * 1e3, altitude_error, azimuth_error, own, estimate.fit.keptShare(),
              estimate.fit.elevation_residual_deg, estimate.fit.azimuth_residual_deg);
  EXPECT_LT(altitude_error, 0.02);
  EXPECT_LT(azimuth_error, 0.02);
  EXPECT_GE(own, 0.99);
  EXPECT_NEAR(found.beam_origin_radius_m, truth.beam_origin_radius_m, 1e-4);
}

INSTANTIATE_TEST_SUITE_P(
    Captures, OusterCaptureEstimation,
    ::testing::Values(OusterCapture{"OS-0-128-U1_v2.3.0_1024x10.pcap", "OS-0-128-U1_v2.3.0_1024x10.json"},
                      OusterCapture{"OS-1-128_v2.3.0_1024x10_lb_n3.pcap", "OS-1-128_v2.3.0_1024x10.json"},
                      OusterCapture{"OS-2-128-U1_v2.3.0_1024x10.pcap", "OS-2-128-U1_v2.3.0_1024x10.json"},
                      OusterCapture{"OS-0-32-U1_v2.2.0_1024x10.pcap", "OS-0-32-U1_v2.2.0_1024x10.json"},
                      OusterCapture{"OS-1-32-G_v2.1.1_1024x10.pcap", "OS-1-32-G_v2.1.1_1024x10.json"},
                      OusterCapture{"OS-2-32-U0_v2.0.0_1024x10.pcap", "OS-2-32-U0_v2.0.0_1024x10.json"}),
    [](const ::testing::TestParamInfo<OusterCapture>& info) {
      std::string name = info.param.metadata;
      name = name.substr(0, name.find('_'));
      for (char& c : name)
        if (c == '-') c = '_';
      return name;
    });

// KITTI's HDL-64E: at least 97 % of the points keep a pixel of their own
// (the synthetic 64 x 2048 model keeps about 80 %).
void expectKittiKept(const std::vector<std::string>& files) {
  std::vector<PointCloudInput> scans;
  for (const std::string& file : files) scans.push_back(io::readKittiVelodyne(file));
  const SensorEstimate estimate = estimateSensorModel(scans);
  const SensorModelFit synthetic =
      measureSensorModelFit(scans, std::make_shared<const LidarModel>(io::kittiHdl64Intrinsics()));
  std::printf("%s (+%zu): %d x %d, beam origin %.1f mm up, step %.4f deg; kept %.4f (outside %.4f, "
              "shared pixel %.4f), residual %.3f / %.3f deg; synthetic 64 x 2048 keeps %.4f\n",
              files[0].c_str(), files.size() - 1, estimate.intrinsics.rows, estimate.intrinsics.columns,
              estimate.intrinsics.beam_origin_z_m * 1e3, estimate.azimuth_step_deg, estimate.fit.keptShare(),
              estimate.fit.outsideShare(), estimate.fit.occludedShare(), estimate.fit.elevation_residual_deg,
              estimate.fit.azimuth_residual_deg, synthetic.keptShare());
  EXPECT_GE(estimate.fit.keptShare(), 0.97);
  EXPECT_GT(estimate.fit.keptShare(), synthetic.keptShare());
  EXPECT_GE(estimate.intrinsics.rows, 64);
}

TEST(SensorModelEstimation, KittiOdometryScansKeepTheirPoints) {
  RIM_REQUIRE_DATA(first, "kitti00/velodyne/000094.bin");
  RIM_REQUIRE_DATA(second, "kitti00/velodyne/000095.bin");
  expectKittiKept({first, second});
}

TEST(SensorModelEstimation, KittiRawScansKeepTheirPoints) {
  std::vector<std::string> files;
  for (const char* name : {"000000.bin", "000001.bin", "000002.bin"}) {
    RIM_REQUIRE_DATA(file, std::string("kitti-raw-22/velodyne/") + name);
    files.push_back(file);
  }
  expectKittiKept(files);
}

}  // namespace
}  // namespace range_image_mapping
