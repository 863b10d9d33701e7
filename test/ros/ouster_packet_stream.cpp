// The Adapter's Ouster input, driven by this node as the driver would:
// ouster_sensor_msgs/PacketMsg packets replayed from pcaps and a latched
// metadata topic. Every image must equal the core's decoding of the same
// capture (io::readOusterScans + toRangeImage).
#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/ouster_packet.h"
#include "range_image_mapping/receive_time_stamps.h"
#include "test_data.h"

#include "spin_until.h"

#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <rosgraph_msgs/Clock.h>
#include <std_msgs/String.h>
#include <topic_tools/shape_shifter.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

using test::spinUntil;

void spinFor(double seconds) {
  spinUntil([] { return false; }, seconds);
}

std::string readText(const std::string& path) {
  std::ifstream file(path);
  std::stringstream text;
  text << file.rdbuf();
  return text.str();
}

// The lidar packets of a capture, in order (recognised by their size).
std::vector<std::vector<uint8_t>> lidarPackets(const std::string& pcap_path, const OusterMetadata& metadata) {
  const std::size_t packet_size = PacketFormat(metadata).packetSize();
  io::PcapReader reader(pcap_path);
  io::UdpDatagram datagram;
  std::vector<std::vector<uint8_t>> packets;
  while (reader.next(datagram))
    if (datagram.size == packet_size)
      packets.emplace_back(datagram.payload, datagram.payload + datagram.size);
  return packets;
}

// The core's images of a capture, by frame id.
std::map<uint32_t, RangeImage> coreImages(const std::string& pcap_path, const OusterMetadata& metadata) {
  const auto model = std::make_shared<const LidarModel>(metadata.intrinsics);
  std::map<uint32_t, RangeImage> images;
  io::readOusterScans(pcap_path, metadata,
                      [&](const LidarScan& scan) { images[scan.frame_id] = toRangeImage(scan, model); });
  return images;
}

void expectSameImage(const LidarRangeImage& message, const RangeImage& expected) {
  SCOPED_TRACE("frame " + std::to_string(message.frame_id));
  ASSERT_EQ(int(message.height), expected.rows());
  ASSERT_EQ(int(message.width), expected.columns());
  ASSERT_EQ(message.range.size(), expected.range.size());
  std::size_t differing = 0;
  for (std::size_t i = 0; i < expected.range.size(); ++i)
    differing += !((std::isnan(message.range[i]) && std::isnan(expected.range[i])) ||
                   message.range[i] == expected.range[i]);
  EXPECT_EQ(differing, 0u) << "pixels that differ from the core's decoding";
  EXPECT_EQ(message.column_timestamps, expected.column_timestamp_ns);
  EXPECT_EQ(message.altitude, expected.model->intrinsics().altitude_rad);
  EXPECT_FALSE(message.header.stamp.isZero());
}

class OusterPacketStreamTest : public testing::Test {
 protected:
  void SetUp() override {
    timeout_s_ = ros::NodeHandle("~").param("timeout", 20.0);
    topic_tools::ShapeShifter packet_type;
    packet_type.morph("4f7b5949e76f86d01e96b0e33ba9b5e3", "ouster_sensor_msgs/PacketMsg", "uint8[] buf\n", "");
    packet_publisher_ = packet_type.advertise(node_, "lidar_packets", 4096);
    metadata_publisher_ = node_.advertise<std_msgs::String>("metadata", 1, /*latch=*/true);
    subscriber_ = node_.subscribe<LidarRangeImage>(
        "range_image", 16, [this](const LidarRangeImage::ConstPtr& image) { images_.push_back(image); });
    ASSERT_TRUE(spinUntil(
        [&] {
          return packet_publisher_.getNumSubscribers() > 0 && metadata_publisher_.getNumSubscribers() > 0 &&
                 subscriber_.getNumPublishers() > 0;
        },
        timeout_s_))
        << "the Adapter did not connect";
    ros::WallDuration(0.2).sleep();
  }

  void publishPackets(const std::vector<std::vector<uint8_t>>& packets) {
    for (const std::vector<uint8_t>& packet : packets) {
      // A PacketMsg's serialization: uint32 length, then the bytes.
      std::vector<uint8_t> serialized(4 + packet.size());
      const uint32_t length = static_cast<uint32_t>(packet.size());
      std::memcpy(serialized.data(), &length, 4);
      std::memcpy(serialized.data() + 4, packet.data(), packet.size());
      topic_tools::ShapeShifter message;
      message.morph("4f7b5949e76f86d01e96b0e33ba9b5e3", "ouster_sensor_msgs/PacketMsg", "uint8[] buf\n", "");
      ros::serialization::IStream stream(serialized.data(), static_cast<uint32_t>(serialized.size()));
      message.read(stream);
      packet_publisher_.publish(message);
    }
  }

  void publishMetadata(const std::string& json) {
    std_msgs::String message;
    message.data = json;
    metadata_publisher_.publish(message);
  }

  ros::NodeHandle node_;
  ros::Publisher packet_publisher_;
  ros::Publisher metadata_publisher_;
  ros::Subscriber subscriber_;
  std::vector<LidarRangeImage::ConstPtr> images_;
  double timeout_s_ = 20.0;
};

TEST_F(OusterPacketStreamTest, EarlyPacketsIncompleteScansBadMetadataAndASensorSwitch) {
  RIM_REQUIRE_DATA(crc_pcap, "ouster-pcaps/crc_test.pcap");
  RIM_REQUIRE_DATA(crc_json, "ouster-pcaps/crc_test.json");
  RIM_REQUIRE_DATA(lb_pcap, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(lb_json, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  const OusterMetadata crc_metadata = loadOusterMetadata(crc_json);
  const OusterMetadata lb_metadata = loadOusterMetadata(lb_json);

  // crc_test: frame 254 complete, then 32 of 512 columns of frame 255. The
  // packets come before the metadata: the Adapter keeps them until it arrives.
  const std::map<uint32_t, RangeImage> crc_expected = coreImages(crc_pcap, crc_metadata);
  ASSERT_EQ(crc_expected.size(), 2u);
  publishPackets(lidarPackets(crc_pcap, crc_metadata));
  spinFor(1.0);
  EXPECT_TRUE(images_.empty()) << "an image before any metadata";
  publishMetadata(readText(crc_json));
  // 254 as soon as its last column arrives; 255 once packets stopped for flush_after_idle.
  ASSERT_TRUE(spinUntil([&] { return images_.size() >= 2; }, timeout_s_))
      << images_.size() << " of 2 crc_test images within " << timeout_s_ << " s";
  for (const auto& image : images_) {
    ASSERT_TRUE(crc_expected.count(image->frame_id)) << "unexpected frame " << image->frame_id;
    expectSameImage(*image, crc_expected.at(image->frame_id));
  }
  EXPECT_EQ(images_[0]->frame_id, 254u);
  EXPECT_EQ(images_[1]->frame_id, 255u);

  // Metadata that does not parse is rejected; then another sensor's metadata
  // replaces crc_test's, and its packets decode with the new model.
  images_.clear();
  publishMetadata("{\"not\": \"metadata\"");
  spinFor(0.5);
  publishMetadata(readText(lb_json));
  spinFor(1.5);  // the new metadata must be in before the packets
  const std::map<uint32_t, RangeImage> lb_expected = coreImages(lb_pcap, lb_metadata);
  ASSERT_EQ(lb_expected.size(), 3u);
  publishPackets(lidarPackets(lb_pcap, lb_metadata));
  ASSERT_TRUE(spinUntil([&] { return images_.size() >= 3; }, timeout_s_))
      << images_.size() << " of 3 lb_n3 images within " << timeout_s_ << " s";
  for (const auto& image : images_) {
    ASSERT_TRUE(lb_expected.count(image->frame_id)) << "unexpected frame " << image->frame_id;
    expectSameImage(*image, lb_expected.at(image->frame_id));
    EXPECT_EQ(image->sensor_model, lb_metadata.intrinsics.sensor_model);
  }
}

// Run by adapter_standing_clock.test (use_sim_time, this node owns /clock):
// ROS time stands still while three revolutions arrive, as a starved /clock
// does on a loaded machine. Receive-time stamps must still increase, by the
// sensor clock's intervals, so that the Odometry refuses none as out of order.
TEST_F(OusterPacketStreamTest, StandingClockStillGivesIncreasingStamps) {
  RIM_REQUIRE_DATA(lb_pcap, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(lb_json, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  ASSERT_TRUE(ros::Time::isSimTime()) << "run through adapter_standing_clock.test (use_sim_time)";
  ros::Publisher clock_publisher = node_.advertise<rosgraph_msgs::Clock>("/clock", 1);
  ASSERT_TRUE(spinUntil([&] { return clock_publisher.getNumSubscribers() > 0; }, timeout_s_));
  rosgraph_msgs::Clock frozen;
  frozen.clock = ros::Time(100, 0);
  for (int i = 0; i < 5; ++i) {
    clock_publisher.publish(frozen);
    spinFor(0.1);
  }
  const OusterMetadata lb_metadata = loadOusterMetadata(lb_json);
  publishMetadata(readText(lb_json));
  spinFor(1.5);
  publishPackets(lidarPackets(lb_pcap, lb_metadata));
  ASSERT_TRUE(spinUntil([&] { return images_.size() >= 3; }, timeout_s_))
      << images_.size() << " of 3 lb_n3 images within " << timeout_s_ << " s";
  const auto sensor_stamp_ns = [](const LidarRangeImage& image) {
    for (const uint64_t stamp : image.column_timestamps)
      if (stamp != 0) return static_cast<int64_t>(stamp);
    return int64_t{0};
  };
  EXPECT_EQ(images_[0]->header.stamp, frozen.clock);
  for (std::size_t i = 1; i < images_.size(); ++i) {
    SCOPED_TRACE("image " + std::to_string(i));
    EXPECT_GT(images_[i]->header.stamp, images_[i - 1]->header.stamp) << "stamps must increase";
    const int64_t sensor_interval_ns = sensor_stamp_ns(*images_[i]) - sensor_stamp_ns(*images_[i - 1]);
    EXPECT_NEAR(double(images_[i]->header.stamp.toNSec() - images_[i - 1]->header.stamp.toNSec()),
                double(sensor_interval_ns), ReceiveTimeStamps::kDriftRate * double(sensor_interval_ns))
        << "spaced by the sensor clock";
  }
  // Not silent: the packet path's diagnostics warn and count the early receipts.
  diagnostic_msgs::DiagnosticStatus packets_status;
  ros::Subscriber diagnostics = node_.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 20, [&](const diagnostic_msgs::DiagnosticArray::ConstPtr& array) {
        for (const diagnostic_msgs::DiagnosticStatus& status : array->status)
          if (status.name.find("Ouster packets") != std::string::npos) packets_status = status;
      });
  const auto early = [&] {
    for (const diagnostic_msgs::KeyValue& value : packets_status.values)
      if (value.key == "scans received early (ROS time stood still)") return std::stoul(value.value);
    return 0ul;
  };
  ASSERT_TRUE(spinUntil([&] { return early() >= images_.size() - 1; }, timeout_s_))
      << "no Ouster packets diagnostics counting " << images_.size() - 1 << " early scans; last summary: '"
      << packets_status.message << "'";
  EXPECT_EQ(packets_status.level, diagnostic_msgs::DiagnosticStatus::WARN);
  EXPECT_NE(packets_status.message.find("early (a late /clock"), std::string::npos) << packets_status.message;
  EXPECT_NE(packets_status.message.find("replay slower"), std::string::npos) << "names the fix: "
                                                                             << packets_status.message;
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "ouster_packet_stream");
  ros::NodeHandle keep_node_alive;
  return RUN_ALL_TESTS();
}
