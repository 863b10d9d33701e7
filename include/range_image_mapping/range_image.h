// A scan as a cylindrical range image: ranges, validity, optional intensity,
// per-column timestamps and the sensor model needed to unproject it.
#pragma once

#include "range_image_mapping/lidar_intrinsics.h"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace range_image_mapping {

// Columns are stored staggered (column = measurement id, what Pi and Pi^-1
// expect) or destaggered (rows shifted by pixel_shift_by_row, for display).
enum class ColumnOrder : uint8_t { kStaggered = 0, kDestaggered = 1 };

// A strided window on row-major pixels: level s of the pyramid reads pixel
// (s*row, s*column) of the full image without copying anything.
template <typename T>
class ImageView {
 public:
  ImageView() = default;
  ImageView(T* data, int full_rows, int full_columns, int stride)
      : data_(data),
        full_columns_(full_columns),
        rows_((full_rows + stride - 1) / stride),
        columns_((full_columns + stride - 1) / stride),
        stride_(stride) {}

  int rows() const { return rows_; }
  int columns() const { return columns_; }
  int stride() const { return stride_; }
  T* data() const { return data_; }
  T& operator()(int row, int column) const {
    return data_[static_cast<std::ptrdiff_t>(row) * stride_ * full_columns_ +
                 static_cast<std::ptrdiff_t>(column) * stride_];
  }
  // Full-resolution pixel of a view pixel, for Pi^-1 with the original tables.
  int fullRow(int row) const { return row * stride_; }
  int fullColumn(int column) const { return column * stride_; }

 private:
  T* data_ = nullptr;
  int full_columns_ = 0;
  int rows_ = 0;
  int columns_ = 0;
  int stride_ = 1;
};

inline bool isValidRange(float range) { return std::isfinite(range) && range > 0.0f; }

struct RangeImage {
  LidarModelConstPtr model;  // shared by all scans of one sensor
  // Ranges in metres from the beam origin, row-major H*W. No return = NaN.
  // Float metres hold every Ouster millimetre reading (up to 2^20 mm) exactly:
  // std::lround(range * 1000) gives the sensor's integer back.
  std::vector<float> range;
  std::vector<float> intensity;  // empty or H*W
  std::string intensity_field;   // what intensity holds: "reflectivity", "signal", "intensity", ...
  std::vector<uint64_t> column_timestamp_ns;  // W entries, 0 where the column is missing
  ColumnOrder column_order = ColumnOrder::kStaggered;
  uint64_t stamp_ns = 0;  // scan time: first valid column timestamp unless the source says otherwise
  uint32_t frame_id = 0;

  RangeImage() = default;
  // Allocates an image of the model's size with every pixel invalid.
  explicit RangeImage(LidarModelConstPtr sensor_model);

  int rows() const { return model ? model->rows() : 0; }
  int columns() const { return model ? model->columns() : 0; }
  std::size_t index(int row, int column) const {
    return static_cast<std::size_t>(row) * columns() + column;
  }
  float at(int row, int column) const { return range[index(row, column)]; }
  bool valid(int row, int column) const { return isValidRange(at(row, column)); }
  std::size_t validCount() const;
  std::vector<uint8_t> validityMask() const;  // 1 = return, 0 = no return

  ImageView<const float> rangeView(int stride = 1) const {
    return ImageView<const float>(range.data(), rows(), columns(), stride);
  }

  // Points of all valid pixels in the lidar frame (staggered images only).
  std::vector<Eigen::Vector3f> unprojectAll() const;

  // Copies with rows shifted for display, and back. Geometry needs staggered.
  RangeImage destaggered() const;
  RangeImage staggered() const;
};

}  // namespace range_image_mapping
