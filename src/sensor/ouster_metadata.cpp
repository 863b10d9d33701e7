#include "range_image_mapping/ouster_metadata.h"

#include <json/json.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <initializer_list>
#include <memory>
#include <sstream>

namespace range_image_mapping {
namespace {

constexpr double kDegreesToRadians = M_PI / 180.0;
constexpr double kMillimetresToMetres = 0.001;

[[noreturn]] void fail(const std::string& problem) { throw MetadataError("metadata: " + problem); }

std::string quoted(const std::string& text) {
  // Long garbage would drown the message; the start is enough to recognise it.
  constexpr std::size_t kMaxShown = 40;
  return "'" + (text.size() > kMaxShown ? text.substr(0, kMaxShown) + "..." : text) + "'";
}

// The nested format keeps each field in a section; the flat one keeps it at the
// top level (section ""), except the data format fields, which sit in "data_format".
constexpr const char* kTopLevel = "";

const Json::Value* findField(const Json::Value& root, std::initializer_list<const char*> sections,
                             const char* key) {
  for (const char* section : sections) {
    const Json::Value* object = &root;
    if (*section != '\0') {
      object = root.find(section, section + std::strlen(section));
      if (object == nullptr || !object->isObject()) continue;
    }
    if (const Json::Value* value = object->find(key, key + std::strlen(key))) {
      if (!value->isNull()) return value;
    }
  }
  return nullptr;
}

int integerField(const Json::Value& value, const char* name) {
  if (!value.isInt()) fail(std::string(name) + " must be an integer");
  return value.asInt();
}

double numberField(const Json::Value& value, const std::string& name) {
  if (!value.isNumeric()) fail(name + " must be a number");
  const double number = value.asDouble();
  if (!std::isfinite(number)) fail(name + " is not finite");
  return number;
}

std::string stringField(const Json::Value& value, const char* name) {
  if (!value.isString()) fail(std::string(name) + " must be a string");
  return value.asString();
}

std::vector<double> numberArray(const Json::Value& value, const char* name) {
  if (!value.isArray()) fail(std::string(name) + " must be an array of numbers");
  std::vector<double> numbers;
  numbers.reserve(value.size());
  for (Json::ArrayIndex i = 0; i < value.size(); ++i)
    numbers.push_back(numberField(value[i], std::string(name) + "[" + std::to_string(i) + "]"));
  return numbers;
}

std::vector<int> integerArray(const Json::Value& value, const char* name) {
  if (!value.isArray()) fail(std::string(name) + " must be an array of integers");
  std::vector<int> numbers;
  numbers.reserve(value.size());
  for (Json::ArrayIndex i = 0; i < value.size(); ++i) {
    if (!value[i].isInt())
      fail(std::string(name) + "[" + std::to_string(i) + "] must be an integer");
    numbers.push_back(value[i].asInt());
  }
  return numbers;
}

// A 4x4 row-major homogeneous transform; translation stays in millimetres.
Eigen::Matrix4d transformField(const Json::Value& value, const char* name) {
  const std::vector<double> numbers = numberArray(value, name);
  if (numbers.size() != 16)
    fail(std::string(name) + " has " + std::to_string(numbers.size()) + " entries, expected 16");
  Eigen::Matrix4d matrix;
  for (int i = 0; i < 16; ++i) matrix(i / 4, i % 4) = numbers[i];
  if (matrix.row(3) != Eigen::RowVector4d(0, 0, 0, 1))
    fail(std::string(name) + " last row must be 0 0 0 1");
  return matrix;
}

struct LidarMode {
  int columns;
  double frequency_hz;
};

// The modes the sensors offer; anything else is a typo or a corrupt file.
LidarMode parseLidarMode(const std::string& text) {
  static const struct {
    const char* name;
    LidarMode mode;
  } kModes[] = {{"512x10", {512, 10}},   {"512x20", {512, 20}},   {"1024x10", {1024, 10}},
                {"1024x20", {1024, 20}}, {"2048x10", {2048, 10}}, {"4096x5", {4096, 5}}};
  for (const auto& known : kModes)
    if (text == known.name) return known.mode;
  fail("lidar_mode " + quoted(text) +
       " is not one of 512x10, 512x20, 1024x10, 1024x20, 2048x10, 4096x5");
}

// Manufacturer defaults for metadata written before these fields existed.
double defaultBeamOriginMillimetres(const std::string& prod_line) {
  if (prod_line.rfind("OS-0-", 0) == 0) return 27.67;
  if (prod_line.rfind("OS-1-", 0) == 0) return 15.806;
  if (prod_line.rfind("OS-2-", 0) == 0) return 13.762;
  return 12.163;  // first-generation sensors, which did not report a product line
}

std::vector<int> defaultPixelShiftByRow(int rows, int columns) {
  // Four staggered azimuth columns per group of beams: shifts {3k, 2k, k, 0}
  // with k = 3 columns at 512, 6 at 1024, 12 at 2048.
  const int step = 3 * columns / 512;
  std::vector<int> shifts(rows);
  for (int v = 0; v < rows; ++v) shifts[v] = (3 - v % 4) * step;
  return shifts;
}

Eigen::Isometry3d defaultLidarToSensorMillimetres() {
  Eigen::Isometry3d transform = Eigen::Isometry3d::Identity();
  transform.linear().diagonal() << -1, -1, 1;
  transform.translation() << 0, 0, 36.18;
  return transform;
}

Json::Value parseJson(const std::string& text) {
  Json::CharReaderBuilder builder;
  builder["collectComments"] = false;
  builder["failIfExtra"] = true;
  builder["rejectDupKeys"] = true;
  const std::unique_ptr<Json::CharReader> reader(builder.newCharReader());
  Json::Value root;
  std::string errors;
  bool parsed = false;
  try {
    parsed = reader->parse(text.data(), text.data() + text.size(), &root, &errors);
  } catch (const Json::Exception& error) {  // e.g. nesting deeper than the reader's stack limit
    errors = error.what();
  }
  if (!parsed) {
    while (!errors.empty() && (errors.back() == '\n' || errors.back() == ' ')) errors.pop_back();
    fail("not valid JSON: " + errors);
  }
  if (!root.isObject()) fail("top level must be a JSON object");
  return root;
}

const std::initializer_list<const char*> kBeamSections = {"beam_intrinsics", kTopLevel};
const std::initializer_list<const char*> kFormatSections = {"lidar_data_format", "data_format"};
const std::initializer_list<const char*> kConfigSections = {"config_params", kTopLevel};
const std::initializer_list<const char*> kSensorInfoSections = {"sensor_info", kTopLevel};

std::vector<double> beamTable(const Json::Value& root, const char* name) {
  const Json::Value* value = findField(root, kBeamSections, name);
  if (value == nullptr) fail(std::string(name) + " is missing");
  std::vector<double> table = numberArray(*value, name);
  if (table.empty()) fail(std::string(name) + " is empty");
  return table;
}

}  // namespace

const char* toString(UdpProfile profile) {
  switch (profile) {
    case UdpProfile::kLegacy: return "LEGACY";
    case UdpProfile::kRng19Rfl8Sig16Nir16: return "RNG19_RFL8_SIG16_NIR16";
    case UdpProfile::kRng19Rfl8Sig16Nir16Dual: return "RNG19_RFL8_SIG16_NIR16_DUAL";
    case UdpProfile::kRng15Rfl8Nir8: return "RNG15_RFL8_NIR8";
  }
  return "unknown";
}

UdpProfile udpProfileFromString(const std::string& name) {
  for (const UdpProfile profile :
       {UdpProfile::kLegacy, UdpProfile::kRng19Rfl8Sig16Nir16, UdpProfile::kRng19Rfl8Sig16Nir16Dual,
        UdpProfile::kRng15Rfl8Nir8})
    if (name == toString(profile)) return profile;
  fail("udp_profile_lidar " + quoted(name) +
       " is not supported (LEGACY, RNG19_RFL8_SIG16_NIR16, RNG19_RFL8_SIG16_NIR16_DUAL, "
       "RNG15_RFL8_NIR8)");
}

OusterMetadata parseOusterMetadata(const std::string& json_text) {
  const Json::Value root = parseJson(json_text);
  OusterMetadata metadata;
  metadata.json = json_text;

  if (const Json::Value* value = findField(root, kSensorInfoSections, "prod_line"))
    metadata.prod_line = stringField(*value, "prod_line");
  if (const Json::Value* value = findField(root, kSensorInfoSections, "build_rev"))
    metadata.firmware = stringField(*value, "build_rev");
  if (const Json::Value* value = findField(root, kSensorInfoSections, "prod_sn")) {
    // Some firmware writes the serial number as a JSON number.
    metadata.serial = value->isUInt64() ? std::to_string(value->asUInt64())
                                        : stringField(*value, "prod_sn");
  }
  if (const Json::Value* value = findField(root, kSensorInfoSections, "initialization_id")) {
    if (!value->isUInt()) fail("initialization_id must be a non-negative integer");
    metadata.initialization_id = value->asUInt();
  }

  // Columns and rate: lidar_mode is authoritative, columns_per_frame must agree.
  const Json::Value* mode_value = findField(root, kConfigSections, "lidar_mode");
  if (mode_value == nullptr) fail("lidar_mode is missing");
  if (!mode_value->isString()) fail("lidar_mode must be a string such as \"1024x10\"");
  metadata.lidar_mode = mode_value->asString();
  const LidarMode mode = parseLidarMode(metadata.lidar_mode);
  metadata.columns_per_frame = mode.columns;
  metadata.frequency_hz = mode.frequency_hz;
  if (const Json::Value* value = findField(root, kFormatSections, "columns_per_frame")) {
    const int columns = integerField(*value, "columns_per_frame");
    if (columns != mode.columns)
      fail("columns_per_frame is " + std::to_string(columns) + ", lidar_mode " +
           metadata.lidar_mode + " has " + std::to_string(mode.columns));
  }
  const int columns = metadata.columns_per_frame;

  // Beams: the tables decide the row count unless pixels_per_column is given.
  const std::vector<double> altitude_deg = beamTable(root, "beam_altitude_angles");
  const std::vector<double> azimuth_deg = beamTable(root, "beam_azimuth_angles");
  int rows = static_cast<int>(altitude_deg.size());
  if (const Json::Value* value = findField(root, kFormatSections, "pixels_per_column")) {
    rows = integerField(*value, "pixels_per_column");
    if (rows <= 0 || rows > kMaxPixelsPerColumn)
      fail("pixels_per_column is " + std::to_string(rows) + ", must be within [1, " +
           std::to_string(kMaxPixelsPerColumn) + "]");
  } else if (rows > kMaxPixelsPerColumn) {
    fail("beam_altitude_angles has " + std::to_string(rows) + " entries, more than " +
         std::to_string(kMaxPixelsPerColumn) + " beams");
  }
  metadata.pixels_per_column = rows;
  const auto check_count = [rows](std::size_t count, const char* name) {
    if (static_cast<int>(count) != rows)
      fail(std::string(name) + " has " + std::to_string(count) + " entries, pixels_per_column is " +
           std::to_string(rows));
  };
  check_count(altitude_deg.size(), "beam_altitude_angles");
  check_count(azimuth_deg.size(), "beam_azimuth_angles");

  if (const Json::Value* value = findField(root, kFormatSections, "udp_profile_lidar"))
    metadata.profile = udpProfileFromString(stringField(*value, "udp_profile_lidar"));
  else if (const Json::Value* config = findField(root, {"config_params"}, "udp_profile_lidar"))
    metadata.profile = udpProfileFromString(stringField(*config, "udp_profile_lidar"));

  const Json::Value* per_packet = findField(root, kFormatSections, "columns_per_packet");
  if (per_packet == nullptr) per_packet = findField(root, {"config_params"}, "columns_per_packet");
  if (per_packet != nullptr) {
    metadata.columns_per_packet = integerField(*per_packet, "columns_per_packet");
    if (metadata.columns_per_packet <= 0 || metadata.columns_per_packet > columns)
      fail("columns_per_packet is " + std::to_string(metadata.columns_per_packet) +
           ", must be within [1, " + std::to_string(columns) + "]");
  }

  for (const auto& [name, port] : {std::pair{"udp_port_lidar", &metadata.udp_port_lidar},
                                   std::pair{"udp_port_imu", &metadata.udp_port_imu}}) {
    const Json::Value* value = findField(root, kConfigSections, name);
    // Unconfigured sensors report 0 or "": the sensor then uses its default port.
    if (value == nullptr || (value->isString() && value->asString().empty())) continue;
    const int number = integerField(*value, name);
    if (number < 0 || number > 65535)
      fail(std::string(name) + " is " + std::to_string(number) + ", must be within [0, 65535]");
    if (number != 0) *port = number;
  }

  LidarIntrinsics& intrinsics = metadata.intrinsics;
  intrinsics.rows = rows;
  intrinsics.columns = columns;
  intrinsics.sensor_model = metadata.prod_line.empty() ? "OS-unknown" : metadata.prod_line;
  intrinsics.altitude_rad.resize(rows);
  intrinsics.azimuth_offset_rad.resize(rows);
  for (int v = 0; v < rows; ++v) {
    intrinsics.altitude_rad[v] = altitude_deg[v] * kDegreesToRadians;
    // Ouster's beam azimuth is measured the other way round from the encoder angle.
    intrinsics.azimuth_offset_rad[v] = -azimuth_deg[v] * kDegreesToRadians;
  }

  if (const Json::Value* value = findField(root, kBeamSections, "beam_to_lidar_transform")) {
    const Eigen::Matrix4d beam_to_lidar = transformField(*value, "beam_to_lidar_transform");
    intrinsics.beam_origin_radius_m = beam_to_lidar(0, 3) * kMillimetresToMetres;
    intrinsics.beam_origin_z_m = beam_to_lidar(2, 3) * kMillimetresToMetres;
  } else if (const Json::Value* origin =
                 findField(root, kBeamSections, "lidar_origin_to_beam_origin_mm")) {
    intrinsics.beam_origin_radius_m =
        numberField(*origin, "lidar_origin_to_beam_origin_mm") * kMillimetresToMetres;
  } else {
    intrinsics.beam_origin_radius_m =
        defaultBeamOriginMillimetres(metadata.prod_line) * kMillimetresToMetres;
  }

  if (const Json::Value* value = findField(root, kFormatSections, "pixel_shift_by_row")) {
    intrinsics.pixel_shift_by_row = integerArray(*value, "pixel_shift_by_row");
    check_count(intrinsics.pixel_shift_by_row.size(), "pixel_shift_by_row");
  } else {
    intrinsics.pixel_shift_by_row = defaultPixelShiftByRow(rows, columns);
  }

  intrinsics.column_window = {0, columns - 1};
  if (const Json::Value* value = findField(root, kFormatSections, "column_window")) {
    const std::vector<int> window = integerArray(*value, "column_window");
    if (window.size() != 2)
      fail("column_window has " + std::to_string(window.size()) + " entries, expected 2");
    for (const int column : window)
      if (column < 0 || column >= columns)
        fail("column_window [" + std::to_string(window[0]) + ", " + std::to_string(window[1]) +
             "] must lie within [0, " + std::to_string(columns - 1) + "]");
    intrinsics.column_window = {window[0], window[1]};
  }

  Eigen::Isometry3d lidar_to_sensor = defaultLidarToSensorMillimetres();
  if (const Json::Value* value =
          findField(root, {"lidar_intrinsics", kTopLevel}, "lidar_to_sensor_transform")) {
    lidar_to_sensor.matrix() = transformField(*value, "lidar_to_sensor_transform");
    const Eigen::Matrix3d rotation = lidar_to_sensor.linear();
    if (!(rotation * rotation.transpose()).isIdentity(1e-3) || rotation.determinant() < 0)
      fail("lidar_to_sensor_transform rotation is not a rotation matrix");
  }
  lidar_to_sensor.translation() *= kMillimetresToMetres;
  intrinsics.lidar_to_sensor = lidar_to_sensor;

  intrinsics.validate();
  return metadata;
}

OusterMetadata loadOusterMetadata(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) throw MetadataError("metadata: cannot open '" + path + "': " + std::strerror(errno));
  std::ostringstream text;
  text << file.rdbuf();
  if (file.bad()) throw MetadataError("metadata: cannot read '" + path + "'");
  try {
    return parseOusterMetadata(text.str());
  } catch (const MetadataError& error) {
    throw MetadataError(std::string(error.what()) + " (in '" + path + "')");
  } catch (const IntrinsicsError& error) {
    throw IntrinsicsError(std::string(error.what()) + " (in '" + path + "')");
  }
}

}  // namespace range_image_mapping
