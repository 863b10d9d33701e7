// Sensors the simulator can be, when no metadata file is given: approximations
// of Ouster sensors (for machines without a real metadata file) and the
// KITTI-like HDL-64.
#pragma once

#include "range_image_mapping/ouster_metadata.h"

#include <string>

namespace range_image_mapping::simulation {

// Flat (firmware 2.x) metadata JSON of an Ouster-like sensor: "OS-0-128" or
// "OS-1-128", 1024x10, the given profile. Altitudes are spread evenly over the
// product's field of view and azimuth offsets repeat the four-column pattern of
// the real sensors, with their beam-origin offset and lidar_to_sensor; a real
// sensor's metadata file is always better and is the simulator's default where
// one is at hand. Throws std::invalid_argument for another product name.
std::string ousterLikeMetadataJson(const std::string& product_line, UdpProfile profile);

}  // namespace range_image_mapping::simulation
