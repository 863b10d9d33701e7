// Log throttling on the steady clock: ROS's *_THROTTLE macros use ROS time,
// which stands still in a paused replay or before a bag's clock starts, and
// then never log at all.
#pragma once

#include <ros/time.h>

namespace range_image_mapping {

// Lets one message through per period.
class SteadyThrottle {
 public:
  bool allow(double period_s) {
    const ros::SteadyTime now = ros::SteadyTime::now();
    if (!last_.isZero() && (now - last_).toSec() < period_s) return false;
    last_ = now;
    return true;
  }

 private:
  ros::SteadyTime last_;
};

}  // namespace range_image_mapping
