// Windows of a nodelet's running counters on the steady clock, for the
// periodic log and the diagnostics: both report what happened since they last
// reported, at wall-clock rates that hold in a paused or fast replay.
#pragma once

#include <ros/time.h>

#include <utility>

namespace range_image_mapping {

// Statistics: counters since the start, with operator- giving the counts
// between two snapshots.
template <typename Statistics>
struct StatisticsWindow {
  Statistics start;
  ros::SteadyTime started;

  // The counts since the last call and the window's length in seconds (0 on
  // the first call); starts a new window.
  std::pair<Statistics, double> advance(const Statistics& now) {
    const ros::SteadyTime time = ros::SteadyTime::now();
    const double period = started.isZero() ? 0.0 : (time - started).toSec();
    const Statistics window = now - start;
    start = now;
    started = time;
    return {window, period};
  }
};

}  // namespace range_image_mapping
