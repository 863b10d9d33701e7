#include "range_image_mapping/range_image.h"

#include <limits>
#include <stdexcept>

namespace range_image_mapping {
namespace {

// Destaggering moves pixel (v, u) to column (u + shift[v]) mod W; restaggering
// is the same move with the opposite sign. Both move intensity with range.
RangeImage shiftRows(const RangeImage& source, int sign, ColumnOrder result_order) {
  RangeImage result = source;
  const int rows = source.rows();
  const int columns = source.columns();
  const auto& shifts = source.model->intrinsics().pixel_shift_by_row;
  for (int v = 0; v < rows; ++v) {
    const int shift = ((sign * shifts[v]) % columns + columns) % columns;
    for (int u = 0; u < columns; ++u) {
      const std::size_t to = result.index(v, (u + shift) % columns);
      result.range[to] = source.range[source.index(v, u)];
      if (!source.intensity.empty()) result.intensity[to] = source.intensity[source.index(v, u)];
    }
  }
  result.column_order = result_order;
  return result;
}

}  // namespace

RangeImage::RangeImage(LidarModelConstPtr sensor_model) : model(std::move(sensor_model)) {
  if (!model) throw std::invalid_argument("RangeImage: no sensor model");
  range.assign(static_cast<std::size_t>(rows()) * columns(), std::numeric_limits<float>::quiet_NaN());
  column_timestamp_ns.assign(columns(), 0);
}

std::size_t RangeImage::validCount() const {
  std::size_t count = 0;
  for (const float r : range) count += isValidRange(r);
  return count;
}

std::vector<uint8_t> RangeImage::validityMask() const {
  std::vector<uint8_t> mask(range.size());
  for (std::size_t i = 0; i < range.size(); ++i) mask[i] = isValidRange(range[i]);
  return mask;
}

std::vector<Eigen::Vector3f> RangeImage::unprojectAll() const {
  if (column_order != ColumnOrder::kStaggered)
    throw std::logic_error("RangeImage::unprojectAll needs a staggered image");
  std::vector<Eigen::Vector3f> points;
  points.reserve(validCount());
  for (int v = 0; v < rows(); ++v)
    for (int u = 0; u < columns(); ++u)
      if (valid(v, u)) points.push_back(model->unproject(u, v, at(v, u)));
  return points;
}

RangeImage RangeImage::destaggered() const {
  if (column_order == ColumnOrder::kDestaggered) return *this;
  return shiftRows(*this, +1, ColumnOrder::kDestaggered);
}

RangeImage RangeImage::staggered() const {
  if (column_order == ColumnOrder::kStaggered) return *this;
  return shiftRows(*this, -1, ColumnOrder::kStaggered);
}

}  // namespace range_image_mapping
