// A diagnostic_updater that publishes once a second of wall time. The
// updater's own period runs on ROS time, which stops with a paused replay
// and, after a bag loop, would hold diagnostics back for as long as the jump.
#pragma once

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/node_handle.h>

#include <memory>
#include <string>

namespace range_image_mapping {

class WallClockDiagnostics {
 public:
  WallClockDiagnostics(ros::NodeHandle& node, ros::NodeHandle& private_node, const std::string& name,
                       const std::string& hardware_id)
      : updater_(node, private_node, name) {
    updater_.setHardwareID(hardware_id);
    timer_ = node.createSteadyTimer(ros::WallDuration(1.0),
                                    [this](const ros::SteadyTimerEvent&) { updater_.force_update(); });
  }
  // The timer holds this object's address.
  WallClockDiagnostics(const WallClockDiagnostics&) = delete;
  WallClockDiagnostics& operator=(const WallClockDiagnostics&) = delete;

  diagnostic_updater::Updater& updater() { return updater_; }

 private:
  diagnostic_updater::Updater updater_;
  ros::SteadyTimer timer_;
};

}  // namespace range_image_mapping
