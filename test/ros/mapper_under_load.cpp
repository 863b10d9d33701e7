// 300 simulated OS1-128 scans through range_image_mapping.launch at rate 1
// while a child process of this test keeps one core busy: every scan must
// reach the odometry and every scan the map. The Mapper's diagnostics
// (tsdf_mapper) give its totals and, when a scan is lost, the reason; the
// figures under load (scan-to-map latency, scans waiting for a pose, mesh
// updates deferred) are printed for the record. The test listens to the mesh
// as rviz would, so the Mapper meshes while it integrates (nobody listening,
// it would not mesh at all). A third of the way in, the nodelet manager is
// stopped (SIGSTOP) for longer than a nodelet bond's heartbeat timeout (4 s),
// as a stalled machine stops it: the pipeline must go on where it stopped.
#include "rostest_main.h"
#include "spin_until.h"

#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <std_srvs/SetBool.h>
#include <visualization_msgs/MarkerArray.h>

#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <set>
#include <string>

namespace range_image_mapping {
namespace {

using test::spinUntil;

// A process that spins until killed: one core's worth of load.
class BusyCore {
 public:
  BusyCore() {
    pid_ = fork();
    if (pid_ == 0) {
      prctl(PR_SET_PDEATHSIG, SIGKILL);  // also when the test itself is killed (time limit)
      if (getppid() == 1) _exit(0);
      volatile unsigned long counter = 0;
      for (;;) counter = counter + 1;
    }
  }
  ~BusyCore() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }
  bool running() const { return pid_ > 0 && kill(pid_, 0) == 0; }

 private:
  pid_t pid_ = -1;
};

// The process whose command line holds `argument` (roslaunch names a node by
// `__name:=NAME`), or -1.
pid_t processWithArgument(const std::string& argument) {
  for (const std::filesystem::directory_entry& entry : std::filesystem::directory_iterator("/proc")) {
    const std::string pid = entry.path().filename();
    if (pid.find_first_not_of("0123456789") != std::string::npos) continue;
    std::ifstream file(entry.path() / "cmdline", std::ios::binary);
    const std::string command_line{std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>()};
    for (std::size_t start = 0; start < command_line.size();) {  // NUL-separated arguments
      const std::size_t end = std::min(command_line.find('\0', start), command_line.size());
      if (command_line.compare(start, end - start, argument) == 0) return pid_t(std::stol(pid));
      start = end + 1;
    }
  }
  return -1;
}

// A process held stopped for the object's lifetime (continued also when a
// failed assertion leaves the scope).
class StoppedProcess {
 public:
  explicit StoppedProcess(pid_t pid) : pid_(pid), stopped_(pid > 0 && kill(pid, SIGSTOP) == 0) {}
  ~StoppedProcess() {
    if (stopped_) kill(pid_, SIGCONT);
  }
  bool stopped() const { return stopped_; }

 private:
  pid_t pid_;
  bool stopped_;
};

// A nodelet's status values, the last message's and the largest seen.
struct NodeletStatus {
  std::map<std::string, std::string> last;
  std::map<std::string, double> largest;
  std::size_t messages = 0;

  double value(const std::string& key) const {
    const auto found = last.find(key);
    return found == last.end() ? -1.0 : std::stod(found->second);
  }
  double peak(const std::string& key) const {
    const auto found = largest.find(key);
    return found == largest.end() ? -1.0 : found->second;
  }
};

TEST(MapperUnderLoad, EveryScanReachesTheOdometryAndTheMap) {
  ros::NodeHandle node, private_node("~");
  const int frames = private_node.param("frames", 300);
  const double timeout_s = private_node.param("timeout", 420.0);
  const double stall_s = private_node.param("manager_stall", 6.0);
  const std::string manager_name = private_node.param<std::string>("manager", "rim_manager");

  std::set<double> odometry_stamps;
  ros::Subscriber odometry_subscriber = node.subscribe<nav_msgs::Odometry>(
      "/odometry", 1000,
      [&](const nav_msgs::Odometry::ConstPtr& message) { odometry_stamps.insert(message->header.stamp.toSec()); });
  std::size_t mesh_messages = 0, mesh_markers = 0;
  ros::Subscriber mesh_subscriber = node.subscribe<visualization_msgs::MarkerArray>(
      "/mesh", 100, [&](const visualization_msgs::MarkerArray::ConstPtr& message) {
        ++mesh_messages;
        mesh_markers += message->markers.size();
      });
  std::map<std::string, NodeletStatus> statuses;  // by hardware id on /diagnostics
  NodeletStatus& adapter = statuses["lidar_adapter"];
  NodeletStatus& odometry = statuses["lidar_odometry"];
  NodeletStatus& mapper = statuses["tsdf_mapper"];
  std::set<std::string> reporting;  // hardware ids on /diagnostics
  double deferred = 0.0;
  ros::Subscriber diagnostics_subscriber = node.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 100, [&](const diagnostic_msgs::DiagnosticArray::ConstPtr& message) {
        for (const diagnostic_msgs::DiagnosticStatus& status : message->status) {
          reporting.insert(status.hardware_id);
          const auto found = statuses.find(status.hardware_id);
          if (found == statuses.end()) continue;
          NodeletStatus& nodelet = found->second;
          ++nodelet.messages;
          for (const diagnostic_msgs::KeyValue& entry : status.values) {
            nodelet.last[entry.key] = entry.value;
            try {
              double& largest = nodelet.largest.try_emplace(entry.key, -1e300).first->second;
              largest = std::max(largest, std::stod(entry.value));
            } catch (const std::exception&) {
              // a text value (last warning)
            }
          }
          if (&nodelet == &mapper) deferred += mapper.value("mesh updates deferred (behind)");
        }
      });

  // The replay starts paused and this node starts it once the whole chain
  // listens (every nodelet has reported, this node's /odometry is
  // connected): a late start on a slow machine would lose the first scans.
  ASSERT_TRUE(spinUntil(
      [&] {
        return reporting.count("lidar_adapter") && reporting.count("lidar_odometry") &&
               reporting.count("tsdf_mapper") && odometry_subscriber.getNumPublishers() > 0 &&
               mesh_subscriber.getNumPublishers() > 0;
      },
      120.0))
      << "the nodelets did not all report within 120 s (adapter " << reporting.count("lidar_adapter")
      << ", odometry " << reporting.count("lidar_odometry") << ", mapper " << reporting.count("tsdf_mapper")
      << "), or /odometry or /mesh has no publisher";
  const std::string resume_service = "/rosbag_play/pause_playback";
  ASSERT_TRUE(ros::service::waitForService(resume_service, 120 * 1000)) << resume_service << " never came";

  const BusyCore busy;  // from before the replay starts to the end
  ASSERT_TRUE(busy.running());
  std_srvs::SetBool resume;
  resume.request.data = false;
  ASSERT_TRUE(ros::service::call(resume_service, resume) && resume.response.success)
      << "the replay did not start: " << resume.response.message;
  const auto started = std::chrono::steady_clock::now();
  const auto elapsed_s = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  };
  // The stall, once a third of the scans are posed (the Mapper is behind then).
  const pid_t manager_pid = processWithArgument("__name:=" + manager_name);
  ASSERT_GT(manager_pid, 0) << "no process named " << manager_name;
  ASSERT_TRUE(spinUntil([&] { return int(odometry_stamps.size()) >= frames / 3; }, timeout_s))
      << "a third of the scans were not posed within " << timeout_s << " s";
  {
    const StoppedProcess stall(manager_pid);
    ASSERT_TRUE(stall.stopped()) << "could not stop the manager (pid " << manager_pid << ")";
    spinUntil([] { return false; }, stall_s);
  }
  const bool done = spinUntil(
      [&] {
        return int(odometry_stamps.size()) >= frames && mapper.value("total scans integrated") >= frames;
      },
      timeout_s - elapsed_s());
  const double waited_s = elapsed_s();
  const bool node_shut_down = !ros::ok();
  // Meshing slows under load (it waits while the Mapper is behind), so the
  // mesh may reach this node only after the last scan; at most a minute.
  if (done) spinUntil([&] { return mesh_markers > 0 && mapper.value("triangles") > 0.0; }, 60.0);
  // The last diagnostics after the replay: nothing more comes in.
  spinUntil([] { return false; }, 3.0);

  // Where each scan went, stage by stage, so that a loss names its stage.
  const int packets_per_scan = 1024 / 16;  // outdoor_car's OS1-128: 1024 columns, 16 per packet
  char summary[2048];
  std::snprintf(summary, sizeof(summary),
                "under load: adapter: %s of %d packets, %s scans (%s incomplete, %s read late, %s early, %s "
                "restamped, %s clock steps); odometry: %s scans received, %s stepped, %s published, %s out of "
                "order, %s held for tf base -> lidar, %s dropped frames; %zu odometry messages here; mapper: %s "
                "scans received, %s integrated, %s without pose, %s lost before; max scan-to-map latency %.0f ms, "
                "max scans waiting for a pose %.0f, mean pose wait up to %.1f ms, %.0f mesh updates deferred, mean "
                "integration up to %.1f ms, mean mesh update up to %.1f ms, triangles %s (%s shown); %zu mesh "
                "messages (%zu markers) here",
                adapter.last["packets"].c_str(), frames * packets_per_scan, adapter.last["scans"].c_str(),
                adapter.last["incomplete scans"].c_str(), adapter.last["scans received late (stall)"].c_str(),
                adapter.last["scans received early (ROS time stood still)"].c_str(),
                adapter.last["scans restamped (stamp would not advance)"].c_str(),
                adapter.last["clock steps (stamps follow the receipt anew)"].c_str(),
                odometry.last["total scans received"].c_str(), odometry.last["total scans stepped"].c_str(),
                odometry.last["total scans published"].c_str(), odometry.last["total out of order"].c_str(),
                odometry.last["total scans held for tf (base_frame -> lidar)"].c_str(),
                odometry.last["total dropped frames"].c_str(), odometry_stamps.size(),
                mapper.last["total scans received"].c_str(),
                mapper.last["total scans integrated"].c_str(), mapper.last["total scans without pose"].c_str(),
                mapper.last["total scans lost before the mapper"].c_str(),
                mapper.peak("max scan-to-map latency (ms)"), mapper.peak("max scans waiting for a pose"),
                mapper.peak("mean pose wait (ms)"), deferred, mapper.peak("mean integration (ms)"),
                mapper.peak("mean mesh update (ms)"), mapper.last["triangles"].c_str(),
                mapper.last["triangles shown"].c_str(), mesh_messages, mesh_markers);
  std::printf("%s\n", summary);
  SCOPED_TRACE(summary);  // in every failure message below, so a CI log's summary has the figures
  EXPECT_FALSE(node_shut_down) << "this node was shut down after " << waited_s
                               << " s: roslaunch ends the launch when a required node (the Mapper's loader) exits";
  EXPECT_TRUE(done) << "not every scan arrived within " << waited_s << " s (limit " << timeout_s
                    << " s); last warning: " << mapper.last["last warning"];
  EXPECT_EQ(adapter.value("scans"), frames) << "scans the Adapter assembled from the packets";
  EXPECT_EQ(odometry.value("total scans published"), frames) << "last warning: " << odometry.last["last warning"];
  EXPECT_EQ(int(odometry_stamps.size()), frames) << "scans posed by the odometry, as this node received them";
  EXPECT_EQ(mapper.value("total scans received"), frames);
  EXPECT_EQ(mapper.value("total scans integrated"), frames) << "last warning: " << mapper.last["last warning"];
  EXPECT_EQ(mapper.value("total scans without pose"), 0.0) << "last warning: " << mapper.last["last warning"];
  EXPECT_EQ(mapper.value("total scans lost before the mapper"), 0.0);
  EXPECT_GT(mapper.value("triangles"), 0.0) << "the Mapper never meshed, though /mesh has a subscriber";
  EXPECT_GT(mesh_markers, 0u) << "no mesh reached the subscriber";
  EXPECT_TRUE(busy.running()) << "the busy process ended early: the load was not there all along";
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  return range_image_mapping::test::runRostestNode(argc, argv, "mapper_under_load");
}
