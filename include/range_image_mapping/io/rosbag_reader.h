// ROS 1 bags read with the rosbag storage library (no ROS master, no node):
// the topics a bag holds, its sensor_msgs/PointCloud2 messages as point-cloud
// layouts, and Ouster packet messages (ouster_ros/PacketMsg or
// ouster_sensor_msgs/PacketMsg) with the driver's metadata string. No ROS type
// appears in this header.
#pragma once

#include "range_image_mapping/point_cloud_layout.h"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping::io {

// A bag that cannot be opened or read, a topic it does not hold or of another
// type, or a message that is not what its type says; what() names the bag,
// the topic and the problem.
class BagError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct BagTopic {
  std::string name;
  std::string datatype;  // e.g. sensor_msgs/PointCloud2
  std::string md5sum;
  std::size_t messages = 0;
};

// One PointCloud2 message: its layout, its data (valid during the callback)
// and its header.
struct BagPointCloud {
  PointCloudLayout layout;
  const uint8_t* data = nullptr;
  std::size_t size = 0;
  uint64_t header_stamp_ns = 0;
  uint32_t header_seq = 0;
  std::string frame_id;
  uint64_t bag_time_ns = 0;  // when it was recorded
};

// One Ouster packet message: the UDP payload (valid during the callback).
struct BagPacket {
  const uint8_t* data = nullptr;
  std::size_t size = 0;
  uint64_t bag_time_ns = 0;
};

class BagReader {
 public:
  static constexpr const char* kPointCloudType = "sensor_msgs/PointCloud2";

  // Throws BagError naming the path and the storage library's message.
  explicit BagReader(const std::string& path);
  ~BagReader();
  BagReader(const BagReader&) = delete;
  BagReader& operator=(const BagReader&) = delete;

  const std::string& path() const;
  // Every topic with its type and message count, sorted by name.
  const std::vector<BagTopic>& topics() const;
  // The topics of one message type.
  std::vector<BagTopic> topicsOfType(const std::string& datatype) const;
  // Topics carrying Ouster packets (either driver generation's PacketMsg).
  std::vector<BagTopic> ousterPacketTopics() const;

  // Calls on_cloud with each PointCloud2 of topic in recorded order until it
  // returns false; returns how many were given. Throws BagError when topic is
  // not a PointCloud2 topic of this bag.
  std::size_t forEachPointCloud(const std::string& topic,
                                const std::function<bool(const BagPointCloud&)>& on_cloud) const;
  // The same for an Ouster packet topic.
  std::size_t forEachOusterPacket(const std::string& topic,
                                  const std::function<bool(const BagPacket&)>& on_packet) const;
  // The first std_msgs/String message of topic (the Ouster drivers' metadata).
  std::string firstString(const std::string& topic) const;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

// The payload of a serialized Ouster PacketMsg ("uint8[] buf": a little-endian
// uint32 length and the bytes). datatype and md5sum are the message's; throws
// BagError naming the type for any other message, and for a length that
// disagrees with the serialized size.
BagPacket ousterPacketPayload(const uint8_t* serialized, std::size_t size, const std::string& datatype,
                              const std::string& md5sum);

// Topic choices, by what the bag holds. requested "" chooses automatically.
// The PointCloud2 topic: requested (which must be one), else the only one;
// throws BagError listing the candidates when there are several or none.
std::string choosePointCloudTopic(const BagReader& bag, const std::string& requested);
// The Ouster lidar packet topic (requested, else the only packet topic not
// named imu, else the one named lidar_packets) and the metadata topic (a
// std_msgs/String topic whose name ends in "metadata"; "" when there is none).
struct OusterBagTopics {
  std::string packets;
  std::string metadata;
};
OusterBagTopics chooseOusterTopics(const BagReader& bag, const std::string& requested);

}  // namespace range_image_mapping::io
