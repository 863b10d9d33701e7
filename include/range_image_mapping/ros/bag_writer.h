// ROS 1 bags of simulated (or re-encoded) data, written with the rosbag C++ API:
// raw Ouster packets as the Ouster driver records them, and PointCloud2 clouds
// of range images. `rosbag play` replays them like recorded ones.
#pragma once

#include "range_image_mapping/ouster_packet_encoder.h"
#include "range_image_mapping/range_image.h"

#include <ros/message_traits.h>
#include <ros/serialization.h>
#include <ros/time.h>
#include <rosbag/bag.h>
#include <sensor_msgs/PointCloud2.h>

#include <boost/shared_ptr.hpp>

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping {

// ouster_ros/PacketMsg, without depending on any Ouster package: its whole
// definition is "uint8[] buf" (ouster_sensor_msgs/PacketMsg is the same).
struct OusterPacketMessage {
  std::vector<uint8_t> buf;
};

}  // namespace range_image_mapping

namespace ros {
namespace message_traits {

template <>
struct IsFixedSize<range_image_mapping::OusterPacketMessage> : FalseType {};
template <>
struct IsSimple<range_image_mapping::OusterPacketMessage> : FalseType {};
template <>
struct HasHeader<range_image_mapping::OusterPacketMessage> : FalseType {};

template <>
struct MD5Sum<range_image_mapping::OusterPacketMessage> {
  static const char* value() { return "4f7b5949e76f86d01e96b0e33ba9b5e3"; }
  static const char* value(const range_image_mapping::OusterPacketMessage&) { return value(); }
  static const uint64_t static_value1 = 0x4f7b5949e76f86d0ULL;
  static const uint64_t static_value2 = 0x1e96b0e33ba9b5e3ULL;
};

template <>
struct DataType<range_image_mapping::OusterPacketMessage> {
  static const char* value() { return "ouster_ros/PacketMsg"; }
  static const char* value(const range_image_mapping::OusterPacketMessage&) { return value(); }
};

template <>
struct Definition<range_image_mapping::OusterPacketMessage> {
  static const char* value() { return "uint8[] buf\n"; }
  static const char* value(const range_image_mapping::OusterPacketMessage&) { return value(); }
};

}  // namespace message_traits

namespace serialization {

template <>
struct Serializer<range_image_mapping::OusterPacketMessage> {
  template <typename Stream, typename T>
  inline static void allInOne(Stream& stream, T message) {
    stream.next(message.buf);
  }
  ROS_DECLARE_ALLINONE_SERIALIZER
};

}  // namespace serialization
}  // namespace ros

namespace range_image_mapping {

// A bag that cannot be written, or a message time a bag cannot hold; what()
// names the file or the time.
class BagWriteError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The three PointCloud2 layouts the simulator writes. Every layout is in the
// range image's own frame (the lidar frame for Ouster sensors: the caller
// names it, e.g. os_lidar), stamped with the scan time (image.stamp_ns).
enum class CloudLayout {
  // H x W like the Ouster driver's cloud: destaggered (point (v, u) of the
  // staggered image at column (u + pixel_shift_by_row[v]) mod W), no return =
  // (0, 0, 0) as the driver writes it; fields x y z intensity (float32),
  // t (uint32 ns after the stamp), ring (uint16, the image row: 0 = top beam).
  kOrganized,
  // Valid points only, row by row in staggered order; fields as kOrganized.
  kUnorganized,
  // Valid points only; x y z intensity (float32).
  kPlain,
  // The real drivers' conventions, so that what the tests feed the Adapter
  // is what users have:
  // ouster-ros: H x W, destaggered, in the sensor frame (points moved by
  // lidar_to_sensor; the caller names the frame, e.g. os_sensor), no return
  // = NaN, t (uint32 ns after the stamp), ring (uint16, 0 = top beam),
  // fields x y z intensity t ring at 0 4 8 12 16 20, 24 bytes a point.
  kOusterRos,
  // velodyne_pointcloud: valid points only (no return dropped), ring (uint16,
  // 0 = lowest beam), time (float32 s after the stamp); x y z at 0 4 8,
  // intensity 16, ring 20, time 24, 32 bytes a point (PCL's padded layout).
  kVelodyne,
  // Hesai's driver: valid points only, timestamp (float64 absolute s), ring
  // (uint16, 0 = top beam); x y z intensity at 0 4 8 12, timestamp 16, ring
  // 24, 32 bytes a point.
  kHesai,
};

// Fills cloud from a staggered range image (reusing its buffers). intensity is
// the image's (0 when it has none); point times come from the column
// timestamps (0 / the stamp for missing columns). Throws std::invalid_argument for a destaggered image, or a
// column time before the stamp or more than 2^32 ns after it.
void rangeImageToPointCloud2(const RangeImage& image, CloudLayout layout, const std::string& frame_id,
                             sensor_msgs::PointCloud2& cloud);

// Message times must lie within ROS time (after 0, before 2^32 s); times in
// nanoseconds are the sensor's or simulator's clock, plus a caller's offset
// where that clock starts at zero.
class BagWriter {
 public:
  // Throws BagWriteError naming the path when the bag cannot be created.
  explicit BagWriter(const std::string& path,
                     rosbag::compression::CompressionType compression = rosbag::compression::Uncompressed);
  ~BagWriter();  // closes
  BagWriter(const BagWriter&) = delete;
  BagWriter& operator=(const BagWriter&) = delete;

  // The Ouster driver's metadata String, latched (connection header latching=1),
  // so `rosbag play` hands it to late subscribers; write it at or before the
  // first packet's time.
  void writeOusterMetadata(const std::string& metadata_json, uint64_t time_ns,
                           const std::string& topic = "/ouster/metadata");
  void writeOusterPacket(const uint8_t* packet, std::size_t size, uint64_t time_ns,
                         const std::string& topic = "/ouster/lidar_packets");
  // Every packet of the scan, each at its packet timestamp (latest column) +
  // time_offset_ns. Returns the number of packets. Throws like
  // OusterPacketEncoder::encode (nothing written then) and BagWriteError.
  std::size_t writeOusterScan(const OusterPacketEncoder& encoder, const LidarScan& scan,
                              int64_t time_offset_ns = 0,
                              const std::string& topic = "/ouster/lidar_packets");
  // At the cloud's header stamp.
  void writePointCloud(const sensor_msgs::PointCloud2& cloud, const std::string& topic);

  void close();
  rosbag::Bag& bag() { return bag_; }

 private:
  ros::Time messageTime(int64_t time_ns) const;

  std::string path_;
  rosbag::Bag bag_;
  OusterPacketMessage packet_;  // reused per packet
  boost::shared_ptr<ros::M_string> packet_connection_header_;
  boost::shared_ptr<ros::M_string> metadata_connection_header_;
};

}  // namespace range_image_mapping
