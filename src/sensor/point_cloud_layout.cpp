#include "range_image_mapping/point_cloud_layout.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

namespace range_image_mapping {
namespace {

[[noreturn]] void fail(const std::string& what) { throw PointCloudLayoutError("point cloud: " + what); }

bool isInteger(uint8_t datatype) {
  return datatype >= static_cast<uint8_t>(PointFieldType::kInt8) &&
         datatype <= static_cast<uint8_t>(PointFieldType::kUint32);
}
bool isFloat(uint8_t datatype) {
  return datatype == static_cast<uint8_t>(PointFieldType::kFloat32) ||
         datatype == static_cast<uint8_t>(PointFieldType::kFloat64);
}

template <typename T>
T readValue(const uint8_t* bytes, bool swap) {
  uint8_t buffer[sizeof(T)];
  std::memcpy(buffer, bytes, sizeof(T));
  if (swap) std::reverse(buffer, buffer + sizeof(T));
  T value;
  std::memcpy(&value, buffer, sizeof(T));
  return value;
}

bool hostIsBigEndian() {
  const uint16_t probe = 1;
  uint8_t first;
  std::memcpy(&first, &probe, 1);
  return first == 0;
}

// One field of a point, read as double whatever its type.
class FieldReader {
 public:
  FieldReader() = default;
  FieldReader(const PointFieldLayout& field, bool swap) : field_(&field), swap_(swap) {}

  explicit operator bool() const { return field_ != nullptr; }
  const PointFieldLayout& field() const { return *field_; }

  double read(const uint8_t* point) const {
    const uint8_t* bytes = point + field_->offset;
    switch (static_cast<PointFieldType>(field_->datatype)) {
      case PointFieldType::kInt8: return readValue<int8_t>(bytes, false);
      case PointFieldType::kUint8: return readValue<uint8_t>(bytes, false);
      case PointFieldType::kInt16: return readValue<int16_t>(bytes, swap_);
      case PointFieldType::kUint16: return readValue<uint16_t>(bytes, swap_);
      case PointFieldType::kInt32: return readValue<int32_t>(bytes, swap_);
      case PointFieldType::kUint32: return readValue<uint32_t>(bytes, swap_);
      case PointFieldType::kFloat32: return readValue<float>(bytes, swap_);
      case PointFieldType::kFloat64: return readValue<double>(bytes, swap_);
    }
    return std::numeric_limits<double>::quiet_NaN();
  }

 private:
  const PointFieldLayout* field_ = nullptr;
  bool swap_ = false;
};

enum class Allowed { kFloat, kInteger, kNumeric };

const char* allowedNames(Allowed allowed) {
  switch (allowed) {
    case Allowed::kFloat: return "float32 or float64";
    case Allowed::kInteger: return "an integer type";
    case Allowed::kNumeric: return "a numeric type";
  }
  return "";
}

// The field of that name checked against its convention; an empty reader when absent.
FieldReader findField(const PointCloudLayout& layout, const std::string& name, Allowed allowed, bool swap) {
  const PointFieldLayout* field = layout.find(name);
  if (!field) return {};
  const bool type_ok = (allowed != Allowed::kInteger && isFloat(field->datatype)) ||
                       (allowed != Allowed::kFloat && isInteger(field->datatype));
  if (!type_ok)
    fail("field '" + name + "' has type " + pointFieldTypeName(field->datatype) + " (" +
         std::to_string(field->datatype) + "), expected " + allowedNames(allowed));
  if (field->count == 0) fail("field '" + name + "' has count 0");
  if (std::uint64_t(field->offset) + pointFieldTypeSize(field->datatype) > layout.point_step)
    fail("field '" + name + "' at offset " + std::to_string(field->offset) + " (" +
         pointFieldTypeName(field->datatype) + ") does not fit in point_step " +
         std::to_string(layout.point_step));
  return FieldReader(*field, swap);
}

FieldReader requireField(const PointCloudLayout& layout, const std::string& name, Allowed allowed, bool swap) {
  FieldReader reader = findField(layout, name, allowed, swap);
  if (!reader) fail("required field '" + name + "' (" + allowedNames(allowed) + ") is missing");
  return reader;
}

// The first of names the cloud has.
FieldReader findFirst(const PointCloudLayout& layout, const std::vector<std::string>& names, Allowed allowed,
                      bool swap) {
  for (const std::string& name : names)
    if (FieldReader reader = findField(layout, name, allowed, swap)) return reader;
  return {};
}

void checkSizes(const PointCloudLayout& layout, std::size_t size) {
  const std::uint64_t points = std::uint64_t(layout.width) * layout.height;
  if (points == 0) return;
  if (layout.point_step == 0) fail("point_step is 0");
  if (std::uint64_t(layout.point_step) * layout.width > layout.row_step)
    fail("row_step " + std::to_string(layout.row_step) + " is smaller than width " +
         std::to_string(layout.width) + " * point_step " + std::to_string(layout.point_step));
  if (std::uint64_t(layout.row_step) * layout.height > size)
    fail("data has " + std::to_string(size) + " bytes, height " + std::to_string(layout.height) +
         " * row_step " + std::to_string(layout.row_step) + " needs more");
  if (layout.height > static_cast<uint32_t>(std::numeric_limits<int>::max()) ||
      layout.width > static_cast<uint32_t>(std::numeric_limits<int>::max()))
    fail("height x width " + std::to_string(layout.height) + " x " + std::to_string(layout.width) +
         " is too large");
}

bool isMeasured(const Eigen::Vector3f& point) {
  return point.allFinite() && !(point.x() == 0.0f && point.y() == 0.0f && point.z() == 0.0f);
}

}  // namespace

const char* pointFieldTypeName(uint8_t datatype) {
  switch (datatype) {
    case 1: return "int8";
    case 2: return "uint8";
    case 3: return "int16";
    case 4: return "uint16";
    case 5: return "int32";
    case 6: return "uint32";
    case 7: return "float32";
    case 8: return "float64";
    default: return "unknown";
  }
}

std::size_t pointFieldTypeSize(uint8_t datatype) {
  switch (datatype) {
    case 1:
    case 2: return 1;
    case 3:
    case 4: return 2;
    case 5:
    case 6:
    case 7: return 4;
    case 8: return 8;
    default: return 0;
  }
}

const PointFieldLayout* PointCloudLayout::find(const std::string& name) const {
  for (const PointFieldLayout& field : fields)
    if (field.name == name) return &field;
  return nullptr;
}

const std::vector<std::string>& intensityFieldNames() {
  static const std::vector<std::string> names = {"intensity", "reflectivity", "signal"};
  return names;
}

const std::vector<std::string>& ringFieldNames() {
  static const std::vector<std::string> names = {"ring", "channel"};
  return names;
}

const std::vector<std::string>& timeFieldNames() {
  static const std::vector<std::string> names = {"t",          "time",        "timestamp",
                                                 "time_stamp", "offset_time", "time_offset"};
  return names;
}

void readPointCloud(const PointCloudLayout& layout, const uint8_t* data, std::size_t size,
                    uint64_t header_stamp_ns, PointCloudInput& input, PointCloudReadReport* report) {
  checkSizes(layout, size);
  const bool swap = layout.is_bigendian != hostIsBigEndian();
  const FieldReader x = requireField(layout, "x", Allowed::kFloat, swap);
  const FieldReader y = requireField(layout, "y", Allowed::kFloat, swap);
  const FieldReader z = requireField(layout, "z", Allowed::kFloat, swap);
  const FieldReader intensity = findFirst(layout, intensityFieldNames(), Allowed::kNumeric, swap);
  const FieldReader ring = findFirst(layout, ringFieldNames(), Allowed::kInteger, swap);
  const FieldReader time = findFirst(layout, timeFieldNames(), Allowed::kNumeric, swap);

  const std::size_t count = std::size_t(layout.width) * layout.height;
  input.points.resize(count);
  input.intensity.resize(intensity ? count : 0);
  input.intensity_field = intensity ? intensity.field().name : "";
  input.ring.resize(ring ? count : 0);
  input.time_offset_s.resize(time ? count : 0);
  input.organized_height = static_cast<int>(layout.height);
  input.organized_width = static_cast<int>(layout.width);
  input.stamp_ns = header_stamp_ns;

  // Times are first read in their own unit, as doubles, into a scratch array
  // (absolute nanoseconds do not fit time_offset_s's float).
  thread_local std::vector<double> raw_time;
  raw_time.resize(time ? count : 0);
  PointCloudReadReport found;
  found.points = count;
  found.header_stamp_ns = header_stamp_ns;
  double earliest = std::numeric_limits<double>::infinity();
  double latest = -std::numeric_limits<double>::infinity();
  std::size_t i = 0;
  for (uint32_t row = 0; row < layout.height; ++row) {
    const uint8_t* point = data + std::size_t(row) * layout.row_step;
    for (uint32_t column = 0; column < layout.width; ++column, ++i, point += layout.point_step) {
      Eigen::Vector3f& p = input.points[i];
      p = Eigen::Vector3f(static_cast<float>(x.read(point)), static_cast<float>(y.read(point)),
                          static_cast<float>(z.read(point)));
      const bool measured = isMeasured(p);
      if (!measured) ++(p.allFinite() ? found.at_origin : found.non_finite);
      if (intensity) input.intensity[i] = static_cast<float>(intensity.read(point));
      if (ring) {
        const double value = ring.read(point);
        if (value < 0.0 || value > std::numeric_limits<uint16_t>::max())
          fail("field '" + ring.field().name + "' of point " + std::to_string(i) + " is " +
               std::to_string(static_cast<long long>(value)) + ", outside 0..65535");
        input.ring[i] = static_cast<uint16_t>(value);
      }
      if (time) {
        const double value = time.read(point);
        raw_time[i] = value;
        if (measured && std::isfinite(value)) {
          earliest = std::min(earliest, value);
          latest = std::max(latest, value);
        }
      }
    }
  }

  if (time) {
    found.time_field = time.field().name;
    const bool nanoseconds = isInteger(time.field().datatype) ||
                             std::max(std::abs(earliest), std::abs(latest)) > 1e12;
    found.time_unit_s = nanoseconds ? 1e-9 : 1.0;
    const double header_s = static_cast<double>(header_stamp_ns) * 1e-9;
    if (!std::isfinite(earliest)) {
      // No measured point has a time: nothing to read the scan time from.
      found.time_reference = PointTimeReference::kRelative;
      std::fill(input.time_offset_s.begin(), input.time_offset_s.end(), 0.0f);
    } else {
      const double earliest_s = earliest * found.time_unit_s;
      const bool absolute = std::abs(earliest_s - header_s) < std::abs(earliest_s);
      found.time_reference = absolute ? PointTimeReference::kAbsolute : PointTimeReference::kRelative;
      // The scan's stamp in nanoseconds; each offset is taken from the earliest
      // raw value first, so absolute times keep their precision.
      const double stamp_ns = absolute ? earliest_s * 1e9 : double(header_stamp_ns) + earliest_s * 1e9;
      input.stamp_ns = stamp_ns > 0.0 ? static_cast<uint64_t>(std::llround(stamp_ns)) : 0;
      for (std::size_t k = 0; k < count; ++k)
        input.time_offset_s[k] = static_cast<float>((raw_time[k] - earliest) * found.time_unit_s);
      found.time_span_s = (latest - earliest) * found.time_unit_s;
    }
  }
  found.intensity_field = input.intensity_field;
  found.ring_field = ring ? ring.field().name : "";
  found.stamp_from_header_ns = static_cast<int64_t>(input.stamp_ns) - static_cast<int64_t>(header_stamp_ns);
  if (report) *report = std::move(found);
}

}  // namespace range_image_mapping
