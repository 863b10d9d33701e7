// Normals in the image domain against analytic scenes: a box room seen from
// inside (every wall, floor and ceiling normal is known exactly) and a panel
// in front of a far wall (a depth edge).
#include "range_image_mapping/normal_map.h"
#include "range_image_mapping/simulation/lidar_simulator.h"
#include "range_image_mapping/simulation/mesh_primitives.h"
#include "range_image_mapping/simulation/sensor_presets.h"

#include <gtest/gtest.h>

#include <cmath>

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

// levelPixelIndex shifts for power-of-two strides and divides otherwise;
// both must give the nearest level pixel of the plain formula, for every
// full-resolution pixel, including the last rows (clamped) and the columns
// that round up to column W (wrapped to 0).
TEST(LevelPixelIndex, NearestLevelPixelForEveryStride) {
  constexpr int kRows = 128, kColumns = 1024;
  for (int stride = 1; stride <= 16; ++stride) {
    VertexNormalMap level;
    level.stride = stride;
    level.rows = (kRows + stride - 1) / stride;
    level.columns = (kColumns + stride - 1) / stride;
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
      }
    }
  }
}

}  // namespace
}  // namespace range_image_mapping
