// Bags written by BagWriter, replayed with `rosbag play` through the Adapter:
// packets (ouster_replay.launch) give back the source scans bit for bit, and
// the organized, unorganized and plain PointCloud2 clouds (pointcloud.launch,
// Ouster intrinsics) give back the source range images.
//
// The bag must exist before rosbag play starts, so simulated_bag.test runs this
// node twice: first as `simulated_bag_node --write-bag BAG METADATA` from a
// <param command=...> (roslaunch runs those while loading the file, before any
// node starts), then as the test.
#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/ouster_packet_encoder.h"
#include "range_image_mapping/ros/bag_writer.h"
#include "range_image_mapping/scan_batcher.h"

#include "spin_until.h"

#include <gtest/gtest.h>
#include <ros/ros.h>
#include <rosbag/view.h>
#include <std_msgs/String.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

constexpr int kRows = 32;
constexpr int kColumns = 512;
constexpr int kScans = 3;
constexpr uint32_t kFirstFrameId = 1795;
constexpr uint64_t kFirstScanNs = 991587364520ull;  // a sensor clock, as in the lb_n3 capture
constexpr uint64_t kScanPeriodNs = 100000000ull;
const std::vector<int> kShiftPattern = {12, 8, 4, 0};
const std::vector<double> kAzimuthPatternDeg = {4.2, 1.4, -1.4, -4.2};

const char* const kCloudTopics[] = {"/sim/points_organized", "/sim/points_unorganized", "/sim/points_plain"};
constexpr CloudLayout kCloudLayouts[] = {CloudLayout::kOrganized, CloudLayout::kUnorganized, CloudLayout::kPlain};

// Flat (firmware 2.x) metadata of a made-up OS-1-32 at 512 x 10, RNG19 profile.
std::string metadataJson() {
  std::ostringstream json;
  const auto list = [&](int count, const auto& value) {
    json << "[";
    for (int i = 0; i < count; ++i) json << (i ? ", " : "") << value(i);
    json << "]";
  };
  json << "{\n  \"lidar_mode\": \"512x10\",\n  \"prod_line\": \"OS-1-32-SIM\",\n"
       << "  \"build_rev\": \"v2.3.0\",\n  \"prod_sn\": \"122201000998\",\n"
       << "  \"initialization_id\": 7109750,\n  \"udp_port_lidar\": 7502,\n  \"udp_port_imu\": 7503,\n"
       << "  \"lidar_origin_to_beam_origin_mm\": 15.806,\n"
       << "  \"lidar_to_sensor_transform\": [-1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 36.18, 0, 0, 0, 1],\n"
       << "  \"imu_to_sensor_transform\": [1, 0, 0, 6.253, 0, 1, 0, -11.775, 0, 0, 1, 7.645, 0, 0, 0, 1],\n"
       << "  \"beam_altitude_angles\": ";
  list(kRows, [](int v) { return 16.6 - 33.2 * v / (kRows - 1); });
  json << ",\n  \"beam_azimuth_angles\": ";
  list(kRows, [](int v) { return kAzimuthPatternDeg[v % 4]; });
  json << ",\n  \"data_format\": {\"columns_per_frame\": " << kColumns
       << ", \"columns_per_packet\": 16, \"column_window\": [0, " << kColumns - 1
       << "], \"pixels_per_column\": " << kRows << ", \"udp_profile_lidar\": \"RNG19_RFL8_SIG16_NIR16\""
       << ", \"udp_profile_imu\": \"LEGACY\", \"pixel_shift_by_row\": ";
  list(kRows, [](int v) { return kShiftPattern[v % 4]; });
  json << "}\n}\n";
  return json.str();
}

// Made-up revolutions: every column valid, ranges 1.5 to 31.5 m with holes.
std::vector<LidarScan> sourceScans(const OusterMetadata& metadata) {
  std::vector<LidarScan> scans;
  for (int s = 0; s < kScans; ++s) {
    LidarScan scan(kRows, kColumns, metadata.profile);
    scan.frame_id = kFirstFrameId + s;
    for (int u = 0; u < kColumns; ++u) {
      scan.status[u] = validColumnStatus(metadata.profile);
      scan.measurement_id[u] = static_cast<uint16_t>(u);
      scan.timestamp_ns[u] = kFirstScanNs + s * kScanPeriodNs + u * kScanPeriodNs / kColumns;
      for (int v = 0; v < kRows; ++v) {
        const std::size_t i = std::size_t(v) * kColumns + u;
        const bool hole = (v + 3 * u + s) % 11 == 0;
        scan.range[i] = hole ? 0 : 1500 + (v * 7919u + u * 104729u + s * 13u) % 30000u;
        scan.reflectivity[i] = static_cast<uint8_t>((v * 31 + u) % 256);
        scan.signal[i] = static_cast<uint16_t>(v * u);
        scan.near_ir[i] = static_cast<uint16_t>(u * 3 + v);
      }
    }
    scans.push_back(scan);
  }
  return scans;
}

// The bag: metadata, packets and the three cloud layouts of each revolution.
void writeBag(const std::string& bag_path, const std::string& metadata_path) {
  const std::string json = metadataJson();
  std::ofstream(metadata_path) << json;
  const OusterMetadata metadata = parseOusterMetadata(json);
  const auto model = std::make_shared<const LidarModel>(metadata.intrinsics);
  const OusterPacketEncoder encoder(metadata);
  BagWriter bag(bag_path);
  const std::vector<LidarScan> scans = sourceScans(metadata);
  bag.writeOusterMetadata(json, scans.front().timestamp_ns.front());
  sensor_msgs::PointCloud2 cloud;
  for (const LidarScan& scan : scans) {
    bag.writeOusterScan(encoder, scan);
    const RangeImage image = toRangeImage(scan, model);
    for (int layout = 0; layout < 3; ++layout) {
      rangeImageToPointCloud2(image, kCloudLayouts[layout], "os_lidar", cloud);
      bag.writePointCloud(cloud, kCloudTopics[layout]);
    }
  }
  bag.close();
}

// ------------------------------------------------------------ the test

using test::spinUntil;

class SimulatedBagTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    ros::NodeHandle private_node("~");
    bag_file_ = private_node.param<std::string>("bag_file", "");
    metadata_ = parseOusterMetadata(metadataJson());
    model_ = std::make_shared<const LidarModel>(metadata_.intrinsics);
    scans_ = sourceScans(metadata_);
    for (const LidarScan& scan : scans_) images_.push_back(toRangeImage(scan, model_));
  }

  static std::string bag_file_;
  static OusterMetadata metadata_;
  static LidarModelConstPtr model_;
  static std::vector<LidarScan> scans_;
  static std::vector<RangeImage> images_;
};
std::string SimulatedBagTest::bag_file_;
OusterMetadata SimulatedBagTest::metadata_;
LidarModelConstPtr SimulatedBagTest::model_;
std::vector<LidarScan> SimulatedBagTest::scans_;
std::vector<RangeImage> SimulatedBagTest::images_;

TEST_F(SimulatedBagTest, BagHoldsWhatTheOusterDriverRecords) {
  ASSERT_TRUE(std::filesystem::exists(bag_file_)) << bag_file_;
  rosbag::Bag bag(bag_file_, rosbag::bagmode::Read);
  std::map<std::string, std::size_t> counts;
  std::vector<std::vector<uint8_t>> packets;
  std::vector<uint64_t> packet_times;
  for (const rosbag::MessageInstance& message : rosbag::View(bag)) {
    ++counts[message.getTopic()];
    if (message.getTopic() == "/ouster/lidar_packets") {
      EXPECT_EQ(message.getDataType(), "ouster_ros/PacketMsg");
      EXPECT_EQ(message.getMD5Sum(), "4f7b5949e76f86d01e96b0e33ba9b5e3");
      EXPECT_EQ(message.getMessageDefinition(), "uint8[] buf\n");
      const auto packet = message.instantiate<OusterPacketMessage>();
      ASSERT_TRUE(packet);
      packets.push_back(packet->buf);
      packet_times.push_back(message.getTime().toNSec());
    } else if (message.getTopic() == "/ouster/metadata") {
      const auto header = message.getConnectionHeader();
      ASSERT_TRUE(header);
      EXPECT_EQ(header->at("latching"), "1");
      const auto text = message.instantiate<std_msgs::String>();
      ASSERT_TRUE(text);
      EXPECT_EQ(text->data, metadataJson());
      EXPECT_EQ(message.getTime().toNSec(), scans_.front().timestamp_ns.front());
    } else {
      const auto cloud = message.instantiate<sensor_msgs::PointCloud2>();
      ASSERT_TRUE(cloud);
      const std::size_t scan = counts[message.getTopic()] - 1;
      ASSERT_LT(scan, images_.size());
      EXPECT_EQ(message.getTime().toNSec(), images_[scan].stamp_ns);  // the scan time
      EXPECT_EQ(cloud->header.stamp.toNSec(), images_[scan].stamp_ns);
      EXPECT_EQ(cloud->header.frame_id, "os_lidar");
      if (message.getTopic() == kCloudTopics[0]) {
        EXPECT_EQ(cloud->height, uint32_t(kRows));
        EXPECT_EQ(cloud->width, uint32_t(kColumns));
      } else {
        EXPECT_EQ(cloud->height, 1u);
        EXPECT_EQ(cloud->width, images_[scan].validCount());
      }
    }
  }
  const std::size_t packets_per_scan = kColumns / 16;
  EXPECT_EQ(counts["/ouster/lidar_packets"], kScans * packets_per_scan);
  EXPECT_EQ(counts["/ouster/metadata"], 1u);
  for (const char* topic : kCloudTopics) EXPECT_EQ(counts[topic], std::size_t(kScans)) << topic;

  // Each packet at the time of its last column; decoded, the source scans.
  ASSERT_EQ(packets.size(), kScans * packets_per_scan);
  for (std::size_t p = 0; p < packets.size(); ++p)
    EXPECT_EQ(packet_times[p], scans_[p / packets_per_scan].timestamp_ns[(p % packets_per_scan) * 16 + 15]);
  std::vector<LidarScan> decoded;
  ScanBatcher batcher(metadata_, [&](const LidarScan& scan) { decoded.push_back(scan); });
  for (const auto& packet : packets) batcher.addPacket(packet.data(), packet.size());
  ASSERT_EQ(decoded.size(), scans_.size());
  for (std::size_t s = 0; s < scans_.size(); ++s) {
    EXPECT_EQ(decoded[s].frame_id, scans_[s].frame_id);
    EXPECT_EQ(decoded[s].range, scans_[s].range);
    EXPECT_EQ(decoded[s].signal, scans_[s].signal);
    EXPECT_EQ(decoded[s].timestamp_ns, scans_[s].timestamp_ns);
  }
}

// Collects the range images of one topic.
struct ImageCollector {
  std::vector<LidarRangeImage::ConstPtr> images;
  ros::Subscriber subscriber;
  ImageCollector(ros::NodeHandle& node, const std::string& topic) {
    subscriber = node.subscribe<LidarRangeImage>(
        topic, 8, [this](const LidarRangeImage::ConstPtr& message) { images.push_back(message); });
  }
};

// Compares an Adapter image with the source: ranges within tolerance_m (0: bit
// for bit), column times within time_tolerance_ns (< 0: not compared).
void expectSameImage(const LidarRangeImage& actual, const RangeImage& expected, double tolerance_m,
                     bool compare_intensity, int64_t time_tolerance_ns, const std::string& what) {
  ASSERT_EQ(actual.height, uint32_t(kRows)) << what;
  ASSERT_EQ(actual.width, uint32_t(kColumns)) << what;
  ASSERT_EQ(actual.column_order, LidarRangeImage::STAGGERED) << what;
  ASSERT_EQ(actual.range.size(), expected.range.size()) << what;
  std::size_t differing_validity = 0, beyond_tolerance = 0, differing_intensity = 0;
  double worst_m = 0.0;
  for (std::size_t i = 0; i < expected.range.size(); ++i) {
    const bool valid = isValidRange(expected.range[i]);
    if (valid != isValidRange(actual.range[i])) {
      ++differing_validity;
      continue;
    }
    if (!valid) continue;
    const double difference = std::abs(double(actual.range[i]) - double(expected.range[i]));
    worst_m = std::max(worst_m, difference);
    beyond_tolerance += tolerance_m == 0.0 ? actual.range[i] != expected.range[i] : difference > tolerance_m;
    if (compare_intensity && (actual.intensity.size() != expected.intensity.size() ||
                              actual.intensity[i] != expected.intensity[i]))
      ++differing_intensity;
  }
  EXPECT_EQ(differing_validity, 0u) << what;
  EXPECT_EQ(beyond_tolerance, 0u) << what << ": worst " << worst_m << " m";
  EXPECT_EQ(differing_intensity, 0u) << what;
  int64_t worst_ns = 0;
  if (time_tolerance_ns >= 0) {
    ASSERT_EQ(actual.column_timestamps.size(), expected.column_timestamp_ns.size()) << what;
    for (std::size_t u = 0; u < expected.column_timestamp_ns.size(); ++u)
      worst_ns = std::max(worst_ns, std::abs(int64_t(actual.column_timestamps[u]) -
                                             int64_t(expected.column_timestamp_ns[u])));
    EXPECT_LE(worst_ns, time_tolerance_ns) << what;
  }
  std::cout << what << ": worst range difference " << worst_m << " m, column time " << worst_ns << " ns\n";
}

TEST_F(SimulatedBagTest, ReplayedThroughTheAdapterGivesTheSource) {
  ros::NodeHandle node;
  const double timeout_s = ros::NodeHandle("~").param("timeout", 30.0);
  ImageCollector packets(node, "/range_image");
  ImageCollector organized(node, "/organized/range_image");
  ImageCollector unorganized(node, "/unorganized/range_image");
  ImageCollector plain(node, "/plain/range_image");
  const auto all = {&packets, &organized, &unorganized, &plain};
  ASSERT_TRUE(spinUntil(
      [&] {
        for (const ImageCollector* collector : all)
          if (collector->images.size() < std::size_t(kScans)) return false;
        return true;
      },
      timeout_s))
      << "range images within " << timeout_s << " s: packets " << packets.images.size()
      << ", organized " << organized.images.size() << ", unorganized " << unorganized.images.size()
      << ", plain " << plain.images.size() << " of " << kScans << " each";

  for (int s = 0; s < kScans; ++s) {
    const std::string scan = " scan " + std::to_string(s);
    // Packets: the sensor's millimetres, bit for bit.
    EXPECT_EQ(packets.images[s]->frame_id, kFirstFrameId + s);
    expectSameImage(*packets.images[s], images_[s], 0.0, true, 0, "packets" + scan);
    // Clouds: float32 coordinates, so ranges within a few micrometres. Every
    // column has points, so each column time comes back from t (which the
    // Adapter holds as float seconds: a few nanoseconds off).
    expectSameImage(*organized.images[s], images_[s], 1e-4, true, 100, "organized" + scan);
    expectSameImage(*unorganized.images[s], images_[s], 1e-4, true, 100, "unorganized" + scan);
    expectSameImage(*plain.images[s], images_[s], 1e-4, true, -1, "plain" + scan);
    EXPECT_EQ(organized.images[s]->header.stamp.toNSec(), images_[s].stamp_ns);
  }
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  // Generator mode, run by roslaunch before any node starts: no ROS master needed.
  if (argc >= 2 && std::string(argv[1]) == "--write-bag") {
    if (argc != 4) {
      std::cerr << "usage: simulated_bag_node --write-bag BAG_FILE METADATA_FILE\n";
      return 2;
    }
    try {
      range_image_mapping::writeBag(argv[2], argv[3]);
    } catch (const std::exception& error) {
      std::cerr << "simulated_bag_node: " << error.what() << "\n";
      return 1;
    }
    std::cout << argv[2];  // becomes the value of the <param command=...>
    return 0;
  }
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "simulated_bag");
  ros::NodeHandle keep_node_alive;
  const int result = RUN_ALL_TESTS();
  // The generated files served their purpose.
  ros::NodeHandle private_node("~");
  for (const char* name : {"bag_file", "metadata_file"}) {
    std::string path;
    if (private_node.getParam(name, path) && !path.empty()) std::filesystem::remove(path);
  }
  return result;
}
