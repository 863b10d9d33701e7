#include "range_image_mapping/io/rosbag_reader.h"

#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <ros/serialization.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_msgs/String.h>

#include <algorithm>
#include <cstring>
#include <map>

namespace range_image_mapping::io {
namespace {

// Both Ouster drivers' PacketMsg are exactly "uint8[] buf"; the md5 of that
// definition guards against a future message of the same name with more fields.
constexpr const char* kOusterPacketMd5 = "4f7b5949e76f86d01e96b0e33ba9b5e3";

bool isOusterPacketType(const std::string& datatype) {
  return datatype == "ouster_ros/PacketMsg" || datatype == "ouster_sensor_msgs/PacketMsg";
}

std::string topicList(const std::vector<BagTopic>& topics) {
  std::string list;
  for (const BagTopic& topic : topics)
    list += (list.empty() ? "" : ", ") + topic.name + " (" + topic.datatype + ", " +
            std::to_string(topic.messages) + " messages)";
  return list.empty() ? "none" : list;
}

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

}  // namespace

struct BagReader::State {
  std::string path;
  rosbag::Bag bag;
  std::vector<BagTopic> topics;

  const BagTopic& topic(const std::string& name, const std::string& what) const {
    for (const BagTopic& topic : topics)
      if (topic.name == name) return topic;
    throw BagError("bag " + path + ": no topic " + name + " (" + what + "); it holds " + topicList(topics));
  }
};

BagReader::BagReader(const std::string& path) : state_(std::make_unique<State>()) {
  state_->path = path;
  try {
    state_->bag.open(path, rosbag::bagmode::Read);
    rosbag::View everything(state_->bag);
    std::map<std::string, BagTopic> by_name;
    for (const rosbag::ConnectionInfo* connection : everything.getConnections()) {
      BagTopic& topic = by_name[connection->topic];
      topic.name = connection->topic;
      topic.datatype = connection->datatype;
      topic.md5sum = connection->md5sum;
    }
    for (auto& [name, topic] : by_name) {
      topic.messages = rosbag::View(state_->bag, rosbag::TopicQuery(name)).size();
      state_->topics.push_back(topic);
    }
  } catch (const rosbag::BagException& error) {
    throw BagError("bag " + path + ": " + error.what() +
                   " (a bag cut off while recording has no index: rosbag reindex rebuilds it)");
  }
}

BagReader::~BagReader() = default;

const std::string& BagReader::path() const { return state_->path; }
const std::vector<BagTopic>& BagReader::topics() const { return state_->topics; }

std::vector<BagTopic> BagReader::topicsOfType(const std::string& datatype) const {
  std::vector<BagTopic> found;
  for (const BagTopic& topic : state_->topics)
    if (topic.datatype == datatype) found.push_back(topic);
  return found;
}

std::vector<BagTopic> BagReader::ousterPacketTopics() const {
  std::vector<BagTopic> found;
  for (const BagTopic& topic : state_->topics)
    if (isOusterPacketType(topic.datatype)) found.push_back(topic);
  return found;
}

std::size_t BagReader::forEachPointCloud(const std::string& topic_name,
                                         const std::function<bool(const BagPointCloud&)>& on_cloud) const {
  const BagTopic& topic = state_->topic(topic_name, kPointCloudType);
  if (topic.datatype != kPointCloudType)
    throw BagError("bag " + state_->path + ": topic " + topic_name + " holds " + topic.datatype + ", not " +
                   kPointCloudType);
  std::size_t given = 0;
  BagPointCloud cloud;
  try {
    for (const rosbag::MessageInstance& message : rosbag::View(state_->bag, rosbag::TopicQuery(topic_name))) {
      const sensor_msgs::PointCloud2::ConstPtr msg = message.instantiate<sensor_msgs::PointCloud2>();
      if (!msg)
        throw BagError("bag " + state_->path + ": a message on " + topic_name + " is not a " + kPointCloudType +
                       " (md5 " + message.getMD5Sum() + ")");
      cloud.layout.fields.resize(msg->fields.size());
      for (std::size_t i = 0; i < msg->fields.size(); ++i)
        cloud.layout.fields[i] = {msg->fields[i].name, msg->fields[i].offset, msg->fields[i].datatype,
                                  msg->fields[i].count};
      cloud.layout.height = msg->height;
      cloud.layout.width = msg->width;
      cloud.layout.point_step = msg->point_step;
      cloud.layout.row_step = msg->row_step;
      cloud.layout.is_bigendian = msg->is_bigendian;
      cloud.data = msg->data.data();
      cloud.size = msg->data.size();
      cloud.header_stamp_ns = msg->header.stamp.toNSec();
      cloud.header_seq = msg->header.seq;
      cloud.frame_id = msg->header.frame_id;
      cloud.bag_time_ns = message.getTime().toNSec();
      ++given;
      if (!on_cloud(cloud)) break;
    }
  } catch (const rosbag::BagException& error) {
    throw BagError("bag " + state_->path + ", topic " + topic_name + " after " + std::to_string(given) +
                   " messages: " + error.what());
  } catch (const ros::Exception& error) {
    throw BagError("bag " + state_->path + ", topic " + topic_name + " after " + std::to_string(given) +
                   " messages: " + error.what());
  }
  return given;
}

BagPacket ousterPacketPayload(const uint8_t* serialized, std::size_t size, const std::string& datatype,
                              const std::string& md5sum) {
  if (!isOusterPacketType(datatype) || md5sum != kOusterPacketMd5)
    throw BagError("lidar packets: message type '" + datatype + "' (md5 " + md5sum +
                   ") is not an Ouster packet; expected ouster_ros/PacketMsg or ouster_sensor_msgs/PacketMsg "
                   "(uint8[] buf, md5 " + kOusterPacketMd5 + ")");
  if (size < sizeof(uint32_t))
    throw BagError("lidar packets: " + datatype + " of " + std::to_string(size) + " bytes has no length prefix");
  uint32_t length;
  std::memcpy(&length, serialized, sizeof(length));  // ROS serializes little-endian
  if (length != size - sizeof(uint32_t))
    throw BagError("lidar packets: " + datatype + " says buf has " + std::to_string(length) +
                   " bytes, the message carries " + std::to_string(size - sizeof(uint32_t)));
  BagPacket packet;
  packet.data = serialized + sizeof(uint32_t);
  packet.size = length;
  return packet;
}

std::size_t BagReader::forEachOusterPacket(const std::string& topic_name,
                                           const std::function<bool(const BagPacket&)>& on_packet) const {
  const BagTopic& topic = state_->topic(topic_name, "Ouster packets");
  if (!isOusterPacketType(topic.datatype))
    throw BagError("bag " + state_->path + ": topic " + topic_name + " holds " + topic.datatype +
                   ", not Ouster packets (ouster_ros/PacketMsg or ouster_sensor_msgs/PacketMsg)");
  std::vector<uint8_t> buffer;
  std::size_t given = 0;
  try {
    for (const rosbag::MessageInstance& message : rosbag::View(state_->bag, rosbag::TopicQuery(topic_name))) {
      buffer.resize(message.size());
      ros::serialization::OStream stream(buffer.data(), static_cast<uint32_t>(buffer.size()));
      message.write(stream);
      BagPacket packet = ousterPacketPayload(buffer.data(), buffer.size(), message.getDataType(),
                                             message.getMD5Sum());
      packet.bag_time_ns = message.getTime().toNSec();
      ++given;
      if (!on_packet(packet)) break;
    }
  } catch (const rosbag::BagException& error) {
    throw BagError("bag " + state_->path + ", topic " + topic_name + " after " + std::to_string(given) +
                   " messages: " + error.what());
  }
  return given;
}

std::string BagReader::firstString(const std::string& topic_name) const {
  const BagTopic& topic = state_->topic(topic_name, "std_msgs/String");
  try {
    for (const rosbag::MessageInstance& message : rosbag::View(state_->bag, rosbag::TopicQuery(topic_name))) {
      const std_msgs::String::ConstPtr text = message.instantiate<std_msgs::String>();
      if (!text)
        throw BagError("bag " + state_->path + ": topic " + topic_name + " holds " + topic.datatype +
                       ", not std_msgs/String");
      return text->data;
    }
  } catch (const rosbag::BagException& error) {
    throw BagError("bag " + state_->path + ", topic " + topic_name + ": " + error.what());
  }
  throw BagError("bag " + state_->path + ": topic " + topic_name + " has no message");
}

std::string choosePointCloudTopic(const BagReader& bag, const std::string& requested) {
  const std::vector<BagTopic> clouds = bag.topicsOfType(BagReader::kPointCloudType);
  if (!requested.empty()) {
    for (const BagTopic& topic : clouds)
      if (topic.name == requested) return requested;
    throw BagError("bag " + bag.path() + ": --topic " + requested + " is not a PointCloud2 topic of it; " +
                   "PointCloud2 topics: " + topicList(clouds) + "; all topics: " + topicList(bag.topics()));
  }
  if (clouds.size() == 1) return clouds.front().name;
  if (clouds.empty())
    throw BagError("bag " + bag.path() + " has no PointCloud2 topic; it holds " + topicList(bag.topics()));
  throw BagError("bag " + bag.path() + " has " + std::to_string(clouds.size()) +
                 " PointCloud2 topics: choose one with --topic: " + topicList(clouds));
}

OusterBagTopics chooseOusterTopics(const BagReader& bag, const std::string& requested) {
  const std::vector<BagTopic> packets = bag.ousterPacketTopics();
  OusterBagTopics chosen;
  if (!requested.empty()) {
    for (const BagTopic& topic : packets)
      if (topic.name == requested) chosen.packets = requested;
    if (chosen.packets.empty())
      throw BagError("bag " + bag.path() + ": --topic " + requested + " is not an Ouster packet topic of it; " +
                     "packet topics: " + topicList(packets));
  } else {
    std::vector<BagTopic> lidar;
    for (const BagTopic& topic : packets)
      if (!contains(topic.name, "imu")) lidar.push_back(topic);
    if (lidar.size() > 1) {
      std::vector<BagTopic> named;
      for (const BagTopic& topic : lidar)
        if (contains(topic.name, "lidar_packets")) named.push_back(topic);
      if (named.size() == 1) lidar = named;
    }
    if (lidar.size() != 1)
      throw BagError("bag " + bag.path() + ": " +
                     (lidar.empty() ? std::string("no Ouster lidar packet topic; it holds ") + topicList(bag.topics())
                                    : "several Ouster lidar packet topics: choose one with --topic: " +
                                          topicList(lidar)));
    chosen.packets = lidar.front().name;
  }
  // The metadata topic next to the packets (same namespace) when there are several.
  std::vector<BagTopic> metadata;
  for (const BagTopic& topic : bag.topicsOfType("std_msgs/String"))
    if (topic.name.size() >= 8 && topic.name.compare(topic.name.size() - 8, 8, "metadata") == 0)
      metadata.push_back(topic);
  const std::string packet_namespace = chosen.packets.substr(0, chosen.packets.rfind('/') + 1);
  for (const BagTopic& topic : metadata)
    if (topic.name.rfind(packet_namespace, 0) == 0) chosen.metadata = topic.name;
  if (chosen.metadata.empty() && metadata.size() == 1) chosen.metadata = metadata.front().name;
  return chosen;
}

}  // namespace range_image_mapping::io
