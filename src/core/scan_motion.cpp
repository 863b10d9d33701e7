#include "range_image_mapping/scan_motion.h"

#include <cmath>

namespace range_image_mapping {
namespace {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

}  // namespace

Eigen::Isometry3d twistExponential(const Twist& twist) {
  const Eigen::Vector3d omega = twist.head<3>(), v = twist.tail<3>();
  const double angle = omega.norm();
  const Eigen::Matrix3d w = skew(omega);
  Eigen::Matrix3d left_jacobian = Eigen::Matrix3d::Identity();
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  if (angle < 1e-9) {
    left_jacobian += 0.5 * w;
    pose.linear() = Eigen::Matrix3d::Identity() + w;
  } else {
    left_jacobian += (1.0 - std::cos(angle)) / (angle * angle) * w +
                     (angle - std::sin(angle)) / (angle * angle * angle) * w * w;
    pose.linear() = Eigen::AngleAxisd(angle, omega / angle).toRotationMatrix();
  }
  pose.translation() = left_jacobian * v;
  return pose;
}

Twist twistLogarithm(const Eigen::Isometry3d& pose) {
  const Eigen::AngleAxisd rotation(pose.linear());
  const Eigen::Vector3d omega = rotation.angle() * rotation.axis();
  const double angle = rotation.angle();
  const Eigen::Matrix3d w = skew(omega);
  Eigen::Matrix3d inverse_left_jacobian = Eigen::Matrix3d::Identity() - 0.5 * w;
  if (angle > 1e-9)
    inverse_left_jacobian += (1.0 - angle * std::sin(angle) / (2.0 * (1.0 - std::cos(angle)))) /
                             (angle * angle) * w * w;
  Twist twist;
  twist << omega, inverse_left_jacobian * pose.translation();
  return twist;
}

Twist twistBetween(const Eigen::Isometry3d& previous, const Eigen::Isometry3d& current, double dt_s) {
  if (!(dt_s > 0.0)) return Twist::Zero();
  return twistLogarithm(previous.inverse() * current) / dt_s;
}

uint64_t scanTime(const RangeImage& scan) {
  if (scan.stamp_ns != 0) return scan.stamp_ns;
  if (scan.column_timestamp_ns.size() != std::size_t(scan.columns())) return 0;
  for (int u = 0; u < scan.columns(); ++u) {
    if (scan.column_timestamp_ns[u] == 0) continue;
    for (int v = 0; v < scan.rows(); ++v)
      if (scan.valid(v, u)) return scan.column_timestamp_ns[u];
  }
  return 0;
}

bool computeColumnMotion(const RangeImage& scan, uint64_t scan_time_ns, const Twist& twist,
                         std::vector<ColumnMotion>& motion) {
  const int columns = scan.columns();
  if (twist.isZero() || scan.column_timestamp_ns.size() != std::size_t(columns)) return false;
  motion.resize(columns);
  for (int u = 0; u < columns; ++u) {
    const uint64_t time = scan.column_timestamp_ns[u];
    const double offset = time == 0 ? 0.0 : (double(time) - double(scan_time_ns)) * 1e-9;
    motion[u] = twistExponential(offset * twist).matrix().topRows<3>().cast<float>();
  }
  return true;
}

}  // namespace range_image_mapping
