// Pi and Pi^-1 on synthetic and Ouster-like tables (real tables: projection_real_data_test).
#include "range_image_mapping/lidar_intrinsics.h"
#include "range_image_mapping/range_image.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace range_image_mapping {
namespace {

constexpr double kDegree = M_PI / 180.0;

// Non-uniform beams with azimuth offsets and an origin offset, like an OS0-128.
LidarIntrinsics ousterLikeIntrinsics(int rows, int columns) {
  LidarIntrinsics intrinsics;
  intrinsics.rows = rows;
  intrinsics.columns = columns;
  for (int v = 0; v < rows; ++v) {
    const double t = double(v) / (rows - 1);
    intrinsics.altitude_rad.push_back((45.0 - 91.0 * t - 1.5 * std::sin(3.0 * t)) * kDegree);
    intrinsics.azimuth_offset_rad.push_back(((v % 4) - 1.5) * 1.4 * kDegree);
    intrinsics.pixel_shift_by_row.push_back((3 - v % 4) * columns / 128);
  }
  intrinsics.beam_origin_radius_m = 0.02767;
  return intrinsics;
}

TEST(LidarIntrinsics, RejectsInconsistentTablesNamingTheField) {
  LidarIntrinsics intrinsics = ousterLikeIntrinsics(32, 1024);
  intrinsics.altitude_rad.pop_back();
  try {
    intrinsics.validate();
    FAIL() << "expected an error";
  } catch (const IntrinsicsError& error) {
    EXPECT_NE(std::string(error.what()).find("altitude_rad has 31 entries"), std::string::npos)
        << error.what();
  }
  intrinsics = ousterLikeIntrinsics(32, 1024);
  intrinsics.azimuth_offset_rad[3] = std::nan("");
  EXPECT_THROW(intrinsics.validate(), IntrinsicsError);
  intrinsics = ousterLikeIntrinsics(32, 1024);
  intrinsics.columns = 0;
  EXPECT_THROW(intrinsics.validate(), IntrinsicsError);
  intrinsics = ousterLikeIntrinsics(32, 1024);
  intrinsics.column_window = {5, 2000};
  EXPECT_THROW(intrinsics.validate(), IntrinsicsError);
  EXPECT_THROW(LidarIntrinsics::synthetic(64, 2048, -0.1, 0.1), IntrinsicsError);
}

TEST(LidarModel, UnprojectionFollowsTheOusterFormula) {
  const LidarModel model(ousterLikeIntrinsics(64, 1024));
  const auto& in = model.intrinsics();
  const double n = in.beam_origin_radius_m;
  for (int v : {0, 17, 63})
    for (int u : {0, 1, 255, 511, 1023}) {
      const double r = 7.25;
      const double theta_e = 2 * M_PI - 2 * M_PI * u / in.columns;
      const double theta = theta_e + in.azimuth_offset_rad[v];
      const double phi = in.altitude_rad[v];
      const Eigen::Vector3d d(std::cos(theta) * std::cos(phi), std::sin(theta) * std::cos(phi),
                              std::sin(phi));
      const Eigen::Vector3d expected =
          (r - n) * d + Eigen::Vector3d(n * std::cos(theta_e), n * std::sin(theta_e), 0.0);
      EXPECT_LT((model.unproject(u, v, r).cast<double>() - expected).norm(), 2e-6);
    }
  // Column 0 looks along +x, and the azimuth decreases as the column grows.
  const LidarModel flat(LidarIntrinsics::synthetic(1, 360, 0.01, -0.01));
  EXPECT_NEAR(flat.unproject(0, 0, 1.0f).y(), 0.0f, 1e-6f);
  EXPECT_LT(flat.unproject(1, 0, 1.0f).y(), 0.0f);
}

TEST(LidarModel, InverseAltitudeTableHasAtLeastTwoEntriesPerBeam) {
  const LidarModel model(ousterLikeIntrinsics(128, 1024));
  EXPECT_GE(model.inverseAltitudeTableSize(), 2u * 128u);
}

// Pi(Pi^-1(u, v, r)) == (u, v) at every pixel, near and far, across the seam.
void expectExactRoundTrip(const LidarModel& model, const std::vector<float>& ranges) {
  std::size_t wrong = 0, total = 0;
  for (const float r : ranges)
    for (int v = 0; v < model.rows(); ++v)
      for (int u = 0; u < model.columns(); ++u) {
        const auto pixel = model.project(model.unproject(u, v, r));
        ++total;
        if (!pixel || pixel->row != v || pixel->column != u) {
          ++wrong;
          continue;
        }
        EXPECT_NEAR(pixel->range, r, 2e-6f * r + 1e-5f);
      }
  EXPECT_EQ(wrong, 0u) << "of " << total << " pixels";
}

TEST(LidarModel, ProjectionInvertsUnprojectionOnOusterLikeTables) {
  expectExactRoundTrip(LidarModel(ousterLikeIntrinsics(128, 1024)), {0.3f, 1.0f, 12.5f, 120.0f});
  expectExactRoundTrip(LidarModel(ousterLikeIntrinsics(32, 2048)), {0.5f, 40.0f});
  expectExactRoundTrip(LidarModel(ousterLikeIntrinsics(16, 512)), {0.5f, 40.0f});
}

TEST(LidarModel, ProjectionInvertsUnprojectionOnSyntheticTables) {
  expectExactRoundTrip(LidarModel(LidarIntrinsics::synthetic(64, 2048, 2.0 * kDegree, -24.8 * kDegree)),
                       {1.0f, 30.0f, 80.0f});
}

TEST(LidarModel, PointsOutsideTheFieldOfViewDoNotProject) {
  const LidarModel model(LidarIntrinsics::synthetic(64, 2048, 2.0 * kDegree, -24.8 * kDegree));
  EXPECT_FALSE(model.project(Eigen::Vector3f(10, 0, 10)));   // 45 deg up
  EXPECT_FALSE(model.project(Eigen::Vector3f(1, 0, -10)));   // almost straight down
  EXPECT_FALSE(model.project(Eigen::Vector3f(0, 0, 0)));
  EXPECT_FALSE(model.project(Eigen::Vector3f(std::nanf(""), 0, 0)));
  // Half a beam spacing above the top beam still belongs to row 0.
  const double spacing = 26.8 / 63 * kDegree;
  const double above = 2.0 * kDegree + 0.4 * spacing;
  const auto top = model.project(Eigen::Vector3f(std::cos(above), 0, std::sin(above)));
  ASSERT_TRUE(top);
  EXPECT_EQ(top->row, 0);
}

TEST(LidarModel, ProjectionPicksTheNearestBeamForArbitraryPoints) {
  const LidarModel model(ousterLikeIntrinsics(64, 1024));
  std::mt19937 random(7);
  std::uniform_real_distribution<float> coordinate(-30.0f, 30.0f);
  int checked = 0;
  for (int i = 0; i < 20000; ++i) {
    const Eigen::Vector3f point(coordinate(random), coordinate(random), 0.3f * coordinate(random));
    const auto pixel = model.project(point);
    if (!pixel) continue;
    ++checked;
    // The ray to the point from the chosen pixel's beam origin has the
    // altitude closest to one of the beams: no other row is nearer.
    const Eigen::Vector3f origin = model.offset(pixel->column, pixel->row) +
                                   model.direction(pixel->column, pixel->row) *
                                       float(model.intrinsics().beam_origin_radius_m);
    const Eigen::Vector3f ray = (point - origin).normalized();
    const float altitude = std::asin(ray.z());
    float best = 1e9f;
    int best_row = -1;
    for (int v = 0; v < model.rows(); ++v) {
      const float distance = std::abs(float(model.intrinsics().altitude_rad[v]) - altitude);
      if (distance < best) best = distance, best_row = v;
    }
    EXPECT_EQ(pixel->row, best_row);
    // Unprojecting the found pixel at the found range lands within half a
    // pixel's footprint of the point: half the widest beam gap (0.75 deg
    // here) and half a column.
    const Eigen::Vector3f back = model.unproject(pixel->column, pixel->row, pixel->range);
    EXPECT_LT((back - point).norm(), pixel->range * std::hypot(0.75 * kDegree, M_PI / 1024));
  }
  EXPECT_GT(checked, 5000);
}

TEST(LidarModel, ProjectManyAgreesWithProjectPointByPoint) {
  for (const LidarModel& model :
       {LidarModel(ousterLikeIntrinsics(64, 1024)),
        LidarModel(LidarIntrinsics::synthetic(64, 2048, 2.0 * kDegree, -24.8 * kDegree))}) {
    std::mt19937 random(11);
    std::uniform_real_distribution<float> coordinate(-40.0f, 40.0f);
    std::vector<Eigen::Vector3f> points;
    for (int i = 0; i < 5000; ++i)
      points.emplace_back(coordinate(random), coordinate(random), 0.3f * coordinate(random));
    points.emplace_back(0.0f, 0.0f, 5.0f);                 // on the axis
    points.emplace_back(std::nanf(""), 1.0f, 1.0f);        // not a number
    points.emplace_back(0.01f, 0.0f, 0.0f);                // inside the beam-origin circle
    for (int v = 0; v < model.rows(); v += 7)              // exactly on beams, across the seam
      for (int u : {0, 1, model.columns() - 1}) points.push_back(model.unproject(u, v, 3.0f));
    std::vector<ProjectedPixel> pixels(points.size());
    std::vector<uint8_t> hits(points.size());
    model.projectMany(points.data(), points.size(), pixels.data(), hits.data());
    // The same points as coordinate arrays give the same pixels to the bit.
    std::vector<float> x, y, z;
    for (const Eigen::Vector3f& point : points) {
      x.push_back(point.x());
      y.push_back(point.y());
      z.push_back(point.z());
    }
    std::vector<ProjectedPixel> array_pixels(points.size());
    std::vector<uint8_t> array_hits(points.size());
    model.projectMany(x.data(), y.data(), z.data(), points.size(), array_pixels.data(), array_hits.data());
    std::size_t hit_count = 0;
    for (std::size_t i = 0; i < points.size(); ++i) {
      const auto expected = model.project(points[i]);
      ASSERT_EQ(bool(hits[i]), expected.has_value()) << "point " << i;
      ASSERT_EQ(array_hits[i], hits[i]) << "point " << i;
      if (!expected) continue;
      ++hit_count;
      EXPECT_EQ(pixels[i].row, expected->row) << "point " << i;
      EXPECT_EQ(pixels[i].column, expected->column) << "point " << i;
      EXPECT_FLOAT_EQ(pixels[i].range, expected->range) << "point " << i;
      EXPECT_EQ(array_pixels[i].row, pixels[i].row) << "point " << i;
      EXPECT_EQ(array_pixels[i].column, pixels[i].column) << "point " << i;
      EXPECT_EQ(array_pixels[i].range, pixels[i].range) << "point " << i;
    }
    EXPECT_GT(hit_count, 1000u);
  }
}

TEST(RangeImage, StridedViewReadsTheFullImageWithoutCopying) {
  auto model = std::make_shared<const LidarModel>(ousterLikeIntrinsics(16, 64));
  RangeImage image(model);
  for (std::size_t i = 0; i < image.range.size(); ++i) image.range[i] = float(i);
  const auto view = image.rangeView(4);
  EXPECT_EQ(view.rows(), 4);
  EXPECT_EQ(view.columns(), 16);
  EXPECT_EQ(view.data(), image.range.data());
  EXPECT_EQ(view(2, 3), image.at(8, 12));
  image.range[image.index(8, 12)] = -1.0f;
  EXPECT_EQ(view(2, 3), -1.0f);
  EXPECT_EQ(view.fullRow(2), 8);
  EXPECT_EQ(view.fullColumn(3), 12);
}

TEST(RangeImage, DestaggerShiftsRowsAndStaggerUndoesIt) {
  auto model = std::make_shared<const LidarModel>(ousterLikeIntrinsics(8, 32));
  RangeImage image(model);
  image.intensity.assign(image.range.size(), 0.0f);
  for (std::size_t i = 0; i < image.range.size(); ++i) image.range[i] = image.intensity[i] = float(i + 1);
  const RangeImage display = image.destaggered();
  for (int v = 0; v < 8; ++v) {
    const int shift = model->intrinsics().pixel_shift_by_row[v];
    for (int u = 0; u < 32; ++u) {
      EXPECT_EQ(display.at(v, (u + shift) % 32), image.at(v, u));
      EXPECT_EQ(display.intensity[display.index(v, (u + shift) % 32)], image.intensity[image.index(v, u)]);
    }
  }
  EXPECT_EQ(display.column_order, ColumnOrder::kDestaggered);
  EXPECT_EQ(display.staggered().range, image.range);
  EXPECT_THROW(display.unprojectAll(), std::logic_error);
}

TEST(RangeImage, FloatMetresHoldEveryMillimetreReadingExactly) {
  for (uint32_t millimetres = 0; millimetres < (1u << 20); ++millimetres) {
    const float metres = static_cast<float>(millimetres * 0.001);
    ASSERT_EQ(static_cast<uint32_t>(std::lround(metres * 1000.0)), millimetres);
  }
}

TEST(RangeImage, NewImagesAreInvalidEverywhere) {
  auto model = std::make_shared<const LidarModel>(ousterLikeIntrinsics(8, 32));
  const RangeImage image(model);
  EXPECT_EQ(image.validCount(), 0u);
  EXPECT_EQ(image.column_timestamp_ns.size(), 32u);
  EXPECT_THROW(RangeImage(nullptr), std::invalid_argument);
}

}  // namespace
}  // namespace range_image_mapping
