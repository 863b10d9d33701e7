#include "range_image_mapping/evaluation/report.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

namespace range_image_mapping::evaluation {
namespace {

// A straight drive along x, swaying by 10 cm: drawn at equal scales it would
// be a strip a few pixels high.
std::vector<Eigen::Vector2d> straightDrive() {
  std::vector<Eigen::Vector2d> points;
  for (int i = 0; i <= 200; ++i) points.emplace_back(20.0 + 0.5 * i, 3.0 + 0.1 * std::sin(0.3 * i));
  return points;
}

TEST(TopViewRanges, AStraightDriveIsWidenedAboutItsMiddle) {
  const std::vector<Eigen::Vector2d> points = straightDrive();
  const TopViewRanges ranges = topViewRanges(points);
  ASSERT_FALSE(ranges.empty);
  EXPECT_DOUBLE_EQ(ranges.minimum.x(), 20.0);
  EXPECT_DOUBLE_EQ(ranges.maximum.x(), 120.0);
  EXPECT_NEAR(ranges.maximum.y() - ranges.minimum.y(), 100.0 / 3.0, 1e-9);
  double low = points.front().y(), high = low;
  for (const Eigen::Vector2d& point : points) {
    low = std::min(low, point.y());
    high = std::max(high, point.y());
  }
  EXPECT_NEAR(0.5 * (ranges.minimum.y() + ranges.maximum.y()), 0.5 * (low + high), 1e-9);
  // Along y instead of x: the same, the other way round.
  std::vector<Eigen::Vector2d> turned;
  for (const Eigen::Vector2d& point : points) turned.emplace_back(point.y(), point.x());
  const TopViewRanges turned_ranges = topViewRanges(turned, 0.5);
  EXPECT_DOUBLE_EQ(turned_ranges.minimum.y(), 20.0);
  EXPECT_NEAR(turned_ranges.maximum.x() - turned_ranges.minimum.x(), 50.0, 1e-9);
}

TEST(TopViewRanges, AWideEnoughPathKeepsItsExtent) {
  std::vector<Eigen::Vector2d> points;
  for (int i = 0; i < 100; ++i) points.emplace_back(30.0 * std::cos(0.05 * i), -5.0 + 12.0 * std::sin(0.05 * i));
  const TopViewRanges ranges = topViewRanges(points);
  ASSERT_FALSE(ranges.empty);
  Eigen::Vector2d low = points.front(), high = points.front();
  for (const Eigen::Vector2d& point : points) {
    low = low.cwiseMin(point);
    high = high.cwiseMax(point);
  }
  EXPECT_EQ(ranges.minimum, low);
  EXPECT_EQ(ranges.maximum, high);
}

TEST(TopViewRanges, NonFinitePointsAreLeftOutAndAStandingSensorGetsAMetre) {
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  const TopViewRanges standing = topViewRanges({{2.0, -1.0}, {kNaN, 4.0}, {2.0, -1.0}, {1e300 * 1e300, 0.0}});
  ASSERT_FALSE(standing.empty);
  EXPECT_DOUBLE_EQ(standing.minimum.x(), 1.5);
  EXPECT_DOUBLE_EQ(standing.maximum.x(), 2.5);
  EXPECT_DOUBLE_EQ(standing.minimum.y(), -1.5);
  EXPECT_DOUBLE_EQ(standing.maximum.y(), -0.5);
  EXPECT_TRUE(topViewRanges({}).empty);
  EXPECT_TRUE(topViewRanges({{kNaN, kNaN}}).empty);
}

}  // namespace
}  // namespace range_image_mapping::evaluation
