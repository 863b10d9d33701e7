#include "range_image_mapping/ros/bag_writer.h"

#include <rosbag/exceptions.h>
#include <sensor_msgs/PointField.h>
#include <std_msgs/String.h>

#include <boost/make_shared.hpp>

#include <cstring>
#include <limits>

namespace range_image_mapping {
namespace {

using sensor_msgs::PointField;

// Point layouts: x y z intensity, then (not plain) t and ring, padded to 24 bytes.
constexpr uint32_t kTimeOffset = 16;
constexpr uint32_t kRingOffset = 20;
constexpr uint32_t kTimedPointStep = 24;
constexpr uint32_t kPlainPointStep = 16;

void addField(sensor_msgs::PointCloud2& cloud, const char* name, uint32_t offset, uint8_t datatype) {
  PointField field;
  field.name = name;
  field.offset = offset;
  field.datatype = datatype;
  field.count = 1;
  cloud.fields.push_back(field);
}

void setFields(sensor_msgs::PointCloud2& cloud, bool with_time_and_ring) {
  cloud.fields.clear();
  const auto add = [&](const char* name, uint32_t offset, uint8_t datatype) { addField(cloud, name, offset, datatype); };
  add("x", 0, PointField::FLOAT32);
  add("y", 4, PointField::FLOAT32);
  add("z", 8, PointField::FLOAT32);
  add("intensity", 12, PointField::FLOAT32);
  if (with_time_and_ring) {
    add("t", kTimeOffset, PointField::UINT32);
    add("ring", kRingOffset, PointField::UINT16);
  }
  cloud.point_step = with_time_and_ring ? kTimedPointStep : kPlainPointStep;
  cloud.is_bigendian = false;
}

// Column times relative to the stamp, as the t field carries them.
std::vector<uint32_t> columnTimeOffsets(const RangeImage& image) {
  std::vector<uint32_t> offsets(image.columns(), 0);
  for (int u = 0; u < image.columns(); ++u) {
    const uint64_t time = image.column_timestamp_ns.empty() ? 0 : image.column_timestamp_ns[u];
    if (time == 0) continue;  // column not measured
    if (time < image.stamp_ns || time - image.stamp_ns > std::numeric_limits<uint32_t>::max())
      throw std::invalid_argument("rangeImageToPointCloud2: column " + std::to_string(u) + " time " +
                                  std::to_string(time) + " ns does not fit the uint32 offset t "
                                  "after the stamp " + std::to_string(image.stamp_ns) + " ns");
    offsets[u] = static_cast<uint32_t>(time - image.stamp_ns);
  }
  return offsets;
}

void writePoint(uint8_t* point, const Eigen::Vector3f& xyz, float intensity) {
  std::memcpy(point, xyz.data(), 3 * sizeof(float));
  std::memcpy(point + 12, &intensity, sizeof(float));
}

void writeTimeAndRing(uint8_t* point, uint32_t time_offset_ns, uint16_t ring) {
  std::memcpy(point + kTimeOffset, &time_offset_ns, sizeof(uint32_t));
  std::memcpy(point + kRingOffset, &ring, sizeof(uint16_t));
}

// The real drivers' layouts (CloudLayout kOusterRos, kVelodyne, kHesai).
void driverCloud(const RangeImage& image, CloudLayout layout, const std::vector<uint32_t>& time_offsets,
                 sensor_msgs::PointCloud2& cloud) {
  const LidarModel& model = *image.model;
  const int rows = image.rows(), columns = image.columns();
  cloud.fields.clear();
  const auto add = [&](const char* name, uint32_t offset, uint8_t datatype) { addField(cloud, name, offset, datatype); };
  add("x", 0, PointField::FLOAT32);
  add("y", 4, PointField::FLOAT32);
  add("z", 8, PointField::FLOAT32);
  uint32_t intensity_offset = 12, ring_offset = 20, time_offset = 16;
  if (layout == CloudLayout::kOusterRos) {
    add("intensity", 12, PointField::FLOAT32);
    add("t", 16, PointField::UINT32);
    add("ring", 20, PointField::UINT16);
    cloud.point_step = 24;
  } else if (layout == CloudLayout::kVelodyne) {
    intensity_offset = 16, ring_offset = 20, time_offset = 24;
    add("intensity", 16, PointField::FLOAT32);
    add("ring", 20, PointField::UINT16);
    add("time", 24, PointField::FLOAT32);
    cloud.point_step = 32;
  } else {
    ring_offset = 24;
    add("intensity", 12, PointField::FLOAT32);
    add("timestamp", 16, PointField::FLOAT64);
    add("ring", 24, PointField::UINT16);
    cloud.point_step = 32;
  }
  cloud.is_bigendian = false;
  const bool organized = layout == CloudLayout::kOusterRos;
  const Eigen::Isometry3f lidar_to_sensor = model.intrinsics().lidar_to_sensor.cast<float>();
  const auto write = [&](uint8_t* point, int v, int u, bool valid) {
    const std::size_t i = image.index(v, u);
    Eigen::Vector3f xyz = Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN());
    if (valid) xyz = model.unproject(u, v, image.range[i]);
    if (organized && valid) xyz = lidar_to_sensor * xyz;
    std::memcpy(point, xyz.data(), 3 * sizeof(float));
    const float intensity = image.intensity.empty() ? 0.0f : image.intensity[i];
    std::memcpy(point + intensity_offset, &intensity, sizeof(float));
    // Velodyne numbers its rings from the lowest beam up.
    const uint16_t ring = static_cast<uint16_t>(layout == CloudLayout::kVelodyne ? rows - 1 - v : v);
    std::memcpy(point + ring_offset, &ring, sizeof(ring));
    if (layout == CloudLayout::kOusterRos) {
      std::memcpy(point + time_offset, &time_offsets[u], sizeof(uint32_t));
    } else if (layout == CloudLayout::kVelodyne) {
      const float seconds = static_cast<float>(time_offsets[u] * 1e-9);
      std::memcpy(point + time_offset, &seconds, sizeof(float));
    } else {
      const double absolute_s = double(image.stamp_ns + time_offsets[u]) * 1e-9;
      std::memcpy(point + time_offset, &absolute_s, sizeof(double));
    }
  };
  if (organized) {
    cloud.height = static_cast<uint32_t>(rows);
    cloud.width = static_cast<uint32_t>(columns);
    cloud.row_step = cloud.width * cloud.point_step;
    cloud.data.assign(std::size_t(cloud.row_step) * cloud.height, 0);
    cloud.is_dense = false;  // no return is NaN
    const std::vector<int>& shifts = model.intrinsics().pixel_shift_by_row;
    for (int v = 0; v < rows; ++v) {
      const int shift = ((shifts[v] % columns) + columns) % columns;
      for (int u = 0; u < columns; ++u)
        write(cloud.data.data() + std::size_t(v) * cloud.row_step + std::size_t((u + shift) % columns) * cloud.point_step,
              v, u, isValidRange(image.range[image.index(v, u)]));
    }
    return;
  }
  cloud.height = 1;
  cloud.width = static_cast<uint32_t>(image.validCount());
  cloud.row_step = cloud.width * cloud.point_step;
  cloud.data.assign(std::size_t(cloud.row_step), 0);
  cloud.is_dense = true;
  uint8_t* point = cloud.data.data();
  // Column by column, as the drivers fill their clouds packet by packet.
  for (int u = 0; u < columns; ++u)
    for (int v = 0; v < rows; ++v) {
      if (!isValidRange(image.range[image.index(v, u)])) continue;
      write(point, v, u, true);
      point += cloud.point_step;
    }
}

}  // namespace

void rangeImageToPointCloud2(const RangeImage& image, CloudLayout layout, const std::string& frame_id,
                             sensor_msgs::PointCloud2& cloud) {
  if (!image.model) throw std::invalid_argument("rangeImageToPointCloud2: the image has no sensor model");
  if (image.column_order != ColumnOrder::kStaggered)
    throw std::invalid_argument("rangeImageToPointCloud2: the image must be staggered (geometry needs it)");
  const LidarModel& model = *image.model;
  const int rows = image.rows(), columns = image.columns();
  if (image.range.size() != std::size_t(rows) * columns ||
      (!image.intensity.empty() && image.intensity.size() != image.range.size()) ||
      (!image.column_timestamp_ns.empty() && image.column_timestamp_ns.size() != std::size_t(columns)))
    throw std::invalid_argument("rangeImageToPointCloud2: image arrays do not match its size");
  const bool timed = layout != CloudLayout::kPlain;
  const std::vector<uint32_t> time_offsets = timed ? columnTimeOffsets(image) : std::vector<uint32_t>();

  cloud.header.frame_id = frame_id;
  cloud.header.stamp.fromNSec(image.stamp_ns);
  if (layout == CloudLayout::kOusterRos || layout == CloudLayout::kVelodyne || layout == CloudLayout::kHesai) {
    driverCloud(image, layout, columnTimeOffsets(image), cloud);
    return;
  }
  setFields(cloud, timed);
  const auto intensityAt = [&](std::size_t i) { return image.intensity.empty() ? 0.0f : image.intensity[i]; };

  if (layout == CloudLayout::kOrganized) {
    cloud.height = static_cast<uint32_t>(rows);
    cloud.width = static_cast<uint32_t>(columns);
    cloud.row_step = cloud.width * cloud.point_step;
    cloud.data.assign(std::size_t(cloud.row_step) * cloud.height, 0);
    cloud.is_dense = true;  // no return is (0, 0, 0), not NaN
    const std::vector<int>& shifts = model.intrinsics().pixel_shift_by_row;
    for (int v = 0; v < rows; ++v) {
      const int shift = ((shifts[v] % columns) + columns) % columns;
      for (int u = 0; u < columns; ++u) {
        const std::size_t i = image.index(v, u);
        uint8_t* point = cloud.data.data() + std::size_t(v) * cloud.row_step +
                         std::size_t((u + shift) % columns) * cloud.point_step;
        if (isValidRange(image.range[i])) writePoint(point, model.unproject(u, v, image.range[i]), intensityAt(i));
        writeTimeAndRing(point, time_offsets[u], static_cast<uint16_t>(v));
      }
    }
    return;
  }

  const std::size_t valid = image.validCount();
  cloud.height = 1;
  cloud.width = static_cast<uint32_t>(valid);
  cloud.row_step = cloud.width * cloud.point_step;
  cloud.data.resize(std::size_t(cloud.row_step));
  cloud.is_dense = true;
  uint8_t* point = cloud.data.data();
  for (int v = 0; v < rows; ++v)
    for (int u = 0; u < columns; ++u) {
      const std::size_t i = image.index(v, u);
      if (!isValidRange(image.range[i])) continue;
      writePoint(point, model.unproject(u, v, image.range[i]), intensityAt(i));
      if (timed) writeTimeAndRing(point, time_offsets[u], static_cast<uint16_t>(v));
      point += cloud.point_step;
    }
}

BagWriter::BagWriter(const std::string& path, rosbag::compression::CompressionType compression)
    : path_(path) {
  try {
    bag_.open(path, rosbag::bagmode::Write);
  } catch (const rosbag::BagException& error) {
    throw BagWriteError("bag " + path + ": cannot write: " + error.what());
  }
  bag_.setCompression(compression);
  // The connection headers a recording of the Ouster driver would have.
  const auto header = [](const char* type, const char* md5, const char* definition, bool latched) {
    auto fields = boost::make_shared<ros::M_string>();
    (*fields)["type"] = type;
    (*fields)["md5sum"] = md5;
    (*fields)["message_definition"] = definition;
    (*fields)["callerid"] = "/range_image_mapping_bag_writer";
    (*fields)["latching"] = latched ? "1" : "0";
    return fields;
  };
  namespace traits = ros::message_traits;
  packet_connection_header_ = header(traits::DataType<OusterPacketMessage>::value(),
                                     traits::MD5Sum<OusterPacketMessage>::value(),
                                     traits::Definition<OusterPacketMessage>::value(), false);
  metadata_connection_header_ = header(traits::DataType<std_msgs::String>::value(),
                                       traits::MD5Sum<std_msgs::String>::value(),
                                       traits::Definition<std_msgs::String>::value(), true);
}

BagWriter::~BagWriter() {
  try {
    close();
  } catch (...) {
    // A destructor must not throw; call close() to see the error.
  }
}

ros::Time BagWriter::messageTime(int64_t time_ns) const {
  constexpr int64_t kMaxRosTimeNs = int64_t{std::numeric_limits<uint32_t>::max()} * 1000000000;
  if (time_ns <= 0 || time_ns >= kMaxRosTimeNs)
    throw BagWriteError("bag " + path_ + ": message time " + std::to_string(time_ns) +
                        " ns is not a ROS time (after 0, before 2^32 s): give a time offset");
  ros::Time time;
  time.fromNSec(static_cast<uint64_t>(time_ns));
  return time;
}

void BagWriter::writeOusterMetadata(const std::string& metadata_json, uint64_t time_ns,
                                    const std::string& topic) {
  std_msgs::String message;
  message.data = metadata_json;
  bag_.write(topic, messageTime(static_cast<int64_t>(time_ns)), message, metadata_connection_header_);
}

void BagWriter::writeOusterPacket(const uint8_t* packet, std::size_t size, uint64_t time_ns,
                                  const std::string& topic) {
  const ros::Time time = messageTime(static_cast<int64_t>(time_ns));
  packet_.buf.assign(packet, packet + size);
  bag_.write(topic, time, packet_, packet_connection_header_);
}

std::size_t BagWriter::writeOusterScan(const OusterPacketEncoder& encoder, const LidarScan& scan,
                                       int64_t time_offset_ns, const std::string& topic) {
  return encoder.encode(scan, [&](const uint8_t* packet, std::size_t size, uint64_t timestamp_ns) {
    writeOusterPacket(packet, size, static_cast<uint64_t>(static_cast<int64_t>(timestamp_ns) + time_offset_ns),
                      topic);
  });
}

void BagWriter::writePointCloud(const sensor_msgs::PointCloud2& cloud, const std::string& topic) {
  bag_.write(topic, messageTime(static_cast<int64_t>(cloud.header.stamp.toNSec())), cloud);
}

void BagWriter::close() {
  if (!bag_.isOpen()) return;
  try {
    bag_.close();
  } catch (const rosbag::BagException& error) {
    throw BagWriteError("bag " + path_ + ": closing failed: " + error.what());
  }
}

}  // namespace range_image_mapping
