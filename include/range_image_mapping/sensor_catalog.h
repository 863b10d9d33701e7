// Named sensor models: the spinning LiDARs most ROS users have, from their
// data sheets and their drivers' calibration files (per-laser elevation and,
// where the lasers fire at different azimuths, azimuth offset), with the
// column count of one revolution at 10 Hz. A unit's own calibration is always
// better (a sensor file, `rim sensor estimate`), but these explain a cloud of
// that sensor to within a fraction of a beam spacing.
#pragma once

#include "range_image_mapping/lidar_intrinsics.h"

#include <optional>
#include <string>
#include <vector>

namespace range_image_mapping {

struct CatalogSensor {
  std::string name;         // as the maker writes it, e.g. "VLP-32C"
  std::string maker;        // Velodyne, Hesai, RoboSense
  std::string source;       // where the tables come from
  LidarIntrinsics intrinsics;  // sensor_model = name
};

// Every named model, in the order of the README's table.
const std::vector<CatalogSensor>& sensorCatalog();

// The names, for messages ("VLP-16, VLP-32C, ...").
std::string sensorCatalogNames();

// The model of a name, compared without case, spaces, '-' or '_' (so
// "vlp16", "VLP-16" and "vlp_16" are one); aliases: "KITTI" for HDL-64E,
// "XT32" for PandarXT-32, "RS16"/"RS32" for the RoboSense sensors. Nothing
// for an unknown name.
std::optional<LidarIntrinsics> catalogSensor(const std::string& name);

// KITTI's Velodyne HDL-64E as a synthetic model: 64 rows evenly spread from
// +3 deg down to -25 deg, no azimuth offsets, no beam offset (the catalog's
// HDL-64E, at 2048 columns). The data sheet says +2 to -24.8 deg, but seen
// from the KITTI Velodyne origin the upper lasers reach +3.7 deg (3.4 % of
// scan 94's points lie above +2.2 deg). Share of scan 94's points that get a
// pixel of their own: 80 % at 2048 columns, 92 % at 4096 (the lasers' firings
// do not fall on one regular grid; `rim sensor estimate` does better).
LidarIntrinsics kittiHdl64Intrinsics(int columns = 2048);

}  // namespace range_image_mapping
