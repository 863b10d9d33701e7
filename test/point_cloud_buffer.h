// Tests write clouds in the PointCloud2 layout the way drivers do: a list of
// fields with their types, one value per field and point, packed at offsets.
#pragma once

#include "range_image_mapping/point_cloud_layout.h"

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

namespace range_image_mapping::test {

// A cloud under construction: fields are appended in order (each aligned to
// its size, as the drivers' structs are), then points are written value by value.
class PointCloudBuffer {
 public:
  PointCloudBuffer(uint32_t height, uint32_t width) {
    layout.height = height;
    layout.width = width;
  }

  // Adds a field after the previous one (or at offset when given).
  PointCloudBuffer& field(const std::string& name, PointFieldType type, int offset = -1) {
    const uint32_t size = static_cast<uint32_t>(pointFieldTypeSize(static_cast<uint8_t>(type)));
    uint32_t at = offset >= 0 ? static_cast<uint32_t>(offset) : (end_ + size - 1) / size * size;
    layout.fields.push_back({name, at, static_cast<uint8_t>(type), 1});
    end_ = std::max(end_, at + size);
    return *this;
  }

  // Fixes the layout (point_step rounded up to align bytes plus padding) and
  // allocates the data, zeroed.
  PointCloudBuffer& finish(uint32_t padding = 0, uint32_t row_padding = 0, uint32_t align = 4) {
    layout.point_step = (end_ + padding + align - 1) / align * align;
    layout.row_step = layout.point_step * layout.width + row_padding;
    data.assign(std::size_t(layout.row_step) * layout.height, 0);
    return *this;
  }

  // Writes value into field name of point i (row-major), in the layout's byte order.
  void set(std::size_t i, const std::string& name, double value) {
    const PointFieldLayout* field = layout.find(name);
    const std::size_t row = i / layout.width, column = i % layout.width;
    uint8_t* at = data.data() + row * layout.row_step + column * layout.point_step + field->offset;
    uint8_t bytes[8];
    std::size_t size = 0;
    const auto put = [&](auto typed) {
      size = sizeof(typed);
      std::memcpy(bytes, &typed, size);
    };
    switch (static_cast<PointFieldType>(field->datatype)) {
      case PointFieldType::kInt8: put(static_cast<int8_t>(value)); break;
      case PointFieldType::kUint8: put(static_cast<uint8_t>(value)); break;
      case PointFieldType::kInt16: put(static_cast<int16_t>(value)); break;
      case PointFieldType::kUint16: put(static_cast<uint16_t>(value)); break;
      case PointFieldType::kInt32: put(static_cast<int32_t>(value)); break;
      case PointFieldType::kUint32: put(static_cast<uint32_t>(value)); break;
      case PointFieldType::kFloat32: put(static_cast<float>(value)); break;
      case PointFieldType::kFloat64: put(value); break;
    }
    if (layout.is_bigendian) std::reverse(bytes, bytes + size);
    std::memcpy(at, bytes, size);
  }

  PointCloudLayout layout;
  std::vector<uint8_t> data;

 private:
  uint32_t end_ = 0;
};

}  // namespace range_image_mapping::test
