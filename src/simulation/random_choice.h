// Discrete choices for the procedural scenes, on top of SeededRandom so a seed
// gives the same scene on every platform.
#pragma once

#include "seeded_random.h"

#include <cstdint>

namespace range_image_mapping::simulation {

// Uniform in [low, high], both included.
inline int uniformInteger(SeededRandom& random, int low, int high) {
  return low + static_cast<int>(random.next() % static_cast<uint64_t>(high - low + 1));
}

inline bool chance(SeededRandom& random, double probability) {
  return random.uniform() < probability;
}

}  // namespace range_image_mapping::simulation
