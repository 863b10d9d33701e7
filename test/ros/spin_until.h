// Waiting in rostest nodes: spin callbacks until a condition holds or the
// timeout passes on the steady clock (simulated time stops when a bag ends;
// the wall clock can be stepped), or the node is shut down.
#pragma once

#include <ros/ros.h>

#include <functional>

namespace range_image_mapping::test {

inline bool spinUntil(const std::function<bool()>& done, double timeout_s) {
  const ros::SteadyTime deadline = ros::SteadyTime::now() + ros::WallDuration(timeout_s);
  while (ros::ok() && !done() && ros::SteadyTime::now() < deadline) {
    ros::spinOnce();
    ros::WallDuration(0.01).sleep();
  }
  return done();
}

}  // namespace range_image_mapping::test
