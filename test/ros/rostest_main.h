// The main() of a rostest node: gtest and ROS initialised, a node handle held
// for the whole run (so the node stays registered between tests), and the
// generated sequence named by the private parameter ~sequence_dir removed once
// every test passed (kept after a failure, to look at).
#pragma once

#include <gtest/gtest.h>
#include <ros/ros.h>

#include <filesystem>
#include <string>

namespace range_image_mapping::test {

inline int runRostestNode(int argc, char** argv, const std::string& node_name) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, node_name);
  ros::NodeHandle keep_node_alive;
  const int result = RUN_ALL_TESTS();
  const std::string sequence_dir = ros::NodeHandle("~").param<std::string>("sequence_dir", "");
  if (!sequence_dir.empty() && result == 0) std::filesystem::remove_all(sequence_dir);
  return result;
}

}  // namespace range_image_mapping::test
