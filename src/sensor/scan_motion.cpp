#include "range_image_mapping/scan_motion.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>

namespace range_image_mapping {
namespace {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

// Coefficients of the SE(3) exponential for a rotation angle theta
// (Barfoot, State Estimation for Robotics, eq. 7.85-7.86):
//   R = I + a W + b W^2,   J = I + b W + c W^2,   t = J v,
//   a = sin(theta) / theta, b = (1 - cos(theta)) / theta^2,
//   c = (theta - sin(theta)) / theta^3.
// b is evaluated as 2 sin^2(theta / 2) / theta^2, which does not cancel;
// a and c by their Taylor series below kSeriesAngle, where the closed forms
// lose digits (c cancels catastrophically) and the series' next term is
// below double precision.
constexpr double kSeriesAngle = 1e-2;

struct ExponentialCoefficients {
  double a, b, c;
};

ExponentialCoefficients exponentialCoefficients(double theta) {
  const double theta2 = theta * theta;
  if (theta < kSeriesAngle)
    return {1.0 - theta2 / 6.0 * (1.0 - theta2 / 20.0 * (1.0 - theta2 / 42.0)),
            0.5 - theta2 / 24.0 * (1.0 - theta2 / 30.0 * (1.0 - theta2 / 56.0)),
            1.0 / 6.0 - theta2 / 120.0 * (1.0 - theta2 / 42.0 * (1.0 - theta2 / 72.0))};
  const double half_sine = std::sin(0.5 * theta);
  return {std::sin(theta) / theta, 2.0 * half_sine * half_sine / theta2,
          (theta - std::sin(theta)) / (theta2 * theta)};
}

// d in J^-1 = I - W / 2 + d W^2: d = (1 - (theta / 2) cot(theta / 2)) / theta^2,
// finite up to theta = pi (cot(pi / 2) = 0); its series below kSeriesAngle.
double inverseJacobianCoefficient(double theta) {
  const double theta2 = theta * theta;
  if (theta < kSeriesAngle) return 1.0 / 12.0 + theta2 / 720.0 + theta2 * theta2 / 30240.0;
  const double half = 0.5 * theta;
  return (1.0 - half * std::cos(half) / std::sin(half)) / theta2;
}

}  // namespace

Eigen::Isometry3d twistExponential(const Twist& twist) {
  const Eigen::Vector3d omega = twist.head<3>(), v = twist.tail<3>();
  const Eigen::Matrix3d w = skew(omega), w2 = w * w;
  const ExponentialCoefficients k = exponentialCoefficients(omega.norm());
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::Matrix3d::Identity() + k.a * w + k.b * w2;
  pose.translation() = (Eigen::Matrix3d::Identity() + k.b * w + k.c * w2) * v;
  return pose;
}

Twist twistLogarithm(const Eigen::Isometry3d& pose) {
  // The rotation through its unit quaternion: angle 2 atan2(|q.vec|, |q.w|)
  // is exact at every angle, where acos((trace - 1) / 2) loses half the digits
  // near 0 and near pi.
  Eigen::Quaterniond q(pose.linear());
  q.normalize();
  if (q.w() < 0.0) q.coeffs() = -q.coeffs();  // the rotation angle in [0, pi]
  const double sine_half = q.vec().norm();
  const double theta = 2.0 * std::atan2(sine_half, q.w());
  // omega = theta * q.vec / sin(theta / 2): no cancellation at any angle; the
  // ratio tends to 2 as theta -> 0.
  const double scale = sine_half > 0.0 ? theta / sine_half : 2.0;
  const Eigen::Vector3d omega = scale * q.vec();
  const Eigen::Matrix3d w = skew(omega);
  const Eigen::Matrix3d inverse_left_jacobian =
      Eigen::Matrix3d::Identity() - 0.5 * w + inverseJacobianCoefficient(omega.norm()) * w * w;
  Twist twist;
  twist << omega, inverse_left_jacobian * pose.translation();
  return twist;
}

Twist twistBetween(const Eigen::Isometry3d& previous, const Eigen::Isometry3d& current, double dt_s) {
  if (!(dt_s > 0.0)) return Twist::Zero();
  return twistLogarithm(previous.inverse() * current) / dt_s;
}

Twist twistInFrame(const Eigen::Isometry3d& to_from_frame, const Twist& twist) {
  Twist result;
  result.head<3>() = to_from_frame.linear() * twist.head<3>();
  result.tail<3>() = to_from_frame.linear() * twist.tail<3>() + to_from_frame.translation().cross(result.head<3>());
  return result;
}

uint64_t scanTime(const RangeImage& scan, ScanTimeSource source) {
  if (source == ScanTimeSource::kStamp || scan.column_timestamp_ns.size() != std::size_t(scan.columns()))
    return scan.stamp_ns;
  for (int u = 0; u < scan.columns(); ++u) {
    if (scan.column_timestamp_ns[u] == 0) continue;
    for (int v = 0; v < scan.rows(); ++v)
      if (scan.valid(v, u)) return scan.column_timestamp_ns[u];
  }
  return scan.stamp_ns;
}

bool computeColumnMotion(const RangeImage& scan, uint64_t scan_time_ns, const Twist& twist,
                         std::vector<ColumnMotion>& motion) {
  const int columns = scan.columns();
  if (twist.isZero() || scan.column_timestamp_ns.size() != std::size_t(columns)) return false;
  motion.resize(columns);
  // Each column on its own (the odometry asks for them on every deskew pass).
  tbb::parallel_for(tbb::blocked_range<int>(0, columns, 64), [&](const tbb::blocked_range<int>& block) {
    for (int u = block.begin(); u < block.end(); ++u) {
      const uint64_t time = scan.column_timestamp_ns[u];
      const double offset = time == 0 ? 0.0 : (double(time) - double(scan_time_ns)) * 1e-9;
      motion[u] = twistExponential(offset * twist).matrix().topRows<3>().cast<float>();
    }
  });
  return true;
}

}  // namespace range_image_mapping
