// libFuzzer: arbitrary text as Ouster metadata. The parser may only throw the
// documented MetadataError or IntrinsicsError; anything accepted must give a
// consistent packet format.
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/ouster_packet.h"

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

namespace rim = range_image_mapping;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  rim::OusterMetadata metadata;
  try {
    metadata = rim::parseOusterMetadata(text);
  } catch (const rim::MetadataError&) {
    return 0;
  } catch (const rim::IntrinsicsError&) {
    return 0;
  }
  const rim::LidarIntrinsics& intrinsics = metadata.intrinsics;
  if (intrinsics.rows != metadata.pixels_per_column ||
      intrinsics.columns != metadata.columns_per_frame ||
      static_cast<int>(intrinsics.altitude_rad.size()) != intrinsics.rows ||
      static_cast<int>(intrinsics.pixel_shift_by_row.size()) != intrinsics.rows ||
      metadata.columns_per_packet < 1 || metadata.columns_per_packet > metadata.columns_per_frame)
    std::abort();
  const rim::PacketFormat format(metadata);
  if (format.packetSize() == 0 || format.columnWindowWidth() < 1 ||
      format.columnWindowWidth() > metadata.columns_per_frame)
    std::abort();
  return 0;
}
