#include "range_image_mapping/simulation/sensor_presets.h"

#include <json/json.h>

#include <stdexcept>

namespace range_image_mapping::simulation {
namespace {

struct OusterProduct {
  const char* product_line;
  double altitude_top_deg, altitude_bottom_deg;
  double azimuth_pattern_deg[4];  // repeats every four beams, at the horizon
  double azimuth_growth;          // wide lenses: the offsets grow by this fraction at the edges
  int shift_pattern[4];           // pixel_shift_by_row at 1024 columns
  double origin_mm;               // lidar_origin_to_beam_origin_mm
};

// Figures of the sensors' published metadata, rounded.
const OusterProduct kProducts[] = {
    {"OS-0-128", 45.75, -46.26, {8.45, 2.95, -2.5, -8.3}, 0.3, {64, 43, 23, 3}, 27.67},
    {"OS-1-128", 20.95, -21.82, {4.2, 1.4, -1.4, -4.2}, 0.0, {24, 16, 8, 0}, 15.806},
};

}  // namespace

std::string ousterLikeMetadataJson(const std::string& product_line, UdpProfile profile) {
  const OusterProduct* product = nullptr;
  for (const OusterProduct& candidate : kProducts)
    if (product_line == candidate.product_line) product = &candidate;
  if (!product)
    throw std::invalid_argument("no built-in Ouster model '" + product_line +
                                "' (known: OS-0-128, OS-1-128); pass a metadata file instead");
  constexpr int kBeams = 128;
  Json::Value root;
  Json::Value altitudes(Json::arrayValue), azimuths(Json::arrayValue), shifts(Json::arrayValue);
  for (int beam = 0; beam < kBeams; ++beam) {
    const double altitude = product->altitude_top_deg +
                            (product->altitude_bottom_deg - product->altitude_top_deg) * beam / (kBeams - 1);
    const double edge = altitude / product->altitude_top_deg;
    altitudes.append(altitude);
    azimuths.append(product->azimuth_pattern_deg[beam % 4] * (1.0 + product->azimuth_growth * edge * edge));
    shifts.append(product->shift_pattern[beam % 4]);
  }
  root["beam_altitude_angles"] = altitudes;
  root["beam_azimuth_angles"] = azimuths;
  root["lidar_origin_to_beam_origin_mm"] = product->origin_mm;
  Json::Value lidar_to_sensor(Json::arrayValue);
  for (double value : {-1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 36.18, 0.0, 0.0, 0.0, 1.0})
    lidar_to_sensor.append(value);
  root["lidar_to_sensor_transform"] = lidar_to_sensor;
  root["lidar_mode"] = "1024x10";
  root["prod_line"] = product->product_line;
  root["prod_sn"] = "000000000000";
  root["build_rev"] = "simulated";
  root["udp_port_lidar"] = 7502;
  root["udp_port_imu"] = 7503;
  Json::Value format;
  format["columns_per_frame"] = 1024;
  format["columns_per_packet"] = 16;
  format["pixels_per_column"] = kBeams;
  format["column_window"].append(0);
  format["column_window"].append(1023);
  format["pixel_shift_by_row"] = shifts;
  format["udp_profile_lidar"] = toString(profile);
  root["data_format"] = format;
  Json::StreamWriterBuilder writer;
  writer["indentation"] = "  ";
  return Json::writeString(writer, root);
}

}  // namespace range_image_mapping::simulation
