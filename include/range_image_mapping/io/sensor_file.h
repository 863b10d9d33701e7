// Sensor files: any sensor model as YAML (beam tables in degrees, as data
// sheets and calibration files give them), written by `rim sensor estimate`
// and read by --sensor FILE|NAME; an Ouster metadata JSON is read as a sensor file
// too.
//
//   sensor_model: estimated          # free text
//   rows: 64
//   columns: 4096
//   altitude_deg: [1.93, 1.57, ...]  # rows entries, row 0 = the highest beam
//   azimuth_offset_deg: [...]        # rows entries (theta_lut; 0 if absent)
//   beam_origin_radius_m: 0.0        # optional, default 0
//   beam_origin_z_m: 0.216           # optional, default 0
//   pixel_shift_by_row: [...]        # optional, display only
//   column_window: [0, 4095]         # optional
//   lidar_to_sensor: [16 numbers]    # optional, row-major 4x4, metres
//   ring_to_row: [...]               # optional: a cloud's ring field -> row
//   estimate: {...}                  # optional, written by rim; not read
#pragma once

#include "range_image_mapping/lidar_intrinsics.h"
#include "range_image_mapping/sensor_model_estimation.h"

#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping::io {

// A sensor file that is missing, not YAML, has a key of the wrong type, an
// unknown key or tables that do not fit; what() names the file, the key and,
// for syntax errors, the line.
class SensorFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct SensorFile {
  LidarIntrinsics intrinsics;
  std::vector<int> ring_to_row;  // empty unless the file gives one
};

// YAML as above; a file ending in .json is read as Ouster metadata. A path
// that is no file but a named model of the sensor catalog (sensor_catalog.h:
// VLP-16, HDL-64E, Pandar64, ...) gives that model; neither is an error that
// lists the known names.
SensorFile readSensorFile(const std::string& path_or_name);
// The YAML text itself; source names it in errors.
SensorFile parseSensorYaml(const std::string& text, const std::string& source = "sensor file");

// The YAML text of a model; with an estimate, its quality as an `estimate:`
// section (and a comment on how it was made).
std::string sensorYaml(const LidarIntrinsics& intrinsics, const std::vector<int>& ring_to_row = {},
                       const SensorEstimate* estimate = nullptr);
// Throws SensorFileError when the file cannot be written.
void writeSensorFile(const std::string& path, const LidarIntrinsics& intrinsics,
                     const std::vector<int>& ring_to_row = {}, const SensorEstimate* estimate = nullptr);

}  // namespace range_image_mapping::io
