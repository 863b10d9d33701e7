#include "range_image_mapping/ros/range_image_conversions.h"

#include "range_image_mapping/io/rosbag_reader.h"

#include <sensor_msgs/PointField.h>
#include <sensor_msgs/point_cloud2_iterator.h>

#include <algorithm>
#include <cstring>
#include <limits>
#include <optional>
#include <string>

namespace range_image_mapping {
namespace {

[[noreturn]] void fail(const std::string& what) { throw MessageConversionError(what); }

// ------------------------------------------------------------ range image message

template <typename Sequence>
void requireSize(const Sequence& values, std::uint64_t expected, const std::string& name,
                 const std::string& expected_name) {
  if (values.size() != expected)
    fail("LidarRangeImage: " + name + " has " + std::to_string(values.size()) + " values, " +
         expected_name + " is " + std::to_string(expected));
}

// The message's pixel arrays and table sizes agree with height and width. Checked
// before any table is built, so a bogus height*width cannot allocate a huge model.
void checkMessageSizes(const LidarRangeImage& message) {
  if (message.height == 0 || message.width == 0 ||
      message.height > static_cast<uint32_t>(std::numeric_limits<int>::max()) ||
      message.width > static_cast<uint32_t>(std::numeric_limits<int>::max()))
    fail("LidarRangeImage: height and width must be positive, got " +
         std::to_string(message.height) + "x" + std::to_string(message.width));
  const std::uint64_t pixels = std::uint64_t(message.height) * message.width;
  requireSize(message.range, pixels, "range", "height*width");
  if (!message.intensity.empty()) requireSize(message.intensity, pixels, "intensity", "height*width");
  if (!message.column_timestamps.empty())
    requireSize(message.column_timestamps, message.width, "column_timestamps", "width");
  requireSize(message.altitude, message.height, "altitude", "height");
  requireSize(message.azimuth_offset, message.height, "azimuth_offset", "height");
  if (!message.pixel_shift_by_row.empty())
    requireSize(message.pixel_shift_by_row, message.height, "pixel_shift_by_row", "height");
  if (message.column_order != LidarRangeImage::STAGGERED &&
      message.column_order != LidarRangeImage::DESTAGGERED)
    fail("LidarRangeImage: column_order must be STAGGERED (0) or DESTAGGERED (1), got " +
         std::to_string(message.column_order));
}

Eigen::Matrix4d lidarToSensorMatrix(const LidarRangeImage& message) {
  Eigen::Matrix4d matrix;
  for (int i = 0; i < 16; ++i) matrix(i / 4, i % 4) = message.lidar_to_sensor[i];
  return matrix;
}

// Field for field the comparison LidarModelCache needs, without building
// intrinsics (no allocation per scan).
bool sameTables(const LidarIntrinsics& tables, const LidarRangeImage& message) {
  return tables.rows == static_cast<int>(message.height) &&
         tables.columns == static_cast<int>(message.width) &&
         tables.altitude_rad == message.altitude &&
         tables.azimuth_offset_rad == message.azimuth_offset &&
         tables.beam_origin_radius_m == message.beam_origin_radius &&
         tables.beam_origin_z_m == message.beam_origin_z &&
         tables.pixel_shift_by_row == message.pixel_shift_by_row &&
         tables.lidar_to_sensor.matrix() == lidarToSensorMatrix(message) &&
         tables.column_window[0] == message.column_window[0] &&
         tables.column_window[1] == message.column_window[1] &&
         tables.sensor_model == message.sensor_model;
}

}  // namespace

// ------------------------------------------------------------ range image message

LidarIntrinsics intrinsicsFromMessage(const LidarRangeImage& message) {
  checkMessageSizes(message);
  LidarIntrinsics intrinsics;
  intrinsics.rows = static_cast<int>(message.height);
  intrinsics.columns = static_cast<int>(message.width);
  intrinsics.altitude_rad = message.altitude;
  intrinsics.azimuth_offset_rad = message.azimuth_offset;
  intrinsics.beam_origin_radius_m = message.beam_origin_radius;
  intrinsics.beam_origin_z_m = message.beam_origin_z;
  intrinsics.pixel_shift_by_row.assign(message.pixel_shift_by_row.begin(),
                                       message.pixel_shift_by_row.end());
  intrinsics.lidar_to_sensor.matrix() = lidarToSensorMatrix(message);
  intrinsics.column_window = {message.column_window[0], message.column_window[1]};
  intrinsics.sensor_model = message.sensor_model;
  intrinsics.validate();
  return intrinsics;
}

const LidarModelConstPtr& LidarModelCache::modelFor(const LidarRangeImage& message) {
  if (model_ && sameTables(tables_, message)) return model_;
  LidarIntrinsics tables = intrinsicsFromMessage(message);
  model_ = std::make_shared<const LidarModel>(tables);  // may throw: then nothing changes
  tables_ = std::move(tables);
  return model_;
}

void toMessage(const RangeImage& image, const std_msgs::Header& header, LidarRangeImage& message) {
  if (!image.model) fail("toMessage: the range image has no sensor model");
  const LidarIntrinsics& intrinsics = image.model->intrinsics();
  message.header = header;
  message.height = static_cast<uint32_t>(image.rows());
  message.width = static_cast<uint32_t>(image.columns());
  message.column_order = image.column_order == ColumnOrder::kStaggered ? LidarRangeImage::STAGGERED
                                                                         : LidarRangeImage::DESTAGGERED;
  message.frame_id = image.frame_id;
  message.range = image.range;
  message.intensity = image.intensity;
  message.intensity_field = image.intensity_field;
  message.column_timestamps = image.column_timestamp_ns;

  message.sensor_model = intrinsics.sensor_model;
  message.altitude = intrinsics.altitude_rad;
  message.azimuth_offset = intrinsics.azimuth_offset_rad;
  message.beam_origin_radius = intrinsics.beam_origin_radius_m;
  message.beam_origin_z = intrinsics.beam_origin_z_m;
  message.pixel_shift_by_row.assign(intrinsics.pixel_shift_by_row.begin(),
                                    intrinsics.pixel_shift_by_row.end());
  const Eigen::Matrix4d& lidar_to_sensor = intrinsics.lidar_to_sensor.matrix();
  for (int i = 0; i < 16; ++i) message.lidar_to_sensor[i] = lidar_to_sensor(i / 4, i % 4);
  message.column_window[0] = intrinsics.column_window[0];
  message.column_window[1] = intrinsics.column_window[1];
}

RangeImage fromMessage(const LidarRangeImage& message, LidarModelCache& models) {
  RangeImage image;
  image.model = models.modelFor(message);  // checks every size first
  image.range = message.range;
  image.intensity = message.intensity;
  image.intensity_field = message.intensity_field;
  image.column_timestamp_ns = message.column_timestamps;
  if (image.column_timestamp_ns.empty()) image.column_timestamp_ns.assign(message.width, 0);
  image.column_order = message.column_order == LidarRangeImage::STAGGERED ? ColumnOrder::kStaggered
                                                                          : ColumnOrder::kDestaggered;
  image.stamp_ns = message.header.stamp.toNSec();
  image.frame_id = message.frame_id;
  return image;
}

void toPointCloud2(const RangeImage& image, const std_msgs::Header& header,
                   sensor_msgs::PointCloud2& cloud) {
  if (!image.model) fail("toPointCloud2: the range image has no sensor model");
  if (image.column_order != ColumnOrder::kStaggered) {
    toPointCloud2(image.staggered(), header, cloud);
    return;
  }
  const bool with_intensity = !image.intensity.empty();
  const auto add_field = [&](const char* name, uint32_t offset, uint8_t datatype) {
    sensor_msgs::PointField field;
    field.name = name;
    field.offset = offset;
    field.datatype = datatype;
    field.count = 1;
    cloud.fields.push_back(field);
  };
  cloud.fields.clear();
  add_field("x", 0, sensor_msgs::PointField::FLOAT32);
  add_field("y", 4, sensor_msgs::PointField::FLOAT32);
  add_field("z", 8, sensor_msgs::PointField::FLOAT32);
  uint32_t ring_offset = 12;
  if (with_intensity) {
    add_field("intensity", 12, sensor_msgs::PointField::FLOAT32);
    ring_offset = 16;
  }
  add_field("ring", ring_offset, sensor_msgs::PointField::UINT16);

  const std::size_t points = image.validCount();
  cloud.header = header;
  cloud.height = 1;
  cloud.width = static_cast<uint32_t>(points);
  cloud.is_bigendian = false;
  cloud.point_step = ring_offset + 4;  // ring plus padding keeps every point 4-byte aligned
  cloud.row_step = cloud.point_step * cloud.width;
  cloud.is_dense = true;
  cloud.data.assign(cloud.row_step, 0);

  uint8_t* out = cloud.data.data();
  for (int v = 0; v < image.rows(); ++v) {
    const uint16_t ring = static_cast<uint16_t>(v);
    for (int u = 0; u < image.columns(); ++u) {
      if (!image.valid(v, u)) continue;
      const Eigen::Vector3f point = image.model->unproject(u, v, image.at(v, u));
      std::memcpy(out, point.data(), 3 * sizeof(float));
      if (with_intensity) std::memcpy(out + 12, &image.intensity[image.index(v, u)], sizeof(float));
      std::memcpy(out + ring_offset, &ring, sizeof(ring));
      out += cloud.point_step;
    }
  }
}

void pointsToPointCloud2(const std::vector<Eigen::Vector3f>& points, const std::vector<float>* intensities,
                         const std_msgs::Header& header, sensor_msgs::PointCloud2& cloud) {
  const std::size_t count =
      std::count_if(points.begin(), points.end(), [](const Eigen::Vector3f& p) { return p.allFinite(); });
  cloud.header = header;
  sensor_msgs::PointCloud2Modifier modifier(cloud);
  if (intensities)
    modifier.setPointCloud2Fields(4, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1,
                                  sensor_msgs::PointField::FLOAT32, "z", 1, sensor_msgs::PointField::FLOAT32,
                                  "intensity", 1, sensor_msgs::PointField::FLOAT32);
  else
    modifier.setPointCloud2FieldsByString(1, "xyz");
  modifier.resize(count);
  cloud.height = 1;
  cloud.width = static_cast<uint32_t>(count);
  cloud.is_dense = true;
  sensor_msgs::PointCloud2Iterator<float> x(cloud, "x"), y(cloud, "y"), z(cloud, "z");
  std::optional<sensor_msgs::PointCloud2Iterator<float>> intensity;
  if (intensities) intensity.emplace(cloud, "intensity");
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!points[i].allFinite()) continue;
    *x = points[i].x();
    *y = points[i].y();
    *z = points[i].z();
    ++x, ++y, ++z;
    if (intensity) {
      **intensity = (*intensities)[i];
      ++*intensity;
    }
  }
}

void fromPointCloud2(const sensor_msgs::PointCloud2& cloud, PointCloudInput& input, PointCloudReadReport* report) {
  PointCloudLayout layout;
  for (const sensor_msgs::PointField& field : cloud.fields)
    layout.fields.push_back({field.name, field.offset, field.datatype, field.count});
  layout.height = cloud.height;
  layout.width = cloud.width;
  layout.point_step = cloud.point_step;
  layout.row_step = cloud.row_step;
  layout.is_bigendian = cloud.is_bigendian;
  try {
    readPointCloud(layout, cloud.data.data(), cloud.data.size(), cloud.header.stamp.toNSec(), input, report);
  } catch (const PointCloudLayoutError& error) {
    // The core's "point cloud: ..." as "PointCloud2: ...".
    const std::string what = error.what();
    const std::string core_prefix = "point cloud: ";
    fail("PointCloud2: " + (what.rfind(core_prefix, 0) == 0 ? what.substr(core_prefix.size()) : what));
  }
}

// ------------------------------------------------------------ motion

geometry_msgs::Twist toTwistMessage(const Twist& twist) {
  geometry_msgs::Twist message;
  message.angular.x = twist[0];
  message.angular.y = twist[1];
  message.angular.z = twist[2];
  message.linear.x = twist[3];
  message.linear.y = twist[4];
  message.linear.z = twist[5];
  return message;
}

Twist fromTwistMessage(const geometry_msgs::Twist& message) {
  Twist twist;
  twist << message.angular.x, message.angular.y, message.angular.z, message.linear.x, message.linear.y,
      message.linear.z;
  return twist;
}

void toCovarianceMessage(const Eigen::Matrix<double, 6, 6>& covariance, boost::array<double, 36>& message) {
  // Row/column r of the message is row/column (r + 3) % 6 of the core's.
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) message[r * 6 + c] = covariance((r + 3) % 6, (c + 3) % 6);
}

// ------------------------------------------------------------ Ouster packets

PacketBytes ousterPacketBytes(const topic_tools::ShapeShifter& message, std::vector<uint8_t>& buffer) {
  buffer.resize(message.size());
  ros::serialization::OStream stream(buffer.data(), static_cast<uint32_t>(buffer.size()));
  message.write(stream);
  try {
    // The same checks (type, md5, length prefix) as a bag's packets get.
    const io::BagPacket packet =
        io::ousterPacketPayload(buffer.data(), buffer.size(), message.getDataType(), message.getMD5Sum());
    return PacketBytes{packet.data, packet.size};
  } catch (const io::BagError& error) {
    fail(error.what());
  }
}

}  // namespace range_image_mapping
