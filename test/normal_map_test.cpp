// Normals in the image domain against analytic scenes: a box room seen from
// inside (every wall, floor and ceiling normal is known exactly) and a panel
// in front of a far wall (a depth edge).
#include "range_image_mapping/normal_map.h"
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/point_cloud_projection.h"
#include "test_data.h"
#include "range_image_mapping/simulation/lidar_simulator.h"
#include "range_image_mapping/simulation/mesh_primitives.h"
#include "range_image_mapping/simulation/sensor_presets.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <cstdio>
#include <vector>

namespace range_image_mapping {
namespace {

constexpr double kDegree = M_PI / 180.0;

LidarModelConstPtr ousterLikeModel() {
  return std::make_shared<const LidarModel>(
      parseOusterMetadata(simulation::ousterLikeMetadataJson("OS-0-128", UdpProfile::kRng19Rfl8Sig16Nir16))
          .intrinsics);
}

// One scan from the identity pose with the exact (unquantised) ranges, so
// that the geometry, not millimetre steps, is under test.
RangeImage exactScan(const TriangleMesh& mesh, const LidarModelConstPtr& model) {
  const simulation::RayCaster caster(mesh);
  simulation::SensorEffects effects;
  effects.motion_distortion = false;
  effects.min_range_m = 0.1;
  const simulation::LidarSimulator simulator(model, caster, effects, 1);
  const simulation::InterpolatedTrajectory still({0.0, 10.0}, {Eigen::Isometry3d::Identity(), Eigen::Isometry3d::Identity()});
  simulation::SimulatedScan scan = simulator.simulate(still, 0.0, 0);
  scan.image.range = scan.true_range;
  return scan.image;
}

const Eigen::Vector3f kRoomMinimum(-4.0f, -3.0f, -1.5f), kRoomMaximum(6.0f, 5.0f, 2.5f);

// The inward normal of the room face a point lies on; nothing when the point
// is within `margin` of a second face (windows there straddle a corner).
bool roomNormal(const Eigen::Vector3f& point, float margin, Eigen::Vector3f& normal) {
  int faces_near = 0;
  float nearest = 1e9f;
  for (int axis = 0; axis < 3; ++axis) {
    for (int side = 0; side < 2; ++side) {
      const float plane = side ? kRoomMaximum(axis) : kRoomMinimum(axis);
      const float distance = std::abs(point(axis) - plane);
      faces_near += distance < margin;
      if (distance < nearest) {
        nearest = distance;
        normal = Eigen::Vector3f::Zero();
        normal(axis) = side ? -1.0f : 1.0f;
      }
    }
  }
  return faces_near == 1;
}

class RoomNormals : public ::testing::TestWithParam<std::tuple<NormalMethod, int>> {};

TEST_P(RoomNormals, WithinOneDegreeOfTheWallsAndFacingTheSensor) {
  const auto [method, stride] = GetParam();
  const LidarModelConstPtr model = ousterLikeModel();
  const RangeImage image = exactScan(simulation::makeBox(kRoomMinimum, kRoomMaximum, true), model);
  ASSERT_GT(image.validCount(), image.range.size() / 2);

  NormalMapOptions options;
  options.method = method;
  VertexNormalMap map;
  computeVertexNormalMap(image, stride, options, map);
  ASSERT_EQ(map.rows, (image.rows() + stride - 1) / stride);
  ASSERT_EQ(map.columns, (image.columns() + stride - 1) / stride);
  ASSERT_EQ(map.stride, stride);

  std::size_t checked = 0, with_normal = 0;
  double worst_degrees = 0.0;
  for (int row = 0; row < map.rows; ++row) {
    for (int column = 0; column < map.columns; ++column) {
      const Eigen::Vector3f& point = map.point(row, column);
      // The point is Pi^-1 of the level's full-resolution pixel.
      const float range = image.at(row * stride, column * stride);
      ASSERT_EQ(std::isfinite(point.x()), isValidRange(range));
      if (!isValidRange(range)) continue;
      EXPECT_LT((point - model->unproject(column * stride, row * stride, range)).norm(), 1e-5f);
      Eigen::Vector3f expected;
      // Windows reach a few pixel footprints; on the floor seen at a grazing
      // angle a footprint grows with the range.
      if (!roomNormal(point, stride * std::max(0.35f, 0.1f * range), expected)) continue;
      ++checked;
      const Eigen::Vector3f& normal = map.normal(row, column);
      if (!std::isfinite(normal.x())) continue;
      ++with_normal;
      EXPECT_NEAR(normal.norm(), 1.0f, 1e-4f);
      EXPECT_LT(normal.dot(point), 0.0f) << "normal faces away from the sensor at " << row << ", " << column;
      const double angle = std::acos(std::min(1.0, double(normal.dot(expected)))) / kDegree;
      worst_degrees = std::max(worst_degrees, angle);
    }
  }
  ASSERT_GT(checked, 1000u);
  // Away from corners every pixel of a plane gets a normal.
  EXPECT_GT(with_normal, checked * 99 / 100) << "only " << with_normal << " of " << checked;
  EXPECT_LT(worst_degrees, 1.0);
  std::printf("method %d stride %d: %zu plane pixels, worst normal error %.4f deg\n", int(method), stride,
              checked, worst_degrees);
}

INSTANTIATE_TEST_SUITE_P(BothMethods, RoomNormals,
                         ::testing::Combine(::testing::Values(NormalMethod::kCrossProduct, NormalMethod::kCovariance),
                                            ::testing::Values(1, 2, 4)));

class DepthEdge : public ::testing::TestWithParam<NormalMethod> {};

TEST_P(DepthEdge, PixelsBetweenNearAndFarSurfacesHaveNoNormal) {
  // A 2 m panel 3 m ahead in front of a wall 12 m ahead.
  TriangleMesh scene = simulation::makeQuad({3.0f, 1.0f, -1.0f}, {0.0f, -2.0f, 0.0f}, {0.0f, 0.0f, 2.0f});
  scene.append(simulation::makeQuad({12.0f, 10.0f, -8.0f}, {0.0f, -20.0f, 0.0f}, {0.0f, 0.0f, 16.0f}));
  const RangeImage image = exactScan(scene, ousterLikeModel());
  NormalMapOptions options;
  options.method = GetParam();
  VertexNormalMap map;
  computeVertexNormalMap(image, 1, options, map);

  std::size_t edges = 0, near_with_normal = 0, far_with_normal = 0;
  for (int row = 0; row < map.rows; ++row) {
    for (int column = 0; column < map.columns; ++column) {
      const int next = (column + 1) % map.columns;
      const float a = image.at(row, column), b = image.at(row, next);
      if (!isValidRange(a) || !isValidRange(b)) continue;
      const Eigen::Vector3f& normal = map.normal(row, column);
      if (std::isfinite(normal.x())) {
        (a < 6.0f ? near_with_normal : far_with_normal) += 1;
        // Both surfaces face the sensor along -x.
        EXPECT_GT(-normal.x(), std::cos(1.0 * kDegree)) << row << ", " << column;
      }
      if (std::abs(a - b) < 5.0f) continue;
      ++edges;
      EXPECT_FALSE(std::isfinite(map.normal(row, column).x())) << "edge pixel " << row << ", " << column;
      EXPECT_FALSE(std::isfinite(map.normal(row, next).x())) << "edge pixel " << row << ", " << next;
      // The points themselves stay.
      EXPECT_TRUE(std::isfinite(map.point(row, column).x()));
      EXPECT_TRUE(std::isfinite(map.point(row, next).x()));
    }
  }
  EXPECT_GT(edges, 20u);
  EXPECT_GT(near_with_normal, 500u);
  EXPECT_GT(far_with_normal, 500u);
}

INSTANTIATE_TEST_SUITE_P(BothMethods, DepthEdge,
                         ::testing::Values(NormalMethod::kCrossProduct, NormalMethod::kCovariance));

TEST(NormalMap, RejectsBadInput) {
  VertexNormalMap map;
  RangeImage no_model;
  EXPECT_THROW(computeVertexNormalMap(no_model, 1, {}, map), std::invalid_argument);
  RangeImage image(ousterLikeModel());
  EXPECT_THROW(computeVertexNormalMap(image, 0, {}, map), std::invalid_argument);
  NormalMapOptions bad;
  bad.window_radius = 0;
  EXPECT_THROW(computeVertexNormalMap(image, 1, bad, map), std::invalid_argument);
  bad = {};
  bad.max_chord_offset_m = -0.01f;
  EXPECT_THROW(computeVertexNormalMap(image, 1, bad, map), std::invalid_argument);
  bad.max_chord_offset_m = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(computeVertexNormalMap(image, 1, bad, map), std::invalid_argument);
  image.column_order = ColumnOrder::kDestaggered;
  EXPECT_THROW(computeVertexNormalMap(image, 1, {}, map), std::invalid_argument);
  image.column_order = ColumnOrder::kStaggered;
  image.range.pop_back();
  EXPECT_THROW(computeVertexNormalMap(image, 1, {}, map), std::invalid_argument);
}

TEST(NormalMap, AllInvalidImageGivesNoPointsAndNoNormals) {
  const RangeImage image(ousterLikeModel());
  VertexNormalMap map;
  computeVertexNormalMap(image, 2, {}, map);
  for (std::size_t i = 0; i < map.points.size(); ++i) {
    ASSERT_FALSE(std::isfinite(map.points[i].x()));
    ASSERT_FALSE(std::isfinite(map.normals[i].x()));
  }
}

// Share of the pixels with a point that also have a normal, and the median
// angle between up and the normals of the ground within 15 m (the road
// around the KITTI car, about 1.7 m below the Velodyne).
struct NormalCoverage {
  double share = 0.0;
  double ground_median_deg = 180.0;
};
NormalCoverage normalCoverage(const VertexNormalMap& map) {
  std::size_t points = 0, normals = 0;
  std::vector<double> ground_deg;
  for (std::size_t i = 0; i < map.points.size(); ++i) {
    if (!std::isfinite(map.points[i].x())) continue;
    ++points;
    if (!std::isfinite(map.normals[i].x())) continue;
    ++normals;
    const Eigen::Vector3f& p = map.points[i];
    if (p.z() < -1.4f && p.z() > -2.0f && p.head<2>().norm() < 15.0f)
      ground_deg.push_back(std::acos(std::min(1.0f, map.normals[i].z())) / kDegree);
  }
  NormalCoverage coverage;
  if (points) coverage.share = double(normals) / double(points);
  if (!ground_deg.empty()) {
    std::nth_element(ground_deg.begin(), ground_deg.begin() + ground_deg.size() / 2, ground_deg.end());
    coverage.ground_median_deg = ground_deg[ground_deg.size() / 2];
  }
  return coverage;
}

// A model with more columns than the sensor fills per scan (as an estimated
// model that keeps the points of lasers firing between steps): a real KITTI
// scan at 4096 columns leaves most pixels of a row with empty neighbours,
// yet its pixels get normals about as often as at 2048, and right ones.
TEST(NormalMap, RealScanWithEmptyNeighbourColumnsKeepsItsNormals) {
  RIM_REQUIRE_DATA(scan_path, "kitti00/velodyne/000094.bin");
  const PointCloudInput cloud = io::readKittiVelodyne(scan_path);
  NormalCoverage coverage[2];
  int columns[2] = {2048, 4096};
  for (int k = 0; k < 2; ++k) {
    const auto model = std::make_shared<const LidarModel>(io::kittiHdl64Intrinsics(columns[k]));
    VertexNormalMap map;
    computeVertexNormalMap(projectPointCloud(cloud, model), 1, {}, map);
    coverage[k] = normalCoverage(map);
    std::printf("%d columns: normals for %.3f of the points, ground normals %.2f deg from up (median)\n",
                columns[k], coverage[k].share, coverage[k].ground_median_deg);
  }
  // The synthetic model's evenly spread rows are not KITTI's beams, so the
  // road's normals tilt by a few degrees; no worse with the wider reach.
  EXPECT_LT(coverage[0].ground_median_deg, 8.0);
  EXPECT_LT(coverage[1].ground_median_deg, coverage[0].ground_median_deg + 2.0);
  EXPECT_GT(coverage[0].share, 0.8);
  EXPECT_GT(coverage[1].share, 0.9 * coverage[0].share)
      << "normals for " << coverage[1].share << " of the points at 4096 columns, " << coverage[0].share << " at 2048";
}

// Where a pixel's four neighbours all have a return within the allowed jump,
// its normal is the central differences' cross product, normalised and
// facing the sensor, with Eigen's arithmetic to the bit (the loop that does
// most pixels spells it out to vectorise). A real KITTI scan, whose rows
// share one azimuth (the rows above and below are in the same column), at
// the three strides the odometry uses.
TEST(NormalMap, CentralDifferencesAreEigensArithmeticToTheBit) {
  RIM_REQUIRE_DATA(scan_path, "kitti00/velodyne/000094.bin");
  const auto model = std::make_shared<const LidarModel>(io::kittiHdl64Intrinsics(2048));
  const auto azimuth = [&](int row) { return std::atan2(model->direction(0, row).y(), model->direction(0, row).x()); };
  for (int row = 1; row < model->rows(); ++row)
    ASSERT_NEAR(azimuth(row), azimuth(0), 1e-6) << "the test reads the rows above and below in the same column";
  const RangeImage image = projectPointCloud(io::readKittiVelodyne(scan_path), model);
  const NormalMapOptions options;
  for (const int stride : {1, 2, 4}) {
    VertexNormalMap map;
    computeVertexNormalMap(image, stride, options, map);
    const ImageView<const float> ranges = image.rangeView(stride);
    std::size_t checked = 0, mismatched = 0;
    for (int row = 1; row + 1 < map.rows; ++row) {
      for (int column = 1; column + 1 < map.columns; ++column) {
        const float centre_range = ranges(row, column);
        if (!isValidRange(centre_range)) continue;
        const float max_jump = options.max_range_jump_ratio * float(stride) * centre_range;
        const auto usable = [&](int r, int c) {
          return isValidRange(ranges(r, c)) && std::abs(ranges(r, c) - centre_range) <= max_jump;
        };
        if (!usable(row, column + 1) || !usable(row, column - 1) || !usable(row - 1, column) ||
            !usable(row + 1, column))
          continue;
        const auto point = [&](int r, int c) { return map.points[std::size_t(r) * map.columns + c]; };
        const Eigen::Vector3f along_row = point(row, column + 1) - point(row, column - 1);
        const Eigen::Vector3f along_column = point(row + 1, column) - point(row - 1, column);
        const Eigen::Vector3f normal = along_row.cross(along_column);
        const float norm = normal.norm();
        Eigen::Vector3f expected = Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN());
        if (norm > 1e-3f * along_row.norm() * along_column.norm()) {
          expected = normal / norm;
          if (expected.dot(point(row, column)) > 0.0f) expected = -expected;
        }
        const Eigen::Vector3f& got = map.normals[std::size_t(row) * map.columns + column];
        const bool same = std::isfinite(expected.x()) ? got == expected : !std::isfinite(got.x());
        if (!same && ++mismatched <= 3)
          ADD_FAILURE() << "stride " << stride << ", pixel (" << row << ", " << column << "): "
                        << got.transpose() << " instead of " << expected.transpose();
        ++checked;
      }
    }
    std::printf("stride %d: %zu pixels with four usable neighbours, %zu differ\n", stride, checked, mismatched);
    EXPECT_EQ(mismatched, 0u) << "stride " << stride;
    EXPECT_GT(checked, std::size_t(map.rows) * map.columns / 4) << "stride " << stride;
  }
}

// The same for in-line normals (max_chord_offset_m, a sensor with sparse
// rows, full resolution only): where the row neighbours have a return within
// the allowed jump and the rows above and below have one, the normal is the
// central differences' if the pixel lies within the offset of both chords,
// else none, with Eigen's arithmetic to the bit (the loop that does most
// pixels spells it out). A real KITTI scan with a 2 cm offset, which keeps
// some pixels and refuses others.
TEST(NormalMap, InLineNormalsAreEigensArithmeticToTheBit) {
  RIM_REQUIRE_DATA(scan_path, "kitti00/velodyne/000094.bin");
  const auto model = std::make_shared<const LidarModel>(io::kittiHdl64Intrinsics(2048));
  const RangeImage image = projectPointCloud(io::readKittiVelodyne(scan_path), model);
  NormalMapOptions options;
  options.max_chord_offset_m = 0.02f;
  VertexNormalMap map;
  computeVertexNormalMap(image, 1, options, map);
  const ImageView<const float> ranges = image.rangeView(1);
  std::size_t kept = 0, refused = 0, mismatched = 0;
  for (int row = 1; row + 1 < map.rows; ++row) {
    for (int column = 1; column + 1 < map.columns; ++column) {
      const float centre_range = ranges(row, column);
      if (!isValidRange(centre_range)) continue;
      const float max_jump = options.max_range_jump_ratio * centre_range;
      const auto usable = [&](int r, int c) {
        return isValidRange(ranges(r, c)) && std::abs(ranges(r, c) - centre_range) <= max_jump;
      };
      if (!usable(row, column + 1) || !usable(row, column - 1) || !isValidRange(ranges(row - 1, column)) ||
          !isValidRange(ranges(row + 1, column)))
        continue;
      const auto point = [&](int r, int c) { return map.points[std::size_t(r) * map.columns + c]; };
      const Eigen::Vector3f centre = point(row, column);
      const auto onChord = [&](const Eigen::Vector3f& after, const Eigen::Vector3f& before) {
        const Eigen::Vector3f chord = after - before;
        return (centre - before).cross(chord).norm() <= options.max_chord_offset_m * chord.norm();
      };
      const Eigen::Vector3f along_row = point(row, column + 1) - point(row, column - 1);
      const Eigen::Vector3f along_column = point(row + 1, column) - point(row - 1, column);
      const Eigen::Vector3f normal = along_row.cross(along_column);
      const float norm = normal.norm();
      Eigen::Vector3f expected = Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN());
      if (onChord(point(row + 1, column), point(row - 1, column)) &&
          onChord(point(row, column + 1), point(row, column - 1)) &&
          norm > 1e-3f * along_row.norm() * along_column.norm()) {
        expected = normal / norm;
        if (expected.dot(centre) > 0.0f) expected = -expected;
      }
      const Eigen::Vector3f& got = map.normals[std::size_t(row) * map.columns + column];
      const bool same = std::isfinite(expected.x()) ? got == expected : !std::isfinite(got.x());
      if (!same && ++mismatched <= 3)
        ADD_FAILURE() << "pixel (" << row << ", " << column << "): " << got.transpose() << " instead of "
                      << expected.transpose();
      ++(std::isfinite(expected.x()) ? kept : refused);
    }
  }
  std::printf("in-line: %zu pixels with a normal, %zu refused, %zu differ\n", kept, refused, mismatched);
  EXPECT_EQ(mismatched, 0u);
  EXPECT_GT(kept, std::size_t(map.rows) * map.columns / 8);
  EXPECT_GT(refused, 100u);
}

// levelPixelIndex shifts for power-of-two strides and divides otherwise;
// both must give the nearest level pixel of the plain formula, for every
// full-resolution pixel, including the last rows (clamped) and the columns
// that round up to column W (wrapped to 0). LevelPixelTables, its tabulated
// form, must give the same.
TEST(LevelPixelIndex, NearestLevelPixelForEveryStride) {
  constexpr int kRows = 128, kColumns = 1024;
  for (int stride = 1; stride <= 16; ++stride) {
    VertexNormalMap level;
    level.stride = stride;
    level.rows = (kRows + stride - 1) / stride;
    level.columns = (kColumns + stride - 1) / stride;
    LevelPixelTables tables;
    tables.build(level, kRows, kColumns);
    for (int row = 0; row < kRows; ++row) {
      for (int column = 0; column < kColumns; ++column) {
        ProjectedPixel pixel;
        pixel.row = row;
        pixel.column = column;
        const int expected_row = std::min(int(std::floor((row + stride / 2) / double(stride))), level.rows - 1);
        int expected_column = int(std::floor((column + stride / 2) / double(stride)));
        if (expected_column >= level.columns) expected_column = 0;
        ASSERT_EQ(levelPixelIndex(level, pixel), std::size_t(expected_row) * level.columns + expected_column)
            << "stride " << stride << " pixel (" << row << ", " << column << ")";
        ASSERT_EQ(tables.index(pixel), std::size_t(expected_row) * level.columns + expected_column)
            << "tables, stride " << stride << " pixel (" << row << ", " << column << ")";
      }
    }
  }
}

}  // namespace
}  // namespace range_image_mapping
