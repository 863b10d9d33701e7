#include "range_image_mapping/io/pcd.h"

#include "../sensor/little_endian.h"

#include <cmath>
#include <cstring>
#include <fstream>
#include <iomanip>
#include <iterator>
#include <sstream>
#include <vector>

namespace range_image_mapping::io {
namespace {

struct PcdHeader {
  std::vector<std::string> names;
  std::vector<uint32_t> sizes;
  std::vector<char> types;
  std::vector<uint32_t> counts;
  uint32_t width = 0;
  uint32_t height = 1;
  uint64_t points = 0;
  bool has_points = false;
  std::string data;
};

class Failure {
 public:
  explicit Failure(const std::string& path) : path_(path) {}
  [[noreturn]] void operator()(const std::string& what) const { throw PcdFormatError("PCD " + path_ + ": " + what); }

 private:
  std::string path_;
};

std::vector<std::string> words(const std::string& line) {
  std::istringstream stream(line);
  std::vector<std::string> out;
  for (std::string word; stream >> word;) out.push_back(word);
  return out;
}

uint64_t parseCount(const std::string& word, const std::string& key, const Failure& fail) {
  try {
    std::size_t used = 0;
    const long long value = std::stoll(word, &used);
    if (used == word.size() && value >= 0) return static_cast<uint64_t>(value);
  } catch (const std::exception&) {
  }
  fail(key + " value '" + word + "' is not a non-negative integer");
}

// The header up to and including the DATA line; offset is where the data starts.
PcdHeader readHeader(const std::string& bytes, std::size_t& offset, const Failure& fail) {
  PcdHeader header;
  offset = 0;
  int line_number = 0;
  while (offset < bytes.size()) {
    const std::size_t end = bytes.find('\n', offset);
    const std::string line = bytes.substr(offset, end == std::string::npos ? std::string::npos : end - offset);
    offset = end == std::string::npos ? bytes.size() : end + 1;
    ++line_number;
    std::vector<std::string> items = words(line.substr(0, line.find('#')));
    if (items.empty()) continue;
    const std::string key = items.front();
    items.erase(items.begin());
    const std::string where = "line " + std::to_string(line_number) + " (" + key + ")";
    if (key == "VERSION" || key == "VIEWPOINT") continue;
    if (key == "FIELDS" || key == "COLUMNS") {
      header.names = items;
    } else if (key == "SIZE") {
      for (const std::string& item : items) header.sizes.push_back(uint32_t(parseCount(item, where, fail)));
    } else if (key == "TYPE") {
      for (const std::string& item : items) {
        if (item.size() != 1 || (item[0] != 'F' && item[0] != 'I' && item[0] != 'U'))
          fail(where + ": type '" + item + "' is not F, I or U");
        header.types.push_back(item[0]);
      }
    } else if (key == "COUNT") {
      for (const std::string& item : items) header.counts.push_back(uint32_t(parseCount(item, where, fail)));
    } else if (key == "WIDTH" && items.size() == 1) {
      header.width = uint32_t(parseCount(items[0], where, fail));
    } else if (key == "HEIGHT" && items.size() == 1) {
      header.height = uint32_t(parseCount(items[0], where, fail));
    } else if (key == "POINTS" && items.size() == 1) {
      header.points = parseCount(items[0], where, fail);
      header.has_points = true;
    } else if (key == "DATA" && items.size() == 1) {
      header.data = items[0];
      return header;
    } else {
      fail(where + ": unknown header line '" + line + "'");
    }
  }
  fail("the header has no DATA line (not a PCD file?)");
}

// The PointField type of a PCD TYPE and SIZE.
uint8_t fieldType(char type, uint32_t size, const std::string& name, const Failure& fail) {
  const auto is = [](PointFieldType t) { return static_cast<uint8_t>(t); };
  if (type == 'F' && size == 4) return is(PointFieldType::kFloat32);
  if (type == 'F' && size == 8) return is(PointFieldType::kFloat64);
  if (type == 'I' && size == 1) return is(PointFieldType::kInt8);
  if (type == 'I' && size == 2) return is(PointFieldType::kInt16);
  if (type == 'I' && size == 4) return is(PointFieldType::kInt32);
  if (type == 'U' && size == 1) return is(PointFieldType::kUint8);
  if (type == 'U' && size == 2) return is(PointFieldType::kUint16);
  if (type == 'U' && size == 4) return is(PointFieldType::kUint32);
  fail("field '" + name + "' has TYPE " + type + " SIZE " + std::to_string(size) +
       ", which no point field has (F 4/8, I or U 1/2/4)");
}

PointCloudLayout layoutOf(const PcdHeader& header, const Failure& fail) {
  const std::size_t fields = header.names.size();
  if (fields == 0) fail("the header has no FIELDS line");
  if (header.sizes.size() != fields || header.types.size() != fields)
    fail("FIELDS names " + std::to_string(fields) + " fields, SIZE gives " + std::to_string(header.sizes.size()) +
         " and TYPE " + std::to_string(header.types.size()));
  if (!header.counts.empty() && header.counts.size() != fields)
    fail("FIELDS names " + std::to_string(fields) + " fields, COUNT gives " + std::to_string(header.counts.size()));
  PointCloudLayout layout;
  uint32_t offset = 0;
  for (std::size_t i = 0; i < fields; ++i) {
    const uint32_t count = header.counts.empty() ? 1 : header.counts[i];
    if (count == 0) fail("field '" + header.names[i] + "' has COUNT 0");
    layout.fields.push_back({header.names[i], offset, fieldType(header.types[i], header.sizes[i], header.names[i], fail),
                             count});
    offset += header.sizes[i] * count;
  }
  if (header.width == 0 && header.points > 0) fail("WIDTH is missing or 0");
  const uint64_t points = uint64_t(header.width) * header.height;
  if (header.has_points && header.points != points)
    fail("POINTS " + std::to_string(header.points) + " is not WIDTH x HEIGHT " + std::to_string(header.width) + " x " +
         std::to_string(header.height));
  layout.width = header.width;
  layout.height = header.height;
  layout.point_step = offset;
  layout.row_step = offset * header.width;
  layout.is_bigendian = false;
  return layout;
}

// One ASCII value into its binary form at out.
void putValue(uint8_t datatype, double value, uint8_t* out) {
  switch (static_cast<PointFieldType>(datatype)) {
    case PointFieldType::kInt8: { const int8_t v = int8_t(value); std::memcpy(out, &v, 1); break; }
    case PointFieldType::kUint8: { const uint8_t v = uint8_t(value); std::memcpy(out, &v, 1); break; }
    case PointFieldType::kInt16: { const int16_t v = int16_t(value); std::memcpy(out, &v, 2); break; }
    case PointFieldType::kUint16: { const uint16_t v = uint16_t(value); std::memcpy(out, &v, 2); break; }
    case PointFieldType::kInt32: { const int32_t v = int32_t(value); std::memcpy(out, &v, 4); break; }
    case PointFieldType::kUint32: { const uint32_t v = uint32_t(value); std::memcpy(out, &v, 4); break; }
    case PointFieldType::kFloat32: { const float v = float(value); std::memcpy(out, &v, 4); break; }
    case PointFieldType::kFloat64: std::memcpy(out, &value, 8); break;
  }
}

std::vector<uint8_t> asciiData(const std::string& bytes, std::size_t offset, const PointCloudLayout& layout,
                               const Failure& fail) {
  const std::size_t points = std::size_t(layout.width) * layout.height;
  std::vector<uint8_t> data(points * layout.point_step, 0);
  std::istringstream stream(bytes.substr(offset));
  std::string line;
  for (std::size_t i = 0; i < points; ++i) {
    do {
      if (!std::getline(stream, line))
        fail("the data ends after " + std::to_string(i) + " of " + std::to_string(points) + " points");
    } while (line.find_first_not_of(" \t\r") == std::string::npos);
    const char* cursor = line.c_str();
    for (const PointFieldLayout& field : layout.fields) {
      const std::size_t size = pointFieldTypeSize(field.datatype);
      for (uint32_t k = 0; k < field.count; ++k) {
        char* end = nullptr;
        const double value = std::strtod(cursor, &end);
        if (end == cursor)
          fail("point " + std::to_string(i) + " (data line " + std::to_string(i + 1) + "): no value for field '" +
               field.name + "'");
        cursor = end;
        putValue(field.datatype, value, data.data() + i * layout.point_step + field.offset + k * size);
      }
    }
    while (*cursor == ' ' || *cursor == '\t' || *cursor == '\r') ++cursor;
    if (*cursor != '\0')
      fail("point " + std::to_string(i) + " (data line " + std::to_string(i + 1) + ") has more values than the " +
           std::to_string(layout.fields.size()) + " fields");
  }
  return data;
}

// LZF (liblzf's format, which PCL's binary_compressed uses): literal runs and
// back references. Returns false on corrupt input.
bool lzfDecompress(const uint8_t* in, std::size_t in_size, uint8_t* out, std::size_t out_size) {
  std::size_t i = 0, o = 0;
  while (i < in_size) {
    const unsigned control = in[i++];
    if (control < 32) {  // literal run of control + 1 bytes
      const std::size_t length = control + 1;
      if (i + length > in_size || o + length > out_size) return false;
      std::memcpy(out + o, in + i, length);
      i += length;
      o += length;
    } else {  // back reference
      std::size_t length = control >> 5;
      if (length == 7) {
        if (i >= in_size) return false;
        length += in[i++];
      }
      length += 2;
      if (i >= in_size) return false;
      const std::size_t distance = ((control & 0x1f) << 8) + in[i++] + 1;
      if (distance > o || o + length > out_size) return false;
      for (std::size_t k = 0; k < length; ++k, ++o) out[o] = out[o - distance];
    }
  }
  return o == out_size;
}

// binary_compressed: uint32 compressed and uncompressed sizes, then LZF of the
// fields one after the other (all x, then all y, ...), back into packed points.
std::vector<uint8_t> compressedData(const std::string& bytes, std::size_t offset, const PointCloudLayout& layout,
                                    const Failure& fail) {
  if (bytes.size() < offset + 8) fail("binary_compressed data has no size header");
  const uint32_t compressed = readLittleEndian<uint32_t>(bytes.data() + offset);
  const uint32_t uncompressed = readLittleEndian<uint32_t>(bytes.data() + offset + 4);
  const std::size_t points = std::size_t(layout.width) * layout.height;
  if (uncompressed != points * layout.point_step)
    fail("binary_compressed data unpacks to " + std::to_string(uncompressed) + " bytes, the header's points need " +
         std::to_string(points * layout.point_step));
  if (bytes.size() < offset + 8 + compressed)
    fail("binary_compressed data has " + std::to_string(bytes.size() - offset - 8) + " bytes, the header says " +
         std::to_string(compressed));
  std::vector<uint8_t> by_field(uncompressed);
  if (!lzfDecompress(reinterpret_cast<const uint8_t*>(bytes.data()) + offset + 8, compressed, by_field.data(),
                     by_field.size()))
    fail("binary_compressed data is corrupt (LZF)");
  std::vector<uint8_t> data(uncompressed);
  std::size_t start = 0;
  for (const PointFieldLayout& field : layout.fields) {
    const std::size_t size = pointFieldTypeSize(field.datatype) * field.count;
    for (std::size_t i = 0; i < points; ++i)
      std::memcpy(data.data() + i * layout.point_step + field.offset, by_field.data() + start + i * size, size);
    start += points * size;
  }
  return data;
}

}  // namespace

PointCloudInput readPcd(const std::string& path, uint64_t stamp_ns, PointCloudReadReport* report) {
  const Failure fail(path);
  std::ifstream file(path, std::ios::binary);
  if (!file) fail("cannot open the file");
  const std::string bytes((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  std::size_t offset = 0;
  const PcdHeader header = readHeader(bytes, offset, fail);
  const PointCloudLayout layout = layoutOf(header, fail);
  const std::size_t needed = std::size_t(layout.width) * layout.height * layout.point_step;
  std::vector<uint8_t> converted;
  const uint8_t* data = nullptr;
  std::size_t size = 0;
  if (header.data == "ascii") {
    converted = asciiData(bytes, offset, layout, fail);
  } else if (header.data == "binary") {
    if (bytes.size() - offset < needed)
      fail("binary data has " + std::to_string(bytes.size() - offset) + " bytes, " + std::to_string(header.width) +
           " x " + std::to_string(header.height) + " points of " + std::to_string(layout.point_step) +
           " bytes need " + std::to_string(needed));
    data = reinterpret_cast<const uint8_t*>(bytes.data()) + offset;
    size = bytes.size() - offset;
  } else if (header.data == "binary_compressed") {
    converted = compressedData(bytes, offset, layout, fail);
  } else {
    fail("DATA '" + header.data + "' is none of ascii, binary, binary_compressed");
  }
  if (!data) {
    data = converted.data();
    size = converted.size();
  }
  PointCloudInput cloud;
  try {
    readPointCloud(layout, data, size, stamp_ns, cloud, report);
  } catch (const PointCloudLayoutError& error) {
    fail(error.what());
  }
  return cloud;
}

void writePcd(const std::string& path, const PointCloudInput& cloud, PcdEncoding encoding) {
  cloud.validate();
  const bool intensity = !cloud.intensity.empty(), ring = !cloud.ring.empty(), time = !cloud.time_offset_s.empty();
  const uint32_t height = cloud.isOrganized() ? uint32_t(cloud.organized_height) : 1;
  const uint32_t width = cloud.isOrganized() ? uint32_t(cloud.organized_width) : uint32_t(cloud.size());
  std::ostringstream text;
  text << "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z" << (intensity ? " intensity" : "")
       << (ring ? " ring" : "") << (time ? " time" : "") << "\nSIZE 4 4 4" << (intensity ? " 4" : "")
       << (ring ? " 2" : "") << (time ? " 4" : "") << "\nTYPE F F F" << (intensity ? " F" : "") << (ring ? " U" : "")
       << (time ? " F" : "") << "\nCOUNT 1 1 1" << (intensity ? " 1" : "") << (ring ? " 1" : "")
       << (time ? " 1" : "") << "\nWIDTH " << width << "\nHEIGHT " << height
       << "\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " << cloud.size() << "\nDATA "
       << (encoding == PcdEncoding::kAscii ? "ascii" : "binary") << "\n";
  std::string bytes = text.str();
  std::ostringstream lines;
  lines << std::setprecision(9);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3f& p = cloud.points[i];
    if (encoding == PcdEncoding::kAscii) {
      lines << p.x() << ' ' << p.y() << ' ' << p.z();
      if (intensity) lines << ' ' << cloud.intensity[i];
      if (ring) lines << ' ' << cloud.ring[i];
      if (time) lines << ' ' << cloud.time_offset_s[i];
      lines << '\n';
    } else {
      for (int axis = 0; axis < 3; ++axis) appendLittleEndian<float>(bytes, p[axis]);
      if (intensity) appendLittleEndian<float>(bytes, cloud.intensity[i]);
      if (ring) appendLittleEndian<uint16_t>(bytes, cloud.ring[i]);
      if (time) appendLittleEndian<float>(bytes, cloud.time_offset_s[i]);
    }
  }
  bytes += lines.str();
  std::ofstream file(path, std::ios::binary);
  if (!file) throw PcdFormatError("PCD " + path + ": cannot write the file");
  file.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!file.flush()) throw PcdFormatError("PCD " + path + ": writing failed");
}

}  // namespace range_image_mapping::io
