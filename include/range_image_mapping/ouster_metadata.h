// Ouster sensor metadata (JSON), in the flat firmware-2.x format and the
// nested format of newer firmware and the ouster-sdk.
#pragma once

#include "range_image_mapping/lidar_intrinsics.h"

#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping {

// Malformed or incomplete metadata; what() names the offending field.
class MetadataError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

enum class UdpProfile {
  kLegacy,
  kRng19Rfl8Sig16Nir16,      // RNG19_RFL8_SIG16_NIR16
  kRng19Rfl8Sig16Nir16Dual,  // RNG19_RFL8_SIG16_NIR16_DUAL
  kRng15Rfl8Nir8,            // RNG15_RFL8_NIR8 (low bandwidth, 8 mm steps)
};

// Sanity bound on beams: sensors have 16..128; more is a corrupt file, and
// would only make the decoder allocate absurd scans.
inline constexpr int kMaxPixelsPerColumn = 1024;

const char* toString(UdpProfile profile);
UdpProfile udpProfileFromString(const std::string& name);  // throws MetadataError

struct OusterMetadata {
  LidarIntrinsics intrinsics;  // tables in radians/metres, lidar_to_sensor in metres
  UdpProfile profile = UdpProfile::kLegacy;
  int columns_per_packet = 16;
  int columns_per_frame = 0;
  int pixels_per_column = 0;
  int udp_port_lidar = 7502;
  int udp_port_imu = 7503;
  std::string lidar_mode;  // "1024x10"
  std::string prod_line;
  std::string firmware;    // build_rev
  std::string serial;      // prod_sn
  uint32_t initialization_id = 0;  // packet headers carry its low 24 bits
  double frequency_hz = 10.0;
  std::string json;        // the original text, so it can travel with the data
};

// Parses either format. Defaults follow the manufacturer's tools where fields are
// absent (LEGACY profile, 16 columns per packet, pixel shifts and origin offset by
// product line). Missing/invalid beam tables, counts that disagree, or zeros
// where a value is required throw MetadataError naming the field.
OusterMetadata parseOusterMetadata(const std::string& json_text);
OusterMetadata loadOusterMetadata(const std::string& path);

}  // namespace range_image_mapping
