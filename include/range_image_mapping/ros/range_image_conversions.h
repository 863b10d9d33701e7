// Conversions between ROS messages and the core types: the LidarRangeImage
// message and the core RangeImage (with its LidarModel), PointCloud2 into
// the core PointCloudInput, and the core's twists and pose covariances in the
// order of geometry_msgs. Nothing here projects or filters points: that is
// the core's job (point_cloud_projection.h).
#pragma once

#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/point_cloud_layout.h"
#include "range_image_mapping/point_cloud_projection.h"
#include "range_image_mapping/range_image.h"
#include "range_image_mapping/scan_motion.h"

#include <boost/array.hpp>
#include <geometry_msgs/Twist.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_msgs/Header.h>
#include <topic_tools/shape_shifter.h>

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <vector>

namespace range_image_mapping {

// A message that cannot be converted (inconsistent sizes, missing or mistyped
// PointCloud2 fields); what() names the field and what is wrong with it.
class MessageConversionError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// The message's sensor tables as core intrinsics. Throws MessageConversionError
// for tables whose sizes disagree, IntrinsicsError for values no sensor can have.
LidarIntrinsics intrinsicsFromMessage(const LidarRangeImage& message);

// Builds a LidarModel from a message's tables only when they differ from the
// tables of the previous call (compared by value, so a stream of one sensor
// shares one model and building the per-pixel tables happens once).
class LidarModelCache {
 public:
  // Throws like intrinsicsFromMessage; the cached model is kept on error.
  const LidarModelConstPtr& modelFor(const LidarRangeImage& message);
  const LidarModelConstPtr& model() const { return model_; }

 private:
  LidarIntrinsics tables_;  // as read from the message that built model_
  LidarModelConstPtr model_;
};

// Fills message from image: pixels, timestamps and every table of the model, so
// the message alone unprojects its pixels. header.stamp and header.frame_id are
// the caller's (scan time in ROS time, lidar frame).
void toMessage(const RangeImage& image, const std_msgs::Header& header, LidarRangeImage& message);

// The message as a core image whose model comes from (and is cached in) models.
RangeImage fromMessage(const LidarRangeImage& message, LidarModelCache& models);

// The valid pixels of a staggered image as an unorganized cloud in the lidar
// frame with fields x, y, z (float32), ring (uint16, the image row) and, when
// the image has intensity, intensity (float32). Reuses cloud's buffers.
void toPointCloud2(const RangeImage& image, const std_msgs::Header& header,
                   sensor_msgs::PointCloud2& cloud);

// The finite points (NaN marks an invalid one) as an unorganized cloud with
// fields x, y, z and, when intensities is given (one per point), intensity,
// all float32. Reuses cloud's buffers.
void pointsToPointCloud2(const std::vector<Eigen::Vector3f>& points, const std::vector<float>* intensities,
                         const std_msgs::Header& header, sensor_msgs::PointCloud2& cloud);

// PointCloud2 into the core's plain arrays, read by the core's
// readPointCloud (point_cloud_layout.h: the drivers' field names for
// intensity, ring and per-point time, relative or absolute; no-return NaN and
// (0, 0, 0) points kept and counted; input.stamp_ns the scan time from the
// points' times, the header stamp without them). Organized clouds (height > 1)
// keep their layout. Throws MessageConversionError naming the field and its
// type for a missing or unsupported field, and for sizes that disagree with
// the data. Reuses input's buffers, so a converter called per scan does not
// allocate.
void fromPointCloud2(const sensor_msgs::PointCloud2& cloud, PointCloudInput& input,
                     PointCloudReadReport* report = nullptr);

// ------------------------------------------------------------ motion

// A body twist in the core's order [angular, linear] as geometry_msgs/Twist
// (linear first; tf2's Eigen conversions assume that order too), and back.
geometry_msgs::Twist toTwistMessage(const Twist& twist);
Twist fromTwistMessage(const geometry_msgs::Twist& message);

// A 6x6 covariance in the core's order [rotation, translation] as the
// row-major [x y z, roll pitch yaw] array of nav_msgs and geometry_msgs.
void toCovarianceMessage(const Eigen::Matrix<double, 6, 6>& covariance, boost::array<double, 36>& message);

// ------------------------------------------------------------ Ouster packets

// The UDP payload inside an Ouster packet message, without depending on any
// Ouster package: ouster_ros/PacketMsg and ouster_sensor_msgs/PacketMsg are both
// "uint8[] buf", serialized as a little-endian uint32 length and the bytes.
struct PacketBytes {
  const uint8_t* data = nullptr;
  std::size_t size = 0;
};

// Copies the message's serialization into buffer (reused between calls) and
// returns the payload inside it. Throws MessageConversionError naming the type
// for any other message type, and for a length prefix that disagrees with the
// serialized size.
PacketBytes ousterPacketBytes(const topic_tools::ShapeShifter& message, std::vector<uint8_t>& buffer);

}  // namespace range_image_mapping
