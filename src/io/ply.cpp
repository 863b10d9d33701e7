#include "range_image_mapping/io/ply.h"

#include "../sensor/little_endian.h"
#include "triangle_fan.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <iterator>
#include <limits>
#include <optional>
#include <sstream>

namespace range_image_mapping::io {
namespace {

// ---------------------------------------------------------------- scalar types

enum class ScalarType { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

struct ScalarTypeName {
  const char* name;
  ScalarType type;
};
// Both spellings the PLY specification and common writers use.
constexpr std::array<ScalarTypeName, 16> kScalarTypeNames{{
    {"char", ScalarType::kInt8},
    {"int8", ScalarType::kInt8},
    {"uchar", ScalarType::kUint8},
    {"uint8", ScalarType::kUint8},
    {"short", ScalarType::kInt16},
    {"int16", ScalarType::kInt16},
    {"ushort", ScalarType::kUint16},
    {"uint16", ScalarType::kUint16},
    {"int", ScalarType::kInt32},
    {"int32", ScalarType::kInt32},
    {"uint", ScalarType::kUint32},
    {"uint32", ScalarType::kUint32},
    {"float", ScalarType::kFloat32},
    {"float32", ScalarType::kFloat32},
    {"double", ScalarType::kFloat64},
    {"float64", ScalarType::kFloat64},
}};

std::optional<ScalarType> scalarTypeOf(const std::string& name) {
  for (const ScalarTypeName& entry : kScalarTypeNames)
    if (name == entry.name) return entry.type;
  return std::nullopt;
}

std::size_t sizeOf(ScalarType type) {
  switch (type) {
    case ScalarType::kInt8:
    case ScalarType::kUint8:
      return 1;
    case ScalarType::kInt16:
    case ScalarType::kUint16:
      return 2;
    case ScalarType::kInt32:
    case ScalarType::kUint32:
    case ScalarType::kFloat32:
      return 4;
    case ScalarType::kFloat64:
      return 8;
  }
  return 0;
}

double readBinaryScalar(ScalarType type, const char* bytes) {
  switch (type) {
    case ScalarType::kInt8:
      return readLittleEndian<int8_t>(bytes);
    case ScalarType::kUint8:
      return readLittleEndian<uint8_t>(bytes);
    case ScalarType::kInt16:
      return readLittleEndian<int16_t>(bytes);
    case ScalarType::kUint16:
      return readLittleEndian<uint16_t>(bytes);
    case ScalarType::kInt32:
      return readLittleEndian<int32_t>(bytes);
    case ScalarType::kUint32:
      return readLittleEndian<uint32_t>(bytes);
    case ScalarType::kFloat32:
      return readLittleEndian<float>(bytes);
    case ScalarType::kFloat64:
      return readLittleEndian<double>(bytes);
  }
  return 0.0;
}

// ---------------------------------------------------------------- header

struct Property {
  std::string name;
  ScalarType type = ScalarType::kFloat32;
  std::optional<ScalarType> list_count_type;  // set for "property list <count> <item> name"
};

struct Element {
  std::string name;
  std::size_t count = 0;
  std::vector<Property> properties;
};

enum class Encoding { kAscii, kBinaryLittleEndian };

struct Header {
  Encoding encoding = Encoding::kAscii;
  std::vector<Element> elements;
  std::size_t body_offset = 0;  // first byte after "end_header\n"
};

class HeaderParser {
 public:
  HeaderParser(const std::string& path, const std::string& bytes) : path_(path), bytes_(bytes) {}

  Header parse() {
    Header header;
    if (!nextLine() || line_ != "ply") fail("does not start with \"ply\"");
    bool have_format = false;
    while (true) {
      if (!nextLine()) fail("has no end_header line");
      std::istringstream words(line_);
      std::string keyword;
      words >> keyword;
      if (keyword.empty() || keyword == "comment" || keyword == "obj_info") continue;
      if (keyword == "end_header") break;
      if (keyword == "format") {
        std::string encoding, version;
        words >> encoding >> version;
        if (encoding == "ascii")
          header.encoding = Encoding::kAscii;
        else if (encoding == "binary_little_endian")
          header.encoding = Encoding::kBinaryLittleEndian;
        else if (encoding == "binary_big_endian")
          fail("uses binary_big_endian, which is not supported");
        else
          fail("has an unknown format \"" + encoding + "\"");
        if (version != "1.0") fail("has format version \"" + version + "\", expected 1.0");
        have_format = true;
      } else if (keyword == "element") {
        Element element;
        long long count = -1;
        if (!(words >> element.name >> count) || count < 0)
          fail("has an element without a valid count");
        element.count = static_cast<std::size_t>(count);
        header.elements.push_back(element);
      } else if (keyword == "property") {
        if (header.elements.empty()) fail("has a property before any element");
        header.elements.back().properties.push_back(parseProperty(words));
      } else {
        fail("has an unknown header keyword \"" + keyword + "\"");
      }
    }
    if (!have_format) fail("has no format line");
    header.body_offset = position_;
    return header;
  }

 private:
  Property parseProperty(std::istringstream& words) {
    Property property;
    std::string type_name;
    words >> type_name;
    if (type_name == "list") {
      std::string count_name, item_name;
      words >> count_name >> item_name;
      property.list_count_type = scalarType(count_name);
      property.type = scalarType(item_name);
      if (*property.list_count_type == ScalarType::kFloat32 ||
          *property.list_count_type == ScalarType::kFloat64)
        fail("has a list with a floating-point count type");
    } else {
      property.type = scalarType(type_name);
    }
    if (!(words >> property.name)) fail("has a property without a name");
    return property;
  }

  ScalarType scalarType(const std::string& name) {
    const std::optional<ScalarType> type = scalarTypeOf(name);
    if (!type) fail("has an unknown property type \"" + name + "\"");
    return *type;
  }

  bool nextLine() {
    if (position_ >= bytes_.size()) return false;
    const std::size_t end = bytes_.find('\n', position_);
    if (end == std::string::npos) return false;
    line_ = bytes_.substr(position_, end - position_);
    if (!line_.empty() && line_.back() == '\r') line_.pop_back();
    position_ = end + 1;
    ++line_number_;
    return true;
  }

  [[noreturn]] void fail(const std::string& problem) const {
    throw PlyFormatError("PLY: " + path_ + ": header line " + std::to_string(line_number_) + " " +
                         problem);
  }

  const std::string& path_;
  const std::string& bytes_;
  std::size_t position_ = 0;
  std::string line_;
  int line_number_ = 0;
};

// ---------------------------------------------------------------- body

// Walks the body value by value, in either encoding; every read is bounds checked.
class BodyReader {
 public:
  BodyReader(const std::string& path, const std::string& bytes, const Header& header)
      : path_(path), bytes_(bytes), encoding_(header.encoding), position_(header.body_offset) {}

  double scalar(ScalarType type) {
    if (encoding_ == Encoding::kBinaryLittleEndian) {
      const std::size_t size = sizeOf(type);
      if (bytes_.size() - position_ < size) fail("ends in the middle of the data");
      const double value = readBinaryScalar(type, bytes_.data() + position_);
      position_ += size;
      return value;
    }
    position_ = bytes_.find_first_not_of(" \t\r\n", position_);
    if (position_ == std::string::npos) fail("ends in the middle of the data");
    const char* start = bytes_.c_str() + position_;
    char* end = nullptr;
    errno = 0;
    const double value = std::strtod(start, &end);
    if (end == start || errno == ERANGE)
      fail("has a value that is not a number at byte " + std::to_string(position_));
    position_ += static_cast<std::size_t>(end - start);
    return value;
  }

  // Reads one element instance; hands each scalar property's value to `use`
  // and each list property's items to `use_list`.
  template <typename Use, typename UseList>
  void instance(const Element& element, Use&& use, UseList&& use_list) {
    for (std::size_t p = 0; p < element.properties.size(); ++p) {
      const Property& property = element.properties[p];
      if (property.list_count_type) {
        const double count = scalar(*property.list_count_type);
        if (count < 0) fail("has a negative list length");
        // Every item takes at least a byte: a huge count cannot allocate beyond the file.
        if (count > static_cast<double>(remainingBytes()))
          fail("has a list of " + std::to_string(static_cast<long long>(count)) +
               " items but only " + std::to_string(remainingBytes()) + " bytes left");
        list_.resize(static_cast<std::size_t>(count));
        for (double& item : list_) item = scalar(property.type);
        use_list(p, list_);
      } else {
        use(p, scalar(property.type));
      }
    }
  }
  template <typename Use>
  void instance(const Element& element, Use&& use) {
    instance(element, use, [](std::size_t, const std::vector<double>&) {});
  }

  std::size_t remainingBytes() const { return bytes_.size() - position_; }

  [[noreturn]] void fail(const std::string& problem) const {
    throw PlyFormatError("PLY: " + path_ + " " + problem + lineSuffix());
  }

 private:
  // ASCII bodies are edited by hand, so their errors name the line.
  std::string lineSuffix() const {
    if (encoding_ != Encoding::kAscii) return "";
    const auto end =
        bytes_.begin() + static_cast<std::ptrdiff_t>(std::min(position_, bytes_.size()));
    return " (line " + std::to_string(1 + std::count(bytes_.begin(), end, '\n')) + ")";
  }

  const std::string& path_;
  const std::string& bytes_;
  Encoding encoding_;
  std::size_t position_;
  std::vector<double> list_;  // reused for every list, so faces do not allocate
};

// Integers as integers (list items arrive as double), anything else as it is.
std::string numberText(double value) {
  std::ostringstream text;
  text << std::setprecision(15) << value;
  return text.str();
}

std::string readWholeFile(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) throw PlyFormatError("PLY: cannot open " + path);
  return std::string((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
}

// ---------------------------------------------------------------- vertex positions

struct VertexPositions {
  std::vector<Element>::const_iterator element;
  std::array<std::size_t, 3> property{};  // index of x, y, z among the vertex properties
};

VertexPositions findVertexPositions(const std::string& path, const Header& header) {
  VertexPositions positions;
  positions.element = std::find_if(header.elements.begin(), header.elements.end(),
                                   [](const Element& element) { return element.name == "vertex"; });
  if (positions.element == header.elements.end())
    throw PlyFormatError("PLY: " + path + " has no vertex element");
  const std::array<const char*, 3> axis_names{"x", "y", "z"};
  const auto& properties = positions.element->properties;
  for (int axis = 0; axis < 3; ++axis) {
    const auto found =
        std::find_if(properties.begin(), properties.end(), [&](const Property& property) {
          return property.name == axis_names[axis] && !property.list_count_type;
        });
    if (found == properties.end())
      throw PlyFormatError("PLY: " + path + " has no scalar vertex property " + axis_names[axis]);
    positions.property[axis] = static_cast<std::size_t>(found - properties.begin());
  }
  return positions;
}

// Reads the vertex element; the body must be positioned at its start.
std::vector<Eigen::Vector3f> readVertexPositions(BodyReader& body,
                                                 const VertexPositions& positions) {
  // Every vertex takes at least a byte, so a count beyond the file is caught
  // before it turns into a huge allocation.
  if (positions.element->count > body.remainingBytes())
    body.fail("declares " + std::to_string(positions.element->count) + " vertices but has only " +
              std::to_string(body.remainingBytes()) + " bytes of data");
  std::vector<Eigen::Vector3f> points(positions.element->count);
  for (std::size_t i = 0; i < points.size(); ++i) {
    body.instance(*positions.element, [&](std::size_t property, double value) {
      for (int axis = 0; axis < 3; ++axis)
        if (property == positions.property[axis]) points[i][axis] = static_cast<float>(value);
    });
  }
  return points;
}

// ---------------------------------------------------------------- writing

const char* plyTypeName(const PlyProperty& property) {
  static constexpr std::array<const char*, 4> kNames{"uchar", "ushort", "int", "float"};
  return kNames[property.values.index()];
}

std::size_t propertySize(const PlyProperty& property) {
  return std::visit([](const auto& values) { return values.size(); }, property.values);
}

void appendPoint(std::string& buffer, const Eigen::Vector3f& point) {
  for (int axis = 0; axis < 3; ++axis) appendLittleEndian(buffer, point[axis]);
}

// The header lines of the extra per-vertex properties; throws
// std::invalid_argument (naming `writer`) for an empty, spaced or repeated
// name, or a value count other than one per vertex.
std::string extraPropertyHeader(const char* writer, const std::vector<PlyProperty>& properties,
                                std::size_t vertex_count, std::vector<std::string> names) {
  std::ostringstream header;
  for (const PlyProperty& property : properties) {
    if (property.name.empty() || property.name.find_first_of(" \t\r\n") != std::string::npos)
      throw std::invalid_argument(std::string(writer) + ": property name \"" + property.name +
                                  "\" is empty or has white space");
    if (std::find(names.begin(), names.end(), property.name) != names.end())
      throw std::invalid_argument(std::string(writer) + ": property \"" + property.name +
                                  "\" appears twice");
    names.push_back(property.name);
    if (propertySize(property) != vertex_count)
      throw std::invalid_argument(std::string(writer) + ": property \"" + property.name +
                                  "\" has " + std::to_string(propertySize(property)) +
                                  " values for " + std::to_string(vertex_count) + " vertices");
    header << "property " << plyTypeName(property) << ' ' << property.name << '\n';
  }
  return header.str();
}

void appendExtraProperties(std::string& buffer, const std::vector<PlyProperty>& properties,
                           std::size_t vertex) {
  for (const PlyProperty& property : properties)
    std::visit([&](const auto& values) { appendLittleEndian(buffer, values[vertex]); },
               property.values);
}

// Writes in pieces so large clouds never need a second full copy in memory.
class BinaryFileWriter {
 public:
  BinaryFileWriter(const std::string& path, const std::string& header)
      : path_(path), file_(path, std::ios::binary) {
    if (!file_) throw PlyFormatError("PLY: cannot write " + path);
    buffer_ = header;
  }
  std::string& buffer() { return buffer_; }
  void flushIfLarge() {
    if (buffer_.size() >= (std::size_t(1) << 20)) flush();
  }
  void finish() {
    flush();
    file_.close();
    if (!file_) throw PlyFormatError("PLY: writing " + path_ + " failed");
  }

 private:
  void flush() {
    file_.write(buffer_.data(), static_cast<std::streamsize>(buffer_.size()));
    buffer_.clear();
  }
  std::string path_;
  std::ofstream file_;
  std::string buffer_;
};

}  // namespace

void writePlyPointCloud(const std::string& path, const std::vector<Eigen::Vector3f>& points,
                        const std::vector<PlyProperty>& properties) {
  std::ostringstream header;
  header << "ply\nformat binary_little_endian 1.0\nelement vertex " << points.size()
         << "\nproperty float x\nproperty float y\nproperty float z\n";
  header << extraPropertyHeader("writePlyPointCloud", properties, points.size(), {"x", "y", "z"});
  header << "end_header\n";

  BinaryFileWriter writer(path, header.str());
  for (std::size_t i = 0; i < points.size(); ++i) {
    appendPoint(writer.buffer(), points[i]);
    appendExtraProperties(writer.buffer(), properties, i);
    writer.flushIfLarge();
  }
  writer.finish();
}

void writePlyMesh(const std::string& path, const std::vector<Eigen::Vector3f>& vertices,
                  const std::vector<Eigen::Vector3f>& normals,
                  const std::vector<Eigen::Vector3i>& triangles) {
  writePlyMesh(path, vertices, normals, triangles, {});
}

void writePlyMesh(const std::string& path, const std::vector<Eigen::Vector3f>& vertices,
                  const std::vector<Eigen::Vector3f>& normals,
                  const std::vector<Eigen::Vector3i>& triangles,
                  const std::vector<PlyProperty>& vertex_properties) {
  if (!normals.empty() && normals.size() != vertices.size())
    throw std::invalid_argument("writePlyMesh: " + std::to_string(normals.size()) +
                                " normals for " + std::to_string(vertices.size()) + " vertices");
  const auto vertex_count = static_cast<long long>(vertices.size());
  for (std::size_t t = 0; t < triangles.size(); ++t)
    for (int corner = 0; corner < 3; ++corner)
      if (triangles[t][corner] < 0 || triangles[t][corner] >= vertex_count)
        throw std::invalid_argument("writePlyMesh: triangle " + std::to_string(t) +
                                    " refers to vertex " + std::to_string(triangles[t][corner]) +
                                    " of " + std::to_string(vertices.size()));
  std::ostringstream header;
  header << "ply\nformat binary_little_endian 1.0\nelement vertex " << vertices.size()
         << "\nproperty float x\nproperty float y\nproperty float z\n";
  if (!normals.empty()) header << "property float nx\nproperty float ny\nproperty float nz\n";
  header << extraPropertyHeader("writePlyMesh", vertex_properties, vertices.size(),
                                {"x", "y", "z", "nx", "ny", "nz"});
  header << "element face " << triangles.size()
         << "\nproperty list uchar int vertex_indices\nend_header\n";

  BinaryFileWriter writer(path, header.str());
  for (std::size_t i = 0; i < vertices.size(); ++i) {
    appendPoint(writer.buffer(), vertices[i]);
    if (!normals.empty()) appendPoint(writer.buffer(), normals[i]);
    appendExtraProperties(writer.buffer(), vertex_properties, i);
    writer.flushIfLarge();
  }
  for (const Eigen::Vector3i& triangle : triangles) {
    appendLittleEndian<uint8_t>(writer.buffer(), 3);
    for (int corner = 0; corner < 3; ++corner)
      appendLittleEndian<int32_t>(writer.buffer(), triangle[corner]);
    writer.flushIfLarge();
  }
  writer.finish();
}

std::vector<Eigen::Vector3f> readPlyPoints(const std::string& path) {
  const std::string bytes = readWholeFile(path);
  const Header header = HeaderParser(path, bytes).parse();
  const VertexPositions positions = findVertexPositions(path, header);

  BodyReader body(path, bytes, header);
  const auto ignore = [](std::size_t, double) {};
  for (auto element = header.elements.begin(); element != positions.element; ++element)
    for (std::size_t i = 0; i < element->count; ++i) body.instance(*element, ignore);
  return readVertexPositions(body, positions);
}

TriangleMesh readPlyMesh(const std::string& path) {
  const std::string bytes = readWholeFile(path);
  const Header header = HeaderParser(path, bytes).parse();
  const VertexPositions positions = findVertexPositions(path, header);
  const std::size_t vertex_count = positions.element->count;

  TriangleMesh mesh;
  bool have_faces = false;
  BodyReader body(path, bytes, header);
  std::vector<int> polygon;
  for (auto element = header.elements.begin(); element != header.elements.end(); ++element) {
    if (element == positions.element) {
      mesh.vertices = readVertexPositions(body, positions);
      continue;
    }
    const auto corners = element->name == "face"
                             ? std::find_if(element->properties.begin(), element->properties.end(),
                                            [](const Property& property) {
                                              return property.list_count_type &&
                                                     (property.name == "vertex_indices" ||
                                                      property.name == "vertex_index");
                                            })
                             : element->properties.end();
    const auto ignore = [](std::size_t, double) {};
    if (corners == element->properties.end()) {
      for (std::size_t i = 0; i < element->count; ++i) body.instance(*element, ignore);
      continue;
    }
    have_faces = true;
    const auto corners_property = static_cast<std::size_t>(corners - element->properties.begin());
    // Two triangles per face is a fair guess; the byte count bounds a hostile face count.
    mesh.triangles.reserve(std::min(element->count, body.remainingBytes()) * 2);
    for (std::size_t face = 0; face < element->count; ++face) {
      body.instance(*element, ignore, [&](std::size_t property, const std::vector<double>& items) {
        if (property != corners_property) return;
        if (items.size() < 3)
          body.fail("face " + std::to_string(face) + " has " + std::to_string(items.size()) +
                    " vertices; a face needs at least 3");
        polygon.clear();
        for (const double index : items) {
          if (index < 0 || index >= static_cast<double>(vertex_count) || index != std::floor(index))
            body.fail("face " + std::to_string(face) + " refers to vertex " + numberText(index) +
                      " of " + std::to_string(vertex_count));
          polygon.push_back(static_cast<int>(index));
        }
        appendTriangleFan(polygon, mesh.triangles);
      });
    }
  }
  if (!have_faces)
    throw PlyFormatError("PLY: " + path + " has no face element with a vertex_indices list");
  return mesh;
}

}  // namespace range_image_mapping::io
