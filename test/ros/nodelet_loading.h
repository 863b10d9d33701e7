// Loading a nodelet in this process, as a manager does (nodelet::Loader
// without its ROS API), and the reason it gave when it refused. Loader::load
// answers only false (nodelet 1.10 logs "Failed to initialize nodelet"
// without the reason), so the reason is what the nodelet logged as FATAL
// (startOrRefuseLoad) during the load.
#pragma once

#include <gtest/gtest.h>
#include <nodelet/loader.h>
#include <ros/console.h>
#include <ros/node_handle.h>

#include <string>
#include <vector>

namespace range_image_mapping::test {

struct LoadAttempt {
  bool loaded = false;
  std::string refusal;  // the FATAL lines logged while loading
};

inline LoadAttempt loadNodelet(nodelet::Loader& loader, const std::string& name, const std::string& type) {
  struct FatalLines : ros::console::LogAppender {
    void log(ros::console::Level level, const char* text, const char*, const char*, int) override {
      if (level == ros::console::levels::Fatal) lines += std::string(text) + "\n";
    }
    std::string lines;
  } fatal;
  ros::console::register_appender(&fatal);
  LoadAttempt attempt;
  attempt.loaded = loader.load(name, type, nodelet::M_string(), nodelet::V_string());
  ros::console::deregister_appender(&fatal);
  attempt.refusal = fatal.lines;
  return attempt;
}

// The nodelet `type` loaded as `name`, with its private parameter
// `parameter` set to `value`, is refused with a FATAL line that contains
// `reason`.
template <typename Value>
void expectRefused(nodelet::Loader& loader, const std::string& type, const std::string& name,
                   const std::string& parameter, const Value& value, const std::string& reason) {
  SCOPED_TRACE(name);
  ros::NodeHandle(name).setParam(parameter, value);
  const LoadAttempt attempt = loadNodelet(loader, name, type);
  EXPECT_FALSE(attempt.loaded);
  EXPECT_NE(attempt.refusal.find(reason), std::string::npos) << attempt.refusal;
}

// ... and loaded as `name` with the private parameters already set there, it
// loads without a word of refusal (so the refusals are the parameters'), the
// only nodelet of the loader.
inline void expectLoaded(nodelet::Loader& loader, const std::string& type, const std::string& name) {
  SCOPED_TRACE(name);
  const LoadAttempt attempt = loadNodelet(loader, name, type);
  EXPECT_TRUE(attempt.loaded);
  EXPECT_EQ(attempt.refusal, "");
  EXPECT_EQ(loader.listLoadedNodelets(), std::vector<std::string>{name});
}

}  // namespace range_image_mapping::test
