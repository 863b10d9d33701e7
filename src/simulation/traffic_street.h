// The static street of the traffic scenario (traffic.h): a straight road with
// an intersection, kerbs and sidewalks, building rows with facade relief, lamp
// posts and trees.
#pragma once

#include "range_image_mapping/simulation/traffic.h"

namespace range_image_mapping::simulation {

// The main road runs along x over [road_start_x, road_end_x].
Scene buildTrafficStreet(const TrafficLayout& layout, double road_start_x, double road_end_x, uint32_t seed);

}  // namespace range_image_mapping::simulation
