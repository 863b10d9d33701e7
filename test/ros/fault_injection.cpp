// Fault injection into range_image_mapping.launch. This node is a
// misbehaving Ouster driver and bag player at once: it owns /clock, the
// latched metadata and the packets of a simulated indoor_cart sequence, and
// feeds PointCloud2 clouds of the same sequence to a second Adapter and
// Odometry in the same nodelet manager. Each scan waits for the pipeline's
// answer, so the faults, not the machine's load, decide what is dropped.
//
// Faults, in order: random, truncated, oversized and empty packets and a
// packet with a valid header but random payload; missing packets; a missing
// revolution; a revolution sent twice; two revolutions swapped; two scans
// received at the same ROS time (the clock stalls: the Adapter stamps the
// second from the sensor clock and warns); metadata that is not JSON, not metadata,
// a new serial number, a profile the packets do not have, then the original
// again; clouds with NaN and infinite points, all NaN, empty, truncated,
// without x, the same stamp twice and two swapped; then a bag loop: ROS time
// goes back to the start and the sequence is replayed.
//
// Afterwards: the manager is alive and every nodelet publishes again; no
// odometry message holds a NaN; the drops and rejections were counted and
// said; the Odometry restarted on the loop and said so, at the identity, so
// the replayed scans get the poses they had the first time; and the mesh
// saved after the loop still covers the mesh saved before it, without ghosts.
#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/SaveMesh.h"
#include "range_image_mapping/evaluation/surface_metrics.h"
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/ouster_packet.h"
#include "range_image_mapping/ros/bag_writer.h"

#include "finite_odometry.h"
#include "rostest_main.h"
#include "spin_until.h"

#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <rosgraph_msgs/Clock.h>
#include <rosgraph_msgs/Log.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_msgs/String.h>
#include <tf2_eigen/tf2_eigen.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <limits>
#include <map>
#include <numeric>
#include <optional>
#include <random>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

using test::spinUntil;
using Packet = std::vector<uint8_t>;

void spinFor(double seconds) {
  spinUntil([] { return false; }, seconds);
}

// ------------------------------------------------------------ the sequence

struct PacketScan {
  uint32_t frame_id = 0;
  std::vector<Packet> packets;
  std::vector<ros::Time> times;  // bag time of each packet
};

struct Sequence {
  std::string metadata_json;
  ros::Time start;  // the metadata's bag time: where the bag begins
  std::vector<PacketScan> scans;
  std::vector<sensor_msgs::PointCloud2> clouds;
};

Sequence readSequence(const std::string& directory) {
  Sequence sequence;
  rosbag::Bag packets(directory + "/packets.bag", rosbag::bagmode::Read);
  std::optional<PacketFormat> format;
  for (const rosbag::MessageInstance& message : rosbag::View(packets)) {
    if (message.getTopic() == "/ouster/metadata") {
      sequence.metadata_json = message.instantiate<std_msgs::String>()->data;
      sequence.start = message.getTime();
      format.emplace(parseOusterMetadata(sequence.metadata_json));
    } else if (message.getTopic() == "/ouster/lidar_packets") {
      if (!format) throw std::runtime_error("packets before the metadata in " + directory + "/packets.bag");
      const auto packet = message.instantiate<OusterPacketMessage>();
      const uint32_t frame_id = format->frameId(packet->buf.data());
      if (sequence.scans.empty() || sequence.scans.back().frame_id != frame_id) {
        sequence.scans.emplace_back();
        sequence.scans.back().frame_id = frame_id;
      }
      sequence.scans.back().packets.push_back(packet->buf);
      sequence.scans.back().times.push_back(message.getTime());
    }
  }
  rosbag::Bag clouds(directory + "/points.bag", rosbag::bagmode::Read);
  for (const rosbag::MessageInstance& message : rosbag::View(clouds))
    if (const auto cloud = message.instantiate<sensor_msgs::PointCloud2>()) sequence.clouds.push_back(*cloud);
  return sequence;
}

// The metadata text with its first occurrence of `from` replaced (a serial
// number, a profile name), checked to parse and to have changed.
std::string changedMetadata(const std::string& json, const std::string& from, const std::string& to) {
  const std::size_t at = json.find(from);
  if (at == std::string::npos) throw std::runtime_error("the metadata has no '" + from + "'");
  std::string changed = json;
  changed.replace(at, from.size(), to);
  parseOusterMetadata(changed);
  return changed;
}

// ------------------------------------------------------------ what the pipeline says


struct Outputs {
  std::vector<LidarRangeImage::ConstPtr> images, cloud_images;
  std::vector<nav_msgs::Odometry::ConstPtr> odometry, cloud_odometry;
  std::size_t non_finite_odometry = 0;
  std::vector<std::string> log;  // /rosout of the manager: "LEVEL message"
  // After the loop: the first /odometry diagnostics that count a reset ("resets: N, last warning: ...").
  bool loop_started = false;
  std::string loop_reset_diagnostics;

  std::set<std::string> diagnostic_names;
  void noteDiagnostics(const diagnostic_msgs::DiagnosticStatus& status) {
    diagnostic_names.insert(status.name);
    if (!loop_started || !loop_reset_diagnostics.empty() || status.name != "odometry: odometry") return;
    std::string resets, warning;
    for (const diagnostic_msgs::KeyValue& value : status.values) {
      if (value.key == "resets") resets = value.value;
      if (value.key == "last warning") warning = value.value;
    }
    if (!resets.empty() && resets != "0") loop_reset_diagnostics = "resets: " + resets + ", last warning: " + warning;
  }

  bool logged(const std::string& pattern) const {
    const std::regex expression(pattern);
    return std::any_of(log.begin(), log.end(), [&](const std::string& line) { return std::regex_search(line, expression); });
  }
  // Sum of the first number after each match of pattern (the Adapter's drop summaries).
  std::size_t loggedCount(const std::string& pattern) const {
    const std::regex expression(pattern + " ([0-9]+)");
    std::size_t total = 0;
    for (const std::string& line : log)
      for (std::sregex_iterator match(line.begin(), line.end(), expression), end; match != end; ++match)
        total += std::stoul((*match)[1]);
    return total;
  }
};

// ------------------------------------------------------------ the faulty driver

class FaultInjectionTest : public testing::Test {
 protected:
  void SetUp() override {
    ros::NodeHandle private_node("~");
    sequence_dir_ = private_node.param<std::string>("sequence_dir", "");
    step_timeout_s_ = private_node.param("step_timeout", step_timeout_s_);
    ASSERT_TRUE(std::filesystem::exists(sequence_dir_ + "/packets.bag")) << sequence_dir_;
    sequence_ = readSequence(sequence_dir_);
    ASSERT_GE(sequence_.scans.size(), 20u);
    ASSERT_GE(sequence_.clouds.size(), 11u);

    clock_publisher_ = node_.advertise<rosgraph_msgs::Clock>("/clock", 100);
    metadata_publisher_ = node_.advertise<std_msgs::String>("/ouster/metadata", 1, true);
    packet_publisher_ = node_.advertise<OusterPacketMessage>("/ouster/lidar_packets", 4096);
    cloud_publisher_ = node_.advertise<sensor_msgs::PointCloud2>("/cloud/points", 16);
    subscribers_.push_back(node_.subscribe<LidarRangeImage>(
        "/range_image", 64, [this](const LidarRangeImage::ConstPtr& image) { outputs_.images.push_back(image); }));
    subscribers_.push_back(node_.subscribe<LidarRangeImage>(
        "/cloud/range_image", 64,
        [this](const LidarRangeImage::ConstPtr& image) { outputs_.cloud_images.push_back(image); }));
    subscribers_.push_back(node_.subscribe<nav_msgs::Odometry>(
        "/odometry", 64, [this](const nav_msgs::Odometry::ConstPtr& odometry) {
          outputs_.odometry.push_back(odometry);
          outputs_.non_finite_odometry += !test::isFinite(*odometry);
        }));
    subscribers_.push_back(node_.subscribe<nav_msgs::Odometry>(
        "/cloud/odometry", 64, [this](const nav_msgs::Odometry::ConstPtr& odometry) {
          outputs_.cloud_odometry.push_back(odometry);
          outputs_.non_finite_odometry += !test::isFinite(*odometry);
        }));
    subscribers_.push_back(node_.subscribe<rosgraph_msgs::Log>("/rosout", 1000, [this](const rosgraph_msgs::Log::ConstPtr& log) {
      if (log->name == "/rim_manager") outputs_.log.push_back(std::to_string(int(log->level)) + " " + log->msg);
    }));
    subscribers_.push_back(node_.subscribe<diagnostic_msgs::DiagnosticArray>(
        "/diagnostics", 100, [this](const diagnostic_msgs::DiagnosticArray::ConstPtr& array) {
          for (const diagnostic_msgs::DiagnosticStatus& status : array->status) outputs_.noteDiagnostics(status);
        }));

    // ROS time starts where the bag does; the nodelets must be listening first.
    setClock(sequence_.start);
    ASSERT_TRUE(spinUntil(
        [&] {
          return packet_publisher_.getNumSubscribers() > 0 && cloud_publisher_.getNumSubscribers() > 0 &&
                 subscribers_[0].getNumPublishers() > 0 && subscribers_[1].getNumPublishers() > 0 &&
                 subscribers_[2].getNumPublishers() > 0 && subscribers_[3].getNumPublishers() > 0;
        },
        30.0))
        << "the nodelets did not connect";
    sendMetadata(sequence_.metadata_json);
    spinFor(1.0);
  }

  void TearDown() override {
    if (!sequence_dir_.empty()) std::filesystem::remove_all(sequence_dir_);
  }

  void setClock(const ros::Time& time) {
    rosgraph_msgs::Clock clock;
    clock.clock = time;
    clock_ = time;
    clock_publisher_.publish(clock);
  }

  void sendMetadata(const std::string& json) {
    std_msgs::String message;
    message.data = json;
    metadata_publisher_.publish(message);
    spinFor(0.3);
  }

  void sendPacket(const Packet& bytes) {
    OusterPacketMessage message;
    message.buf = bytes;
    packet_publisher_.publish(message);
  }

  // The clock steps to the scan's first packet and never goes back (receipt
  // times of reordered packets still increase); hold keeps it where it is.
  // One step per scan, ahead of its packets: the packets come in a burst, on
  // another connection than the clock, so a clock that followed every packet
  // would stamp the scan with whichever tick the Adapter had seen first.
  void sendScan(const PacketScan& scan, bool hold_clock = false, const std::set<std::size_t>& skip = {}) {
    if (!hold_clock) setClock(std::max(clock_, scan.times.front()));
    spinFor(0.05);  // the clock first, so the scan is stamped with it
    for (std::size_t i = 0; i < scan.packets.size(); ++i)
      if (!skip.count(i)) sendPacket(scan.packets[i]);
  }

  // Waits for the pipeline's answer to what was just sent: an image, then
  // (when one is expected) its odometry, so nothing is dropped for load.
  void awaitScan(bool expect_odometry = true) {
    const std::size_t images = outputs_.images.size(), odometry = outputs_.odometry.size();
    spinUntil([&] { return outputs_.images.size() > images; }, step_timeout_s_);
    if (expect_odometry)
      spinUntil([&] { return outputs_.odometry.size() > odometry; }, step_timeout_s_);
    else
      spinFor(0.5);
  }
  void playScan(std::size_t index, bool expect_odometry = true) {
    sendScan(sequence_.scans.at(index));
    awaitScan(expect_odometry);
  }

  void sendCloud(const sensor_msgs::PointCloud2& cloud, bool expect_image, bool expect_odometry) {
    const std::size_t images = outputs_.cloud_images.size(), odometry = outputs_.cloud_odometry.size();
    cloud_publisher_.publish(cloud);
    if (expect_image)
      spinUntil([&] { return outputs_.cloud_images.size() > images; }, step_timeout_s_);
    if (expect_odometry)
      spinUntil([&] { return outputs_.cloud_odometry.size() > odometry; }, step_timeout_s_);
    if (!expect_image || !expect_odometry) spinFor(0.5);
  }

  std::size_t columnsPerPacket() const {
    return std::size_t(PacketFormat(parseOusterMetadata(sequence_.metadata_json)).columnsPerPacket());
  }
  // Ouster's non-legacy lidar packets: a 32-byte header and footer, each
  // column a 12-byte header (timestamp, measurement id, status) and its pixels.
  static constexpr std::size_t kPacketHeaderBytes = 32, kColumnHeaderBytes = 12;

  SaveMesh::Response saveMesh(const std::string& name) {
    SaveMesh save;
    save.request.path = sequence_dir_ + "/" + name;
    EXPECT_TRUE(ros::service::call("/mapper/save_mesh", save)) << "calling /mapper/save_mesh";
    return save.response;
  }

  ros::NodeHandle node_;
  std::string sequence_dir_;
  double step_timeout_s_ = 10.0;
  Sequence sequence_;
  ros::Time clock_;
  ros::Publisher clock_publisher_, metadata_publisher_, packet_publisher_, cloud_publisher_;
  std::vector<ros::Subscriber> subscribers_;
  Outputs outputs_;
};

// Cloud faults: float fields x, y, z at offsets 0, 4, 8 (the simulator's layout).
void setPoint(sensor_msgs::PointCloud2& cloud, std::size_t point, float value) {
  float xyz[3] = {value, value, value};
  std::memcpy(cloud.data.data() + point * cloud.point_step, xyz, sizeof xyz);
}

// The odometry's poses by the sensor's frame counter: each odometry message
// takes the frame id of the first range image of [first_image, images.end())
// with its stamp (the Adapter's stamps follow the clock, and stay increasing
// where it stalled; the first image with the stamp is the one published).
std::map<uint32_t, Eigen::Isometry3d> posesByFrame(const Outputs& outputs, std::size_t first_odometry,
                                                   std::size_t end_odometry, std::size_t first_image) {
  std::map<uint32_t, Eigen::Isometry3d> poses;
  for (std::size_t i = first_odometry; i < end_odometry; ++i) {
    const auto image = std::find_if(outputs.images.begin() + first_image, outputs.images.end(),
                                    [&](const LidarRangeImage::ConstPtr& candidate) {
                                      return candidate->header.stamp == outputs.odometry[i]->header.stamp;
                                    });
    if (image == outputs.images.end()) continue;
    Eigen::Isometry3d pose;
    tf2::fromMsg(outputs.odometry[i]->pose.pose, pose);
    poses.emplace((*image)->frame_id, pose);
  }
  return poses;
}

TEST_F(FaultInjectionTest, PipelineSurvivesFaultsAndKeepsItsMapAcrossABagLoop) {
  const std::vector<PacketScan>& scans = sequence_.scans;
  std::mt19937 random(7);
  const auto randomBytes = [&](std::size_t size) {
    Packet bytes(size);
    for (uint8_t& byte : bytes) byte = uint8_t(random());
    return bytes;
  };
  const std::size_t packet_size = scans[0].packets[0].size();

  // ---- first pass, with packet and metadata faults
  playScan(0);
  playScan(1);
  playScan(2);
  for (int i = 0; i < 4; ++i) sendPacket(randomBytes(packet_size));   // malformed
  sendPacket(Packet(scans[2].packets[5].begin(), scans[2].packets[5].begin() + packet_size / 2));  // truncated
  sendPacket(Packet(scans[2].packets[6].begin(), scans[2].packets[6].begin() + packet_size / 3));
  Packet oversized = scans[2].packets[7];
  oversized.resize(packet_size + 5, 0xab);
  sendPacket(oversized);
  sendPacket(oversized);
  sendPacket(Packet());
  {
    // Valid packet and column headers (frame id, measurement ids, status)
    // over random pixels: decoded, as garbage ranges.
    PacketScan corrupted = scans[3];
    Packet& packet = corrupted.packets[10];
    const std::size_t column_size = (packet.size() - 2 * kPacketHeaderBytes) / columnsPerPacket();
    for (std::size_t column = 0; column < columnsPerPacket(); ++column) {
      const std::size_t pixels = kPacketHeaderBytes + column * column_size + kColumnHeaderBytes;
      const Packet noise = randomBytes(column_size - kColumnHeaderBytes);
      std::copy(noise.begin(), noise.end(), packet.begin() + pixels);
    }
    sendScan(corrupted);
    awaitScan();
  }
  sendScan(scans[4], false, {20, 21, 22, 23, 24, 25, 26, 27, 28, 29});  // 10 packets lost
  awaitScan();
  // Scan 5 never arrives: a gap in the frame counter.
  playScan(6);
  sendScan(scans[6], true);  // the same revolution again: stale
  awaitScan(false);
  sendScan(scans[8]);  // 8 overtakes 7, whose packets then come late
  awaitScan();
  sendScan(scans[7], true);
  awaitScan(false);
  setClock(scans[9].times.front());  // the clock stalls: 9 and 10 are received at one ROS time
  sendScan(scans[9], true);
  awaitScan();
  spinFor(1.1);  // the Odometry says one frame problem per second
  sendScan(scans[10], true);
  awaitScan();  // stamped from the sensor clock by the Adapter, so the Odometry does not refuse it

  sendMetadata("{\"beam_altitude_angles\": [1, 2");  // not JSON
  sendMetadata("{}");                                // JSON, not metadata
  const OusterMetadata metadata = parseOusterMetadata(sequence_.metadata_json);
  sendMetadata(changedMetadata(sequence_.metadata_json, metadata.serial, "999999999999"));  // a new serial: switch
  playScan(11);
  ASSERT_EQ(metadata.profile, UdpProfile::kRng19Rfl8Sig16Nir16) << "the simulator's default profile changed";
  sendMetadata(changedMetadata(sequence_.metadata_json, "RNG19_RFL8_SIG16_NIR16", "RNG15_RFL8_NIR8"));
  sendScan(scans[12]);  // every packet has the wrong size for this profile
  spinFor(1.0);
  sendMetadata(sequence_.metadata_json);  // the original again
  for (std::size_t i = 13; i < 20; ++i) playScan(i);
  const std::size_t first_pass_odometry = outputs_.odometry.size();
  const std::size_t first_pass_images = outputs_.images.size();
  std::cout << "first pass: " << first_pass_images << " range images, " << first_pass_odometry
            << " odometry messages\n";
  // Scans 0-4, 6, 8-11 and 13-19 have odometry (10 stamped from the sensor clock).
  EXPECT_GE(first_pass_odometry, 17u);
  spinFor(1.0);  // the Mapper integrates the last scan
  const SaveMesh::Response before = saveMesh("before_loop.ply");
  ASSERT_TRUE(before.success) << before.message;

  // ---- PointCloud2 faults, into the second Adapter and Odometry
  const std::vector<sensor_msgs::PointCloud2>& clouds = sequence_.clouds;
  const std::size_t points = std::size_t(clouds[0].width) * clouds[0].height;
  sendCloud(clouds[0], true, true);
  sendCloud(clouds[1], true, true);
  sensor_msgs::PointCloud2 cloud = clouds[2];
  for (std::size_t i = 0; i < points; i += 3) setPoint(cloud, i, std::numeric_limits<float>::quiet_NaN());
  cloud.is_dense = false;
  sendCloud(cloud, true, true);  // a third of the points NaN
  cloud = clouds[3];
  for (std::size_t i = 0; i < points; ++i) setPoint(cloud, i, std::numeric_limits<float>::quiet_NaN());
  cloud.is_dense = false;
  sendCloud(cloud, true, false);  // all NaN: an image without returns, skipped by the odometry
  cloud = clouds[4];
  for (std::size_t i = 0; i < points; i += 7) setPoint(cloud, i, std::numeric_limits<float>::infinity());
  sendCloud(cloud, true, true);
  spinFor(1.1);                       // the Odometry says one warning per second
  sendCloud(clouds[4], true, false);  // the same stamp again: skipped
  sendCloud(clouds[6], true, true);
  spinFor(1.1);
  sendCloud(clouds[5], true, true);  // back in time: the odometry restarts from where it is
  cloud = clouds[7];
  cloud.width = cloud.height = 0;
  cloud.row_step = 0;
  cloud.data.clear();
  sendCloud(cloud, false, false);  // empty
  cloud = clouds[7];
  cloud.data.resize(cloud.data.size() / 2);
  sendCloud(cloud, false, false);  // truncated
  cloud = clouds[7];
  cloud.fields.erase(cloud.fields.begin());  // no x
  sendCloud(cloud, false, false);
  const std::size_t cloud_images_before = outputs_.cloud_images.size();
  const std::size_t cloud_odometry_before = outputs_.cloud_odometry.size();
  sendCloud(clouds[7], true, true);
  sendCloud(clouds[8], true, true);
  EXPECT_EQ(outputs_.cloud_images.size(), cloud_images_before + 2) << "the cloud Adapter stopped after the faults";
  EXPECT_EQ(outputs_.cloud_odometry.size(), cloud_odometry_before + 2) << "the cloud Odometry stopped after the faults";

  // ---- a bag loop: ROS time goes back to the start, the sequence again
  outputs_.loop_started = true;
  setClock(sequence_.start);
  sendMetadata(sequence_.metadata_json);  // rosbag play --loop sends the latched metadata again
  for (std::size_t i = 0; i < 8; ++i) playScan(i);
  sendCloud(clouds[9], true, true);
  sendCloud(clouds[10], true, true);
  spinFor(2.0);  // the last drop summaries (statistics_period 1 s) and diagnostics

  // The manager is alive and every nodelet published after the faults.
  std::vector<std::string> nodes;
  ASSERT_TRUE(ros::master::getNodes(nodes));
  EXPECT_NE(std::find(nodes.begin(), nodes.end(), "/rim_manager"), nodes.end()) << "the nodelet manager is gone";
  EXPECT_GE(outputs_.images.size(), first_pass_images + 8) << "range images after the loop";
  ASSERT_GE(outputs_.odometry.size(), first_pass_odometry + 8) << "odometry after the loop";
  EXPECT_EQ(outputs_.non_finite_odometry, 0u) << "odometry messages with NaN or infinite values";

  // The faults were counted and said.
  EXPECT_GE(outputs_.loggedCount("wrong size"), 4u + scans[12].packets.size());
  EXPECT_GE(outputs_.loggedCount("malformed"), 4u);
  EXPECT_GE(outputs_.loggedCount("stale"), scans[6].packets.size() + scans[7].packets.size());
  EXPECT_GE(outputs_.loggedCount("incomplete scans"), 1u);
  EXPECT_TRUE(outputs_.logged("metadata on /ouster/metadata rejected, keeping the previous one"));
  EXPECT_TRUE(outputs_.logged("dropped frames: frame 6 follows frame 4"));
  EXPECT_TRUE(outputs_.logged("before its sensor time mapped onto ROS time: ROS time stood still"));  // the stall
  EXPECT_FALSE(outputs_.logged("not after the last published one")) << "a scan refused as out of order";
  EXPECT_TRUE(outputs_.logged("PointCloud2 on /cloud/points dropped"));
  EXPECT_TRUE(outputs_.logged("same stamp as the previous scan"));
  EXPECT_TRUE(outputs_.logged("without a single valid range"));
  EXPECT_TRUE(outputs_.logged("time went back by .*: odometry restarted from the current pose"));  // cloud 5
  for (const std::string& line : outputs_.log)
    if (line.rfind("4 ", 0) == 0 || line.rfind("8 ", 0) == 0 || line.rfind("16 ", 0) == 0)
      std::cout << "  " << line.substr(0, 220) << "\n";

  // The Odometry restarted on the loop and said so, at the identity: the
  // replayed scans get the poses they had on the first pass.
  EXPECT_TRUE(outputs_.logged("ROS time jumped back.*odometry restarted at the identity"));
  EXPECT_FALSE(outputs_.loop_reset_diagnostics.empty())
      << "no /odometry diagnostics with a reset after the loop; statuses seen: "
      << std::accumulate(outputs_.diagnostic_names.begin(), outputs_.diagnostic_names.end(), std::string(),
                         [](const std::string& all, const std::string& name) { return all + "'" + name + "' "; });
  std::cout << "odometry diagnostics after the loop: " << outputs_.loop_reset_diagnostics << "\n";
  Eigen::Isometry3d first_after_loop;
  tf2::fromMsg(outputs_.odometry[first_pass_odometry]->pose.pose, first_after_loop);
  EXPECT_LT(first_after_loop.translation().norm(), 1e-9) << "the odometry did not restart at the identity";
  const auto first_pass = posesByFrame(outputs_, 0, first_pass_odometry, 0);
  const auto second_pass = posesByFrame(outputs_, first_pass_odometry, outputs_.odometry.size(), first_pass_images);
  std::size_t compared = 0;
  double worst_m = 0.0;
  for (const auto& [frame, replayed] : second_pass)
    if (const auto original = first_pass.find(frame); original != first_pass.end()) {
      ++compared;
      worst_m = std::max(worst_m, (replayed.translation() - original->second.translation()).norm());
    }
  std::cout << "loop: " << compared << " replayed scans against the first pass, worst position difference "
            << worst_m << " m (the first pass ended " << first_pass.rbegin()->second.translation().norm()
            << " m from the start)\n";
  EXPECT_GE(compared, 5u);
  EXPECT_LT(worst_m, 0.02);

  // The map kept what it had: the mesh after the loop covers the mesh before
  // it (recall) and adds no ghost surfaces (precision), at 3 voxels.
  const SaveMesh::Response after = saveMesh("after_loop.ply");
  ASSERT_TRUE(after.success) << after.message;
  const auto scansIn = [](const std::string& message) {
    std::smatch scans;
    return std::regex_search(message, scans, std::regex("from ([0-9]+) scans")) ? std::stoi(scans[1]) : -1;
  };
  EXPECT_GE(scansIn(after.message), scansIn(before.message) + 8) << "the Mapper stopped integrating: " << after.message;
  double voxel_m = 0.0;
  ASSERT_TRUE(ros::param::get("/mapper/voxel_size", voxel_m));
  evaluation::SurfaceSamplingOptions sampling;
  sampling.spacing_m = 0.75 * voxel_m;
  const evaluation::SurfaceSample before_mesh = evaluation::loadSurfaceSample(sequence_dir_ + "/before_loop.ply", sampling);
  const evaluation::SurfaceSample after_mesh = evaluation::loadSurfaceSample(sequence_dir_ + "/after_loop.ply", sampling);
  const evaluation::SurfaceMetrics kept = evaluation::compareSurfaces(after_mesh.points, before_mesh.points, 3.0 * voxel_m);
  std::cout << "mesh before the loop: " << before.message << "; after: " << after.message << "; after against before at "
            << 3.0 * voxel_m << " m: recall " << kept.recall << ", precision " << kept.precision << "\n";
  EXPECT_GE(kept.recall, 0.95) << "the mesh lost what was mapped before the loop";
  EXPECT_GE(kept.precision, 0.95) << "the loop added surfaces that were not there";
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  return range_image_mapping::test::runRostestNode(argc, argv, "fault_injection");
}
