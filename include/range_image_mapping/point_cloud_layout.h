// Point clouds in the PointCloud2 layout (a list of named, typed fields at
// byte offsets in each point, rows of points) read into the core's
// PointCloudInput without any ROS type, with the drivers' conventions for the
// optional fields: intensity, ring and per-point time. The ROS side, the
// rosbag reader and the PCD reader (whose binary data is this layout) all read
// clouds here.
#pragma once

#include "range_image_mapping/point_cloud_projection.h"

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace range_image_mapping {

// A layout or buffer that cannot be read (inconsistent sizes, a required field
// missing, a field of a type its convention does not allow); what() names the
// field and what is wrong with it.
class PointCloudLayoutError : public PointCloudError {
 public:
  using PointCloudError::PointCloudError;
};

// Field types, numbered as sensor_msgs/PointField's datatype constants (the
// numbers travel in bags and messages, so they are the contract).
enum class PointFieldType : uint8_t {
  kInt8 = 1,
  kUint8 = 2,
  kInt16 = 3,
  kUint16 = 4,
  kInt32 = 5,
  kUint32 = 6,
  kFloat32 = 7,
  kFloat64 = 8,
};

// "float32", "uint16", ...; "unknown" for any other number.
const char* pointFieldTypeName(uint8_t datatype);
// Bytes of one value; 0 for an unknown type.
std::size_t pointFieldTypeSize(uint8_t datatype);

struct PointFieldLayout {
  std::string name;
  uint32_t offset = 0;   // bytes from the start of the point
  uint8_t datatype = 0;  // a PointFieldType number
  uint32_t count = 1;    // values of the field (the conventions below read only the first)
};

// What sensor_msgs/PointCloud2 says about its data besides the bytes and header.
struct PointCloudLayout {
  std::vector<PointFieldLayout> fields;
  uint32_t height = 1;      // > 1: an organized cloud of height x width points
  uint32_t width = 0;
  uint32_t point_step = 0;  // bytes per point
  uint32_t row_step = 0;    // bytes per row (>= width * point_step)
  bool is_bigendian = false;

  // The field of that name, nullptr when there is none.
  const PointFieldLayout* find(const std::string& name) const;
};

// How a cloud's per-point times were read.
enum class PointTimeReference {
  kNone,      // the cloud has no per-point time field: every point is at the header stamp
  kRelative,  // offsets from the header stamp (ouster-ros t, velodyne time, offset_time, time_stamp)
  kAbsolute,  // clock times (Hesai and RoboSense timestamp, Livox timestamp)
};

// What readPointCloud found, for logs and diagnostics.
struct PointCloudReadReport {
  std::string intensity_field;  // "" when none
  std::string ring_field;       // "" when none
  std::string time_field;       // "" when none
  PointTimeReference time_reference = PointTimeReference::kNone;
  double time_unit_s = 0.0;     // seconds per unit of the time field (1e-9 for nanoseconds)
  std::size_t points = 0;       // height * width
  std::size_t non_finite = 0;   // no-return points marked NaN/Inf (ouster-ros): not drops
  std::size_t at_origin = 0;    // no-return points marked (0, 0, 0): not drops
  uint64_t header_stamp_ns = 0;
  // The scan's stamp (the earliest measured point's time, or the header stamp
  // without times) minus the header stamp.
  int64_t stamp_from_header_ns = 0;
  double time_span_s = 0.0;     // latest minus earliest measured point time (0 without times)

  std::size_t noReturn() const { return non_finite + at_origin; }
  std::size_t measured() const { return points - noReturn(); }
};

// Field names tried for each convention, in order (the first present wins).
// Coordinates: x, y, z as float32 or float64, required.
// Intensity (any numeric type): intensity, reflectivity, signal.
// Ring (any integer type): ring, channel.
// Time: t (ouster-ros, uint32 ns), time (velodyne_pointcloud, float32 s),
// timestamp (Hesai, RoboSense: float64 absolute s; Livox: float64 absolute ns),
// time_stamp (Autoware, uint32 ns), offset_time (Livox, uint32 ns), time_offset.
const std::vector<std::string>& intensityFieldNames();
const std::vector<std::string>& ringFieldNames();
const std::vector<std::string>& timeFieldNames();

// Reads the cloud in data (size bytes, laid out as layout says, big- or
// little-endian) into input, reusing its buffers: every point, no-return points
// (NaN/Inf or exactly (0, 0, 0)) included and counted, so organized clouds keep
// their shape; intensity, ring and per-point times where the cloud has them.
// Time units: integer fields are nanoseconds; float fields seconds, except
// float64 values beyond 1e12 (nanoseconds). Whether times are absolute or
// relative to header_stamp_ns is read from the values: a time nearer to the
// header stamp than to zero is absolute. input.stamp_ns is the earliest
// measured point's time (the scan time from the points, not the header, which
// drivers stamp with jitter) and input.time_offset_s is relative to it; without
// times, stamp_ns is the header stamp. The organized column order is left as
// the caller set it. Throws PointCloudLayoutError naming the field or size
// that is wrong; input is then unspecified.
void readPointCloud(const PointCloudLayout& layout, const uint8_t* data, std::size_t size,
                    uint64_t header_stamp_ns, PointCloudInput& input, PointCloudReadReport* report = nullptr);

}  // namespace range_image_mapping
