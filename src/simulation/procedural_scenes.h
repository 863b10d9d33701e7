// The two procedural scene kinds behind generateScene (options already checked).
#pragma once

#include "range_image_mapping/simulation/scene_generator.h"

namespace range_image_mapping::simulation {

Scene generateIndoorScene(uint32_t seed, double extent_m);
Scene generateOutdoorScene(uint32_t seed, double extent_m);

}  // namespace range_image_mapping::simulation
