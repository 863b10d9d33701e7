#include "range_image_mapping/point_cloud_projection.h"

#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/ouster_metadata.h"
#include "test_data.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <limits>
#include <random>

namespace range_image_mapping {
namespace {

constexpr double kDegree = M_PI / 180.0;
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// An Ouster-like sensor: uneven altitudes, alternating azimuth offsets, a beam
// origin off the axis and non-zero stagger shifts.
LidarIntrinsics ousterLikeIntrinsics(int rows = 16, int columns = 128) {
  LidarIntrinsics intrinsics =
      LidarIntrinsics::synthetic(rows, columns, 16.0 * kDegree, -16.0 * kDegree);
  for (int v = 0; v < rows; ++v) {
    intrinsics.altitude_rad[v] += 0.2 * kDegree * std::sin(v);  // uneven spacing
    intrinsics.azimuth_offset_rad[v] = (v % 4 - 1.5) * 1.4 * kDegree;
    intrinsics.pixel_shift_by_row[v] = (3 - v % 4) * 4;
  }
  intrinsics.beam_origin_radius_m = 0.01508;
  intrinsics.beam_origin_z_m = 0.0;
  intrinsics.sensor_model = "ouster-like";
  return intrinsics;
}

// A scene-like range image: smooth ranges between 1.5 m and 40 m, a few holes.
RangeImage sceneImage(const LidarModelConstPtr& model) {
  RangeImage image(model);
  for (int v = 0; v < image.rows(); ++v)
    for (int u = 0; u < image.columns(); ++u) {
      const bool hole = (u * 7 + v * 3) % 23 == 0;
      image.range[image.index(v, u)] =
          hole ? kNaN
               : static_cast<float>(1.5 + 19.0 * (1.0 + std::sin(0.05 * u + 0.3 * v)) + 0.01 * v);
    }
  return image;
}

// The organized cloud the image unprojects to: staggered (as Pi^-1 gives it)
// or destaggered (as the Ouster driver publishes it). Holes are NaN points.
PointCloudInput organizedCloud(const RangeImage& image, ColumnOrder order) {
  const LidarModel& model = *image.model;
  const int rows = image.rows(), columns = image.columns();
  PointCloudInput cloud;
  cloud.organized_height = rows;
  cloud.organized_width = columns;
  cloud.organized_column_order = order;
  cloud.points.assign(static_cast<std::size_t>(rows) * columns, Eigen::Vector3f::Constant(kNaN));
  cloud.intensity.assign(cloud.points.size(), 0.0f);
  cloud.time_offset_s.assign(cloud.points.size(), 0.0f);
  for (int v = 0; v < rows; ++v) {
    const int shift =
        order == ColumnOrder::kDestaggered ? model.intrinsics().pixel_shift_by_row[v] : 0;
    for (int u = 0; u < columns; ++u) {
      const int input_column = ((u + shift) % columns + columns) % columns;
      const std::size_t i = static_cast<std::size_t>(v) * columns + input_column;
      cloud.intensity[i] = static_cast<float>(v * 1000 + u);
      cloud.time_offset_s[i] = 1e-5f * static_cast<float>(u);
      if (image.valid(v, u)) cloud.points[i] = model.unproject(u, v, image.at(v, u));
    }
  }
  return cloud;
}

void expectSameRanges(const RangeImage& expected, const RangeImage& actual, float tolerance) {
  ASSERT_EQ(expected.range.size(), actual.range.size());
  int mismatches = 0;
  for (std::size_t i = 0; i < expected.range.size(); ++i) {
    const bool valid = isValidRange(expected.range[i]);
    const bool same = valid ? std::abs(actual.range[i] - expected.range[i]) <= tolerance
                            : !isValidRange(actual.range[i]);
    if (!same && ++mismatches <= 5)
      ADD_FAILURE() << "pixel " << i << ": expected " << expected.range[i] << ", got "
                    << actual.range[i];
  }
  EXPECT_EQ(mismatches, 0);
}

// ---------------------------------------------------------------- organized

TEST(OrganizedCloud, StaggeredInputMapsPixelForPixel) {
  const auto model = std::make_shared<const LidarModel>(ousterLikeIntrinsics());
  const RangeImage truth = sceneImage(model);
  PointCloudInput cloud = organizedCloud(truth, ColumnOrder::kStaggered);
  cloud.stamp_ns = 1'000'000'000;
  ProjectionStatistics statistics;
  const RangeImage image = projectPointCloud(cloud, model, &statistics);

  expectSameRanges(truth, image, 2e-5f);
  EXPECT_EQ(image.column_order, ColumnOrder::kStaggered);
  EXPECT_EQ(statistics.input_points, cloud.size());
  EXPECT_EQ(statistics.non_finite, cloud.size() - truth.validCount());
  EXPECT_EQ(statistics.kept, truth.validCount());
  EXPECT_DOUBLE_EQ(statistics.keptFraction(), 1.0);
  EXPECT_LT(statistics.max_ray_distance_m, 1e-4);
  for (int v = 0; v < image.rows(); ++v)
    for (int u = 0; u < image.columns(); ++u)
      if (image.valid(v, u)) ASSERT_EQ(image.intensity[image.index(v, u)], float(v * 1000 + u));
  // Column u's points all carry 1e-5 * u s.
  EXPECT_NEAR(double(image.column_timestamp_ns[100]), 1e9 + 1e-5 * 100 * 1e9, 2.0);
  EXPECT_EQ(image.stamp_ns, cloud.stamp_ns);
}

TEST(OrganizedCloud, DestaggeredInputGivesTheSameImage) {
  const auto model = std::make_shared<const LidarModel>(ousterLikeIntrinsics());
  const RangeImage truth = sceneImage(model);
  const RangeImage from_staggered =
      projectPointCloud(organizedCloud(truth, ColumnOrder::kStaggered), model);
  const RangeImage from_destaggered =
      projectPointCloud(organizedCloud(truth, ColumnOrder::kDestaggered), model);
  expectSameRanges(truth, from_destaggered, 2e-5f);
  expectSameRanges(from_staggered, from_destaggered, 0.0f);
  EXPECT_EQ(from_staggered.intensity, from_destaggered.intensity);

  // Destaggered input declared staggered: its pixels are not the model's
  // (points columns off their rays), so it is projected point by point and
  // still gives the image, where pixel for pixel would scramble it.
  PointCloudInput mislabelled = organizedCloud(truth, ColumnOrder::kDestaggered);
  mislabelled.organized_column_order = ColumnOrder::kStaggered;
  EXPECT_GT(organizedOffRayAngle(mislabelled, *model, ColumnOrder::kStaggered), M_PI / model->columns());
  EXPECT_LT(organizedOffRayAngle(mislabelled, *model, ColumnOrder::kDestaggered), 1e-4);
  ProjectionStatistics statistics;
  const RangeImage image = projectPointCloud(mislabelled, model, &statistics);
  EXPECT_EQ(statistics.max_ray_distance_m, 0.0) << "projected pixel for pixel";
  EXPECT_GT(statistics.keptFraction(), 0.99);
  std::size_t near_truth = 0;
  for (std::size_t i = 0; i < truth.range.size(); ++i)
    near_truth += isValidRange(truth.range[i]) && isValidRange(image.range[i]) &&
                  std::abs(truth.range[i] - image.range[i]) < 1e-3f;
  EXPECT_GT(double(near_truth), 0.98 * double(truth.validCount()));
}

TEST(OrganizedCloud, NonFiniteAndOriginPointsAreDroppedAndCounted) {
  const auto model = std::make_shared<const LidarModel>(ousterLikeIntrinsics());
  const RangeImage truth = sceneImage(model);
  PointCloudInput cloud = organizedCloud(truth, ColumnOrder::kStaggered);
  std::size_t non_finite = cloud.size() - truth.validCount();
  // Turn some valid points into Inf and some into origin points ("no return").
  std::size_t no_return = 0;
  RangeImage expected = truth;
  for (std::size_t i = 0; i < cloud.size(); i += 37) {
    if (!cloud.points[i].allFinite()) continue;
    if ((i / 37) % 2) {
      cloud.points[i].y() = std::numeric_limits<float>::infinity();
      ++non_finite;
    } else {
      cloud.points[i].setZero();
      ++no_return;
    }
    expected.range[i] = kNaN;
  }
  ProjectionStatistics statistics;
  const RangeImage image = projectPointCloud(cloud, model, &statistics);
  expectSameRanges(expected, image, 2e-5f);
  EXPECT_EQ(statistics.non_finite, non_finite);
  EXPECT_EQ(statistics.no_return, no_return);
  EXPECT_EQ(statistics.kept, expected.validCount());
  EXPECT_EQ(statistics.measured(), statistics.kept);
}

TEST(OrganizedCloud, RealOusterIntrinsicsRoundTrip) {
  RIM_REQUIRE_DATA(metadata_path, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  const auto model =
      std::make_shared<const LidarModel>(loadOusterMetadata(metadata_path).intrinsics);
  ASSERT_EQ(model->rows(), 128);
  ASSERT_GT(model->intrinsics().beam_origin_radius_m, 0.0);
  const RangeImage truth = sceneImage(model);
  for (const ColumnOrder order : {ColumnOrder::kStaggered, ColumnOrder::kDestaggered}) {
    ProjectionStatistics statistics;
    const RangeImage image = projectPointCloud(organizedCloud(truth, order), model, &statistics);
    expectSameRanges(truth, image, 2e-5f);
    EXPECT_EQ(statistics.kept, truth.validCount());
    EXPECT_LT(statistics.max_ray_distance_m, 1e-4);
  }
}

TEST(OrganizedCloud, CloudsTurnedHalfATurnAreProjectedPointByPoint) {
  const auto model = std::make_shared<const LidarModel>(ousterLikeIntrinsics());
  PointCloudInput cloud = organizedCloud(sceneImage(model), ColumnOrder::kStaggered);
  EXPECT_LT(organizedOffRayAngle(cloud, *model, ColumnOrder::kStaggered), 1e-4);
  // The Ouster sensor frame is the lidar frame turned 180 deg about z (as
  // ouster-ros publishes them, against a model estimated in that frame):
  // every organized pixel is half a turn off its ray, and pixel for pixel
  // would put every point behind the sensor.
  for (Eigen::Vector3f& point : cloud.points) point.head<2>() *= -1.0f;
  EXPECT_GT(organizedOffRayAngle(cloud, *model, ColumnOrder::kStaggered), 2.0);  // pi less twice the elevation
  ProjectionStatistics statistics;
  projectPointCloud(cloud, model, &statistics);
  EXPECT_GT(statistics.keptFraction(), 0.99);
  EXPECT_EQ(statistics.max_ray_distance_m, 0.0) << "projected pixel for pixel";
}

// ---------------------------------------------------------------- unorganized through Pi

TEST(UnorganizedCloud, ShuffledPointsThroughPiRebuildTheImage) {
  const auto model = std::make_shared<const LidarModel>(ousterLikeIntrinsics());
  const RangeImage truth = sceneImage(model);
  PointCloudInput cloud;
  cloud.points = truth.unprojectAll();
  std::shuffle(cloud.points.begin(), cloud.points.end(), std::mt19937(7));
  cloud.organized_width = static_cast<int>(cloud.size());
  ProjectionStatistics statistics;
  const RangeImage image = projectPointCloud(cloud, model, &statistics);
  expectSameRanges(truth, image, 1e-4f);
  EXPECT_EQ(statistics.kept, truth.validCount());
  EXPECT_EQ(statistics.occluded, 0u);
}

TEST(UnorganizedCloud, NearestReturnWinsAndColumnTimeIsTheEarliest) {
  const auto model =
      std::make_shared<const LidarModel>(LidarIntrinsics::synthetic(8, 64, 0.2, -0.2));
  PointCloudInput cloud;
  const int u = 10, v = 3;
  for (const float range : {7.0f, 3.0f, 5.0f})
    cloud.points.push_back(model->unproject(u, v, range));
  cloud.intensity = {70.0f, 30.0f, 50.0f};
  cloud.time_offset_s = {0.002f, 0.003f, 0.001f};
  cloud.stamp_ns = 5'000'000;
  ProjectionStatistics statistics;
  const RangeImage image = projectPointCloud(cloud, model, &statistics);
  EXPECT_NEAR(image.at(v, u), 3.0f, 1e-5f);
  EXPECT_EQ(image.intensity[image.index(v, u)], 30.0f);
  EXPECT_EQ(statistics.kept, 1u);
  EXPECT_EQ(statistics.occluded, 2u);
  EXPECT_EQ(image.validCount(), 1u);
  EXPECT_EQ(image.column_timestamp_ns[u], 5'000'000u + 1'000'000u);
  EXPECT_EQ(image.column_timestamp_ns[u + 1], 0u);
}

TEST(UnorganizedCloud, KittiScanKeepsMostPointsLosslessly) {
  RIM_REQUIRE_DATA(scan_path, "kitti00/velodyne/000094.bin");
  const PointCloudInput cloud = io::readKittiVelodyne(scan_path);
  constexpr int kColumns = 4096;  // 2048 columns keep only 80 %: two points often share a pixel
  const auto model = std::make_shared<const LidarModel>(io::kittiHdl64Intrinsics(kColumns));
  ProjectionStatistics statistics;
  const auto start = std::chrono::steady_clock::now();
  const RangeImage image = projectPointCloud(cloud, model, &statistics);
  const double milliseconds =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  std::cout << "KITTI 000094: " << statistics.input_points << " points, kept " << statistics.kept
            << " (" << 100.0 * statistics.keptFraction() << " %), occluded " << statistics.occluded
            << ", outside " << statistics.outside_model << ", " << milliseconds << " ms\n";
  EXPECT_GE(statistics.keptFraction(), 0.9);
  EXPECT_EQ(statistics.kept + statistics.occluded + statistics.outside_model,
            statistics.measured());

  // Independent reference: the paper's synthetic projection written out with
  // plain trigonometry, the nearest point per pixel kept.
  const double fov_up = 3.0 * kDegree, fov_down = -25.0 * kDegree;
  const double row_step = (fov_up - fov_down) / 63.0;
  std::vector<float> nearest(image.range.size(), std::numeric_limits<float>::infinity());
  std::vector<Eigen::Vector3f> nearest_point(image.range.size());
  for (const Eigen::Vector3f& point : cloud.points) {
    const double range = point.cast<double>().norm();
    const double row = (fov_up - std::asin(point.z() / range)) / row_step;
    const double azimuth = std::atan2(double(point.y()), double(point.x()));
    const double column =
        std::fmod(-azimuth / (2.0 * M_PI) * kColumns + 2.0 * kColumns, double(kColumns));
    const long v = std::lround(row);
    const long u = std::lround(column) % kColumns;
    if (v < 0 || v > 63) continue;
    const std::size_t i = image.index(static_cast<int>(v), static_cast<int>(u));
    if (range < nearest[i]) {
      nearest[i] = static_cast<float>(range);
      nearest_point[i] = point;
    }
  }
  std::size_t disagreements = 0, checked = 0;
  for (int v = 0; v < image.rows(); ++v) {
    for (int u = 0; u < image.columns(); ++u) {
      const std::size_t i = image.index(v, u);
      if (image.valid(v, u) != std::isfinite(nearest[i])) {
        ++disagreements;  // a point on a pixel border, rounded the other way
        continue;
      }
      if (!image.valid(v, u)) continue;
      // Within 1 mm of the nearest point's range, and its direction inside the pixel.
      if (std::abs(image.at(v, u) - nearest[i]) > 1e-3f) {
        ++disagreements;
        continue;
      }
      ++checked;
      const Eigen::Vector3f unprojected = model->unproject(u, v, image.at(v, u));
      const Eigen::Vector3f& original = nearest_point[i];
      const double azimuth_error = std::remainder(
          std::atan2(unprojected.y(), unprojected.x()) - std::atan2(original.y(), original.x()),
          2 * M_PI);
      const double elevation_error = std::asin(unprojected.z() / unprojected.norm()) -
                                     std::asin(original.z() / original.norm());
      ASSERT_LE(std::abs(azimuth_error), M_PI / kColumns + 1e-6) << "pixel " << v << ", " << u;
      ASSERT_LE(std::abs(elevation_error), 0.5 * row_step + 1e-6) << "pixel " << v << ", " << u;
      ASSERT_NEAR(unprojected.norm(), original.norm(), 1e-3) << "pixel " << v << ", " << u;
    }
  }
  std::cout << "checked " << checked << " pixels against the reference, " << disagreements
            << " border disagreements\n";
  EXPECT_LT(disagreements, image.validCount() / 1000);
}

// ---------------------------------------------------------------- rings

// Points of every pixel of the scene image with a ring field; ring order
// Velodyne (ring 0 lowest) or Ouster (ring 0 highest). Elevations jitter by
// up to +-0.004 deg around each beam, as real beams do around their nominal angle.
PointCloudInput ringCloud(const RangeImage& image, bool lowest_ring_first) {
  const LidarModel& model = *image.model;
  PointCloudInput cloud;
  std::mt19937 generator(3);
  std::uniform_real_distribution<float> jitter(-0.004f * float(kDegree), 0.004f * float(kDegree));
  for (int v = 0; v < image.rows(); ++v)
    for (int u = 0; u < image.columns(); ++u) {
      if (!image.valid(v, u)) continue;
      const Eigen::Vector3f point = model.unproject(u, v, image.at(v, u));
      const Eigen::Vector3f horizontal_normal =
          Eigen::Vector3f(-point.y(), point.x(), 0.0f).normalized();
      cloud.points.push_back(Eigen::AngleAxisf(jitter(generator), horizontal_normal) * point);
      cloud.ring.push_back(static_cast<uint16_t>(lowest_ring_first ? image.rows() - 1 - v : v));
      cloud.intensity.push_back(static_cast<float>(v));
    }
  cloud.organized_width = static_cast<int>(cloud.size());
  return cloud;
}

LidarIntrinsics hdl32LikeIntrinsics() {
  LidarIntrinsics intrinsics =
      LidarIntrinsics::synthetic(32, 1024, 10.67 * kDegree, -30.67 * kDegree);
  for (int v = 0; v < 32; ++v) intrinsics.altitude_rad[v] += 0.1 * kDegree * std::cos(3.0 * v);
  return intrinsics;
}

TEST(RingCloud, IntrinsicsFromRingsInBothRingOrders) {
  const LidarIntrinsics truth_intrinsics = hdl32LikeIntrinsics();
  const auto truth_model = std::make_shared<const LidarModel>(truth_intrinsics);
  const RangeImage truth = sceneImage(truth_model);
  for (const bool lowest_ring_first : {true, false}) {
    SCOPED_TRACE(lowest_ring_first ? "Velodyne ring order" : "Ouster ring order");
    const PointCloudInput cloud = ringCloud(truth, lowest_ring_first);
    const RingIntrinsics rings = intrinsicsFromRings(cloud, 1024);
    ASSERT_EQ(rings.intrinsics.rows, 32);
    ASSERT_EQ(rings.ring_to_row.size(), 32u);
    for (int ring = 0; ring < 32; ++ring) {
      const int row = rings.ring_to_row[ring];
      EXPECT_EQ(row, lowest_ring_first ? 31 - ring : ring);
      EXPECT_NEAR(rings.intrinsics.altitude_rad[row] / kDegree,
                  truth_intrinsics.altitude_rad[row] / kDegree, 0.01);
    }
    for (int row = 1; row < 32; ++row)
      EXPECT_GT(rings.intrinsics.altitude_rad[row - 1], rings.intrinsics.altitude_rad[row]);

    // The rows come out highest first: projecting by ring rebuilds the image.
    const auto model = std::make_shared<const LidarModel>(rings.intrinsics);
    ProjectionStatistics statistics;
    const RangeImage image = projectPointCloud(cloud, model, rings.ring_to_row, &statistics);
    expectSameRanges(truth, image, 1e-3f);
    EXPECT_EQ(statistics.kept, truth.validCount());
    for (int v = 0; v < 32; ++v)
      for (int u = 0; u < 1024; ++u)
        if (image.valid(v, u)) ASSERT_EQ(image.intensity[image.index(v, u)], float(v));
  }
}

TEST(RingCloud, RingPathHandlesAzimuthOffsetsAndBeamOrigin) {
  const auto model = std::make_shared<const LidarModel>(ousterLikeIntrinsics(16, 512));
  const RangeImage truth = sceneImage(model);
  PointCloudInput cloud = ringCloud(truth, false);
  std::vector<int> identity(16);
  for (int ring = 0; ring < 16; ++ring) identity[ring] = ring;
  ProjectionStatistics statistics;
  const RangeImage image = projectPointCloud(cloud, model, identity, &statistics);
  expectSameRanges(truth, image, 1e-3f);
  EXPECT_EQ(statistics.occluded, 0u);

  // A ring the map does not know is outside the model.
  cloud.ring[0] = 16;
  projectPointCloud(cloud, model, identity, &statistics);
  EXPECT_EQ(statistics.outside_model, 1u);
}

TEST(RingCloud, MissingRingIsNamed) {
  const auto model = std::make_shared<const LidarModel>(hdl32LikeIntrinsics());
  PointCloudInput cloud = ringCloud(sceneImage(model), true);
  for (std::size_t i = 0; i < cloud.size(); ++i)
    if (cloud.ring[i] == 5) cloud.points[i].x() = kNaN;  // ring 5 has only invalid points
  try {
    intrinsicsFromRings(cloud, 1024);
    FAIL() << "expected IntrinsicsError";
  } catch (const IntrinsicsError& error) {
    EXPECT_NE(std::string(error.what()).find("ring 5 has no points"), std::string::npos)
        << error.what();
  }
  cloud.ring.clear();
  EXPECT_THROW(intrinsicsFromRings(cloud, 1024), IntrinsicsError);
}

// ---------------------------------------------------------------- bad input

TEST(ProjectionInput, InconsistentArraysAreRejected) {
  const auto model =
      std::make_shared<const LidarModel>(LidarIntrinsics::synthetic(8, 64, 0.2, -0.2));
  PointCloudInput cloud;
  cloud.points.assign(10, Eigen::Vector3f(1, 0, 0));
  cloud.intensity.assign(9, 0.0f);
  EXPECT_THROW(projectPointCloud(cloud, model), PointCloudError);
  cloud.intensity.clear();
  cloud.organized_height = 3;
  cloud.organized_width = 3;
  EXPECT_THROW(projectPointCloud(cloud, model), PointCloudError);
  cloud.organized_height = 1;
  EXPECT_THROW(projectPointCloud(cloud, model, std::vector<int>{0, 8}), PointCloudError);
  EXPECT_THROW(projectPointCloud(cloud, nullptr), PointCloudError);
  EXPECT_NO_THROW(projectPointCloud(cloud, model));
}

}  // namespace
}  // namespace range_image_mapping
