#include "range_image_mapping/simulation/sensor_presets.h"
#include "test_data.h"

#include <gtest/gtest.h>

namespace range_image_mapping::simulation {
namespace {

// The built-in approximations parse as real metadata and stay close to the
// real sensors' tables where those are at hand.
TEST(SensorPresets, OusterLikeMetadataParsesAndResemblesTheRealSensor) {
  const struct {
    const char* product;
    const char* real_file;
  } cases[] = {{"OS-0-128", "ouster-pcaps/OS-0-128-U1_v2.3.0_1024x10.json"},
               {"OS-1-128", "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json"}};
  for (const auto& c : cases) {
    const OusterMetadata simulated =
        parseOusterMetadata(ousterLikeMetadataJson(c.product, UdpProfile::kRng19Rfl8Sig16Nir16));
    EXPECT_EQ(simulated.prod_line, c.product);
    EXPECT_EQ(simulated.profile, UdpProfile::kRng19Rfl8Sig16Nir16);
    EXPECT_EQ(simulated.intrinsics.rows, 128);
    EXPECT_EQ(simulated.intrinsics.columns, 1024);
    const std::string real_path = test::dataFile(c.real_file);
    if (real_path.empty()) continue;
    const OusterMetadata real = loadOusterMetadata(real_path);
    EXPECT_NEAR(simulated.intrinsics.beam_origin_radius_m, real.intrinsics.beam_origin_radius_m, 1e-9);
    EXPECT_EQ(simulated.intrinsics.pixel_shift_by_row.size(), real.intrinsics.pixel_shift_by_row.size());
    for (int v = 0; v < 128; ++v) {
      EXPECT_NEAR(simulated.intrinsics.altitude_rad[v], real.intrinsics.altitude_rad[v], 1.0 * M_PI / 180);
      EXPECT_NEAR(simulated.intrinsics.azimuth_offset_rad[v], real.intrinsics.azimuth_offset_rad[v],
                  1.0 * M_PI / 180);
    }
    EXPECT_TRUE(simulated.intrinsics.lidar_to_sensor.isApprox(real.intrinsics.lidar_to_sensor, 1e-9));
  }
  EXPECT_THROW(ousterLikeMetadataJson("OS-9-7", UdpProfile::kLegacy), std::invalid_argument);
}

}  // namespace
}  // namespace range_image_mapping::simulation
