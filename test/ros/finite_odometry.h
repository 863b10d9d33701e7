// Every number of a nav_msgs/Odometry is finite: pose, twist and both
// covariances (shared by the rostests that check no NaN leaves the odometry).
#pragma once

#include <nav_msgs/Odometry.h>

#include <cmath>

namespace range_image_mapping::test {

inline bool isFinite(const nav_msgs::Odometry& odometry) {
  const geometry_msgs::Pose& p = odometry.pose.pose;
  const geometry_msgs::Twist& t = odometry.twist.twist;
  bool ok = std::isfinite(p.position.x) && std::isfinite(p.position.y) && std::isfinite(p.position.z) &&
            std::isfinite(p.orientation.x) && std::isfinite(p.orientation.y) && std::isfinite(p.orientation.z) &&
            std::isfinite(p.orientation.w) && std::isfinite(t.linear.x) && std::isfinite(t.linear.y) &&
            std::isfinite(t.linear.z) && std::isfinite(t.angular.x) && std::isfinite(t.angular.y) &&
            std::isfinite(t.angular.z);
  for (double c : odometry.pose.covariance) ok = ok && std::isfinite(c);
  for (double c : odometry.twist.covariance) ok = ok && std::isfinite(c);
  return ok;
}

}  // namespace range_image_mapping::test
