// A scan of a named sensor model (sensor_catalog.h) for the tests that feed
// the Adapter drivers' clouds: every pixel at a random range (seeded) but every
// 11th (no return), columns 100 ms / W apart from stamp_ns.
#pragma once

#include "range_image_mapping/range_image.h"
#include "range_image_mapping/sensor_catalog.h"

#include <memory>
#include <random>
#include <string>

namespace range_image_mapping::test {

inline RangeImage namedSensorImage(const std::string& name, uint64_t stamp_ns, unsigned seed = 3) {
  RangeImage image(std::make_shared<const LidarModel>(*catalogSensor(name)));
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> range(2.0f, 40.0f);
  for (std::size_t i = 0; i < image.range.size(); ++i) {
    const float value = range(random);
    if (i % 11 != 5) image.range[i] = value;
  }
  image.stamp_ns = stamp_ns;
  image.column_timestamp_ns.resize(image.columns());
  for (int u = 0; u < image.columns(); ++u)
    image.column_timestamp_ns[u] = stamp_ns + uint64_t(u) * 100'000'000 / uint64_t(image.columns());
  return image;
}

}  // namespace range_image_mapping::test
