#include "range_image_mapping/io/sensor_file.h"

#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/sensor_catalog.h"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>

namespace range_image_mapping::io {
namespace {

constexpr double kRadPerDeg = M_PI / 180.0;

const std::set<std::string>& knownKeys() {
  static const std::set<std::string> keys{
      "sensor_model", "rows", "columns", "altitude_deg", "azimuth_offset_deg", "beam_origin_radius_m",
      "beam_origin_z_m", "pixel_shift_by_row", "column_window", "lidar_to_sensor", "ring_to_row", "estimate"};
  return keys;
}

[[noreturn]] void fail(const std::string& source, const std::string& message) {
  throw SensorFileError(source + ": " + message);
}

template <typename T>
T scalar(const YAML::Node& node, const std::string& key, const std::string& source) {
  if (!node.IsScalar()) fail(source, key + " must be a single value");
  try {
    return node.as<T>();
  } catch (const YAML::Exception&) {
    fail(source, key + " is not a " + (std::is_integral_v<T> ? "whole number" : "number") + ": '" +
                     node.Scalar() + "' (line " + std::to_string(node.Mark().line + 1) + ")");
  }
}

template <typename T>
std::vector<T> sequence(const YAML::Node& node, const std::string& key, const std::string& source) {
  if (!node.IsSequence()) fail(source, key + " must be a list, e.g. [1, 2, 3]");
  std::vector<T> values;
  for (std::size_t i = 0; i < node.size(); ++i)
    values.push_back(scalar<T>(node[i], key + "[" + std::to_string(i) + "]", source));
  return values;
}

std::string joined(const std::vector<double>& values, int precision) {
  std::ostringstream text;
  text << std::setprecision(precision);
  text << "[";
  for (std::size_t i = 0; i < values.size(); ++i) text << (i ? ", " : "") << values[i];
  text << "]";
  return text.str();
}

std::string joined(const std::vector<int>& values) {
  std::ostringstream text;
  text << "[";
  for (std::size_t i = 0; i < values.size(); ++i) text << (i ? ", " : "") << values[i];
  text << "]";
  return text.str();
}

}  // namespace

SensorFile parseSensorYaml(const std::string& text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::ParserException& error) {
    fail(source, "not valid YAML at line " + std::to_string(error.mark.line + 1) + ", column " +
                     std::to_string(error.mark.column + 1) + ": " + error.msg);
  }
  if (!root.IsMap()) fail(source, "expected a YAML mapping of sensor fields (rows, columns, altitude_deg, ...)");
  for (const auto& entry : root) {
    const std::string key = entry.first.as<std::string>();
    if (!knownKeys().count(key)) {
      std::string known;
      for (const std::string& name : knownKeys()) known += (known.empty() ? "" : ", ") + name;
      fail(source, "unknown key '" + key + "' (line " + std::to_string(entry.first.Mark().line + 1) +
                       "); known keys: " + known);
    }
  }
  for (const char* required : {"rows", "columns", "altitude_deg"})
    if (!root[required]) fail(source, std::string("missing ") + required);

  SensorFile file;
  LidarIntrinsics& intrinsics = file.intrinsics;
  intrinsics.sensor_model = root["sensor_model"] ? scalar<std::string>(root["sensor_model"], "sensor_model", source)
                                                 : std::string("sensor file");
  intrinsics.rows = scalar<int>(root["rows"], "rows", source);
  intrinsics.columns = scalar<int>(root["columns"], "columns", source);
  for (const double degrees : sequence<double>(root["altitude_deg"], "altitude_deg", source))
    intrinsics.altitude_rad.push_back(degrees * kRadPerDeg);
  if (root["azimuth_offset_deg"]) {
    for (const double degrees : sequence<double>(root["azimuth_offset_deg"], "azimuth_offset_deg", source))
      intrinsics.azimuth_offset_rad.push_back(degrees * kRadPerDeg);
  } else {
    intrinsics.azimuth_offset_rad.assign(intrinsics.altitude_rad.size(), 0.0);
  }
  if (root["beam_origin_radius_m"])
    intrinsics.beam_origin_radius_m = scalar<double>(root["beam_origin_radius_m"], "beam_origin_radius_m", source);
  if (root["beam_origin_z_m"])
    intrinsics.beam_origin_z_m = scalar<double>(root["beam_origin_z_m"], "beam_origin_z_m", source);
  if (root["pixel_shift_by_row"])
    intrinsics.pixel_shift_by_row = sequence<int>(root["pixel_shift_by_row"], "pixel_shift_by_row", source);
  else
    intrinsics.pixel_shift_by_row.assign(intrinsics.altitude_rad.size(), 0);
  if (root["column_window"]) {
    const std::vector<int> window = sequence<int>(root["column_window"], "column_window", source);
    if (window.size() != 2) fail(source, "column_window must hold two columns, [first, last]");
    intrinsics.column_window = {window[0], window[1]};
  }
  if (root["lidar_to_sensor"]) {
    const std::vector<double> matrix = sequence<double>(root["lidar_to_sensor"], "lidar_to_sensor", source);
    if (matrix.size() != 16) fail(source, "lidar_to_sensor must hold 16 numbers (row-major 4x4, metres)");
    Eigen::Matrix4d m;
    for (int i = 0; i < 16; ++i) m(i / 4, i % 4) = matrix[i];
    if (!m.row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1)))
      fail(source, "lidar_to_sensor's last row must be 0 0 0 1");
    intrinsics.lidar_to_sensor.matrix() = m;
  }
  if (root["ring_to_row"]) {
    file.ring_to_row = sequence<int>(root["ring_to_row"], "ring_to_row", source);
    for (std::size_t ring = 0; ring < file.ring_to_row.size(); ++ring)
      if (file.ring_to_row[ring] < -1 || file.ring_to_row[ring] >= intrinsics.rows)
        fail(source, "ring_to_row[" + std::to_string(ring) + "] = " + std::to_string(file.ring_to_row[ring]) +
                         " is no row (0.." + std::to_string(intrinsics.rows - 1) + ", or -1 for none)");
  }
  try {
    intrinsics.validate();
  } catch (const IntrinsicsError& error) {
    // The intrinsics name their tables in radians; the file's keys are in degrees.
    std::string message = error.what();
    for (const auto& [table, key] : {std::pair<std::string, std::string>{"altitude_rad", "altitude_deg"},
                                     {"azimuth_offset_rad", "azimuth_offset_deg"}})
      for (std::size_t at = message.find(table); at != std::string::npos; at = message.find(table))
        message.replace(at, table.size(), key);
    fail(source, message);
  }
  return file;
}

SensorFile readSensorFile(const std::string& path) {
  // A file of that name wins over a catalog name (a sensor file may be called VLP-16).
  if (!std::filesystem::exists(path)) {
    if (std::optional<LidarIntrinsics> named = catalogSensor(path)) return {std::move(*named), {}};
    fail(path, "is neither a sensor file (no such file) nor a named sensor model (known: " + sensorCatalogNames() +
                   ")");
  }
  std::ifstream stream(path, std::ios::binary);
  if (!stream) fail(path, "cannot be read");
  std::stringstream text;
  text << stream.rdbuf();
  if (path.size() >= 5 && path.compare(path.size() - 5, 5, ".json") == 0) {
    try {
      return {parseOusterMetadata(text.str()).intrinsics, {}};
    } catch (const MetadataError& error) {
      fail(path, std::string("not usable Ouster metadata: ") + error.what());
    }
  }
  return parseSensorYaml(text.str(), path);
}

std::string sensorYaml(const LidarIntrinsics& intrinsics, const std::vector<int>& ring_to_row,
                       const SensorEstimate* estimate) {
  intrinsics.validate();
  std::ostringstream yaml;
  yaml << std::setprecision(15);
  yaml << "# range_image_mapping sensor model (--sensor FILE). Angles in degrees, row 0 = the highest beam;\n"
          "# column u looks at encoder angle 360 - 360 u / columns deg, beam v at that plus azimuth_offset_deg[v].\n";
  if (estimate)
    yaml << "# Estimated from " << estimate->fit.scans << " clouds by rim sensor estimate; see estimate: below.\n";
  std::string name = intrinsics.sensor_model;
  for (char& c : name)
    if (c == '"' || c == '\\' || c == '\n') c = '\'';
  yaml << "sensor_model: \"" << name << "\"\n";
  yaml << "rows: " << intrinsics.rows << "\n";
  yaml << "columns: " << intrinsics.columns << "\n";
  yaml << "beam_origin_radius_m: " << intrinsics.beam_origin_radius_m << "\n";
  yaml << "beam_origin_z_m: " << intrinsics.beam_origin_z_m << "\n";
  std::vector<double> altitude_deg, azimuth_deg;
  for (const double value : intrinsics.altitude_rad) altitude_deg.push_back(value / kRadPerDeg);
  for (const double value : intrinsics.azimuth_offset_rad) azimuth_deg.push_back(value / kRadPerDeg);
  yaml << "altitude_deg: " << joined(altitude_deg, 15) << "\n";
  yaml << "azimuth_offset_deg: " << joined(azimuth_deg, 15) << "\n";
  if (!intrinsics.pixel_shift_by_row.empty())
    yaml << "pixel_shift_by_row: " << joined(intrinsics.pixel_shift_by_row) << "\n";
  if (!(intrinsics.column_window[0] == 0 && intrinsics.column_window[1] == -1))
    yaml << "column_window: [" << intrinsics.column_window[0] << ", " << intrinsics.column_window[1] << "]\n";
  if (!intrinsics.lidar_to_sensor.matrix().isIdentity(0.0)) {
    std::vector<double> matrix;
    for (int i = 0; i < 16; ++i) matrix.push_back(intrinsics.lidar_to_sensor.matrix()(i / 4, i % 4));
    yaml << "lidar_to_sensor: " << joined(matrix, 15) << "\n";
  }
  if (!ring_to_row.empty()) yaml << "ring_to_row: " << joined(ring_to_row) << "\n";
  if (estimate) {
    const SensorModelFit& fit = estimate->fit;
    yaml << std::setprecision(6);
    yaml << "estimate:  # how well this model explains the clouds it was estimated from\n";
    yaml << "  clouds: " << fit.scans << "\n";
    yaml << "  measured_points: " << fit.measured_points << "\n";
    yaml << "  kept_share: " << fit.keptShare() << "  # points with a pixel of their own\n";
    yaml << "  outside_share: " << fit.outsideShare() << "  # outside the model's field of view\n";
    yaml << "  shared_pixel_share: " << fit.occludedShare() << "  # lost to a nearer point in the same pixel\n";
    yaml << "  elevation_residual_deg: " << fit.elevation_residual_deg << "  # RMS, point against its beam\n";
    yaml << "  azimuth_residual_deg: " << fit.azimuth_residual_deg << "  # RMS, point against its column\n";
    yaml << "  azimuth_step_deg: " << estimate->azimuth_step_deg << "\n";
    std::vector<double> points(estimate->points_per_row.begin(), estimate->points_per_row.end());
    yaml << "  points_per_row: " << joined(points, 10) << "\n";
  }
  return yaml.str();
}

void writeSensorFile(const std::string& path, const LidarIntrinsics& intrinsics, const std::vector<int>& ring_to_row,
                     const SensorEstimate* estimate) {
  const std::string text = sensorYaml(intrinsics, ring_to_row, estimate);
  std::ofstream stream(path, std::ios::binary);
  stream << text;
  if (!stream) fail(path, "cannot be written");
}

}  // namespace range_image_mapping::io
