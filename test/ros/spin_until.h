// Waiting in rostest nodes: spin callbacks until a condition holds or the
// wall-clock timeout passes (simulated time stops when a bag ends).
#pragma once

#include <ros/ros.h>

#include <functional>

namespace range_image_mapping::test {

inline bool spinUntil(const std::function<bool()>& done, double timeout_s) {
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(timeout_s);
  while (ros::ok() && !done() && ros::WallTime::now() < deadline) {
    ros::spinOnce();
    ros::WallDuration(0.01).sleep();
  }
  return done();
}

}  // namespace range_image_mapping::test
