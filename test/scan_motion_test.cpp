// SE(3) exponential and logarithm (scan_motion.h) as properties over random
// twists at every rotation angle, from 1e-12 rad (a stationary sensor whose
// registration moved by rounding) to just below pi, against Eigen's general
// matrix exponential and logarithm of the 4 x 4 twist matrix as the reference.
#include "range_image_mapping/scan_motion.h"

#include <gtest/gtest.h>
#include <unsupported/Eigen/MatrixFunctions>

#include <cmath>
#include <random>
#include <vector>

namespace range_image_mapping {
namespace {

Eigen::Matrix4d hat(const Twist& twist) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Zero();
  const Eigen::Vector3d w = twist.head<3>();
  m.topLeftCorner<3, 3>() << 0, -w.z(), w.y(), w.z(), 0, -w.x(), -w.y(), w.x(), 0;
  m.topRightCorner<3, 1>() = twist.tail<3>();
  return m;
}

// A twist with rotation angle `angle` about a random axis and a random
// translation part of up to 30 m.
Twist randomTwist(std::mt19937& random, double angle) {
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> uniform(-30.0, 30.0);
  Eigen::Vector3d axis(normal(random), normal(random), normal(random));
  axis.normalize();
  Twist twist;
  twist << angle * axis, uniform(random), uniform(random), uniform(random);
  return twist;
}

// Angles across the whole range, the small ones where 1 - cos(angle) is 0 in
// double precision and where the closed forms lose digits.
std::vector<double> testAngles() {
  return {0.0,  1e-12, 1e-10, 1e-9, 3e-9,  1e-8, 2e-8, 5e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 9.99e-3,
          1e-2, 1.01e-2, 0.1, 0.5,  1.0,   2.0,  3.0,  M_PI - 1e-3, M_PI - 1e-6, M_PI - 1e-9};
}

TEST(ScanMotion, ExponentialMatchesTheMatrixExponentialAtEveryAngle) {
  std::mt19937 random(7);
  for (const double angle : testAngles())
    for (int trial = 0; trial < 20; ++trial) {
      const Twist twist = randomTwist(random, angle);
      const Eigen::Matrix4d reference = hat(twist).exp();
      const Eigen::Isometry3d pose = twistExponential(twist);
      ASSERT_TRUE(pose.matrix().allFinite()) << "angle " << angle;
      EXPECT_LT((pose.matrix() - reference).cwiseAbs().maxCoeff(), 1e-12 * (1.0 + twist.norm()))
          << "angle " << angle << "\n" << pose.matrix() << "\nreference\n" << reference;
      // A rotation, to double precision.
      EXPECT_LT((pose.linear().transpose() * pose.linear() - Eigen::Matrix3d::Identity()).norm(), 1e-14);
      EXPECT_NEAR(pose.linear().determinant(), 1.0, 1e-14);
    }
}

TEST(ScanMotion, LogarithmInvertsTheExponentialAtEveryAngle) {
  std::mt19937 random(11);
  for (const double angle : testAngles())
    for (int trial = 0; trial < 20; ++trial) {
      const Twist twist = randomTwist(random, angle);
      const Twist recovered = twistLogarithm(twistExponential(twist));
      ASSERT_TRUE(recovered.allFinite()) << "angle " << angle;
      // The rotation part: relative to its size even at 1e-12 rad, so that a
      // velocity from a tiny step is right, not only small.
      EXPECT_LT((recovered.head<3>() - twist.head<3>()).norm(), 1e-15 + 1e-9 * angle) << "angle " << angle;
      // Near pi the translation's sensitivity to the rotation grows like
      // 1 / (pi - angle): the tolerance follows it.
      const double conditioning = 1.0 / std::max(M_PI - angle, 1e-3);
      EXPECT_LT((recovered.tail<3>() - twist.tail<3>()).norm(), 1e-10 * conditioning * twist.tail<3>().norm())
          << "angle " << angle << ": " << recovered.transpose() << " vs " << twist.transpose();
    }
}

TEST(ScanMotion, LogarithmMatchesTheMatrixLogarithm) {
  std::mt19937 random(13);
  for (const double angle : testAngles()) {
    if (angle > 3.0) continue;  // the general matrix logarithm itself loses digits near pi
    const Twist twist = randomTwist(random, angle);
    const Eigen::Matrix4d pose = twistExponential(twist).matrix();
    const Eigen::Matrix4d reference = pose.log();
    const Eigen::Matrix4d ours = hat(twistLogarithm(Eigen::Isometry3d(pose)));
    EXPECT_LT((ours - reference).cwiseAbs().maxCoeff(), 1e-9 * (1.0 + twist.norm())) << "angle " << angle;
  }
}

TEST(ScanMotion, RotationsOfExactlyPiGiveAFiniteTwistOfAnglePi) {
  const std::vector<Eigen::Vector3d> axes = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitZ(),
                                             Eigen::Vector3d(1, -2, 0.5).normalized()};
  for (const Eigen::Vector3d& axis : axes) {
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = Eigen::AngleAxisd(M_PI, axis).toRotationMatrix();
    pose.translation() = Eigen::Vector3d(1.0, 2.0, -3.0);
    const Twist twist = twistLogarithm(pose);
    ASSERT_TRUE(twist.allFinite());
    EXPECT_NEAR(twist.head<3>().norm(), M_PI, 1e-12);
    EXPECT_LT((twistExponential(twist).matrix() - pose.matrix()).cwiseAbs().maxCoeff(), 1e-12);
  }
}

// The defect the real Velodyne driver hit: a step of a stationary sensor whose
// rotation is between 1e-9 and 2e-8 rad gave a NaN translation.
TEST(ScanMotion, TwistBetweenTinyRotationsIsFiniteAndRight) {
  for (const double angle : {1e-9, 1.5e-9, 5e-9, 1e-8, 1.9e-8}) {
    Eigen::Isometry3d previous = Eigen::Isometry3d::Identity(), current = Eigen::Isometry3d::Identity();
    previous.translation() = Eigen::Vector3d(10.0, -4.0, 1.0);
    current.linear() = Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    current.translation() = Eigen::Vector3d(10.001, -4.0, 1.0);
    const Twist twist = twistBetween(previous, current, 0.1);
    ASSERT_TRUE(twist.allFinite()) << "angle " << angle;
    EXPECT_NEAR(twist(2), angle / 0.1, 1e-12);
    EXPECT_NEAR(twist(3), 0.01, 1e-9);
  }
}

}  // namespace
}  // namespace range_image_mapping
