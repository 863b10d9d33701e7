// PCD files (PCL's Point Cloud Data format, version 0.7 and the older 0.6
// header): a text header naming the fields (FIELDS, SIZE, TYPE, COUNT, WIDTH,
// HEIGHT, POINTS, DATA) followed by the points as ASCII lines, packed binary
// (the PointCloud2 layout, little-endian) or binary_compressed (LZF, one field
// after the other). Read through point_cloud_layout, so a PCD's fields follow
// the same conventions as a PointCloud2 (intensity, ring, per-point time).
#pragma once

#include "range_image_mapping/point_cloud_layout.h"

#include <cstdint>
#include <stdexcept>
#include <string>

namespace range_image_mapping::io {

// A PCD file that cannot be read or written; what() names the file, the
// header line or point, and the problem.
class PcdFormatError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The file's points (no-return points kept and counted, organized clouds keep
// their shape); stamp and per-point times as readPointCloud gives them with
// stamp_ns as the header stamp (PCD has none).
PointCloudInput readPcd(const std::string& path, uint64_t stamp_ns = 0, PointCloudReadReport* report = nullptr);

enum class PcdEncoding { kAscii, kBinary };

// x, y, z (float32) and whatever of intensity (float32), ring (uint16) and time
// (float32 seconds after cloud.stamp_ns) the cloud has; organized clouds keep
// their height and width.
void writePcd(const std::string& path, const PointCloudInput& cloud, PcdEncoding encoding);

}  // namespace range_image_mapping::io
