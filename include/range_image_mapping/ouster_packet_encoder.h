// Scans back into Ouster lidar packets: the inverse of PacketFormat::decode,
// so simulated scans travel as pcaps and bags any Ouster tool can read.
#pragma once

#include "range_image_mapping/ouster_packet.h"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <vector>

namespace range_image_mapping {

// A scan the packets cannot carry (a value too large for the profile's field,
// a missing field, a size that differs from the metadata); what() names the
// field, the pixel and the limit.
class PacketEncodingError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// Column status the decoder takes for a valid column: LEGACY 0xFFFFFFFF, the
// other profiles 1 (bit 0 set).
uint32_t validColumnStatus(UdpProfile profile);

// The LEGACY encoder count of a column: 90112 ticks per revolution, the value
// the sensors report (column * 90112 / columns).
uint32_t legacyEncoderCount(int column, int columns);

// Largest range in millimetres the profile can carry: LEGACY 2^20 - 1,
// RNG19 profiles 2^19 - 1, RNG15_RFL8_NIR8 (2^15 - 1) * 8.
uint32_t maxRangeMillimetres(UdpProfile profile);

// Rounds a scan to what the profile carries, so that decoding its packets gives
// the scan back exactly: ranges beyond maxRangeMillimetres become 0 (no
// return), and for RNG15_RFL8_NIR8 ranges go to the nearest 8 mm and near-IR to
// the nearest multiple of 16 (at most 4080). The fields are sized as the
// profile carries them (empty second returns for the dual profile, no signal
// for RNG15). Column statuses become the
// profile's valid status (or 0), encoder counts exist only in LEGACY, and
// columns that are not valid lose their timestamps.
void quantizeForProfile(LidarScan& scan, UdpProfile profile);

// CRC-64/XZ (ECMA-182 polynomial, reflected, init and final xor all ones): the
// last 8 bytes of the packet footer of firmware 3.x, over every byte before them.
uint64_t crc64(const uint8_t* data, std::size_t size);

// Encodes with the layouts of ouster-pcaps/SOURCE.md, little-endian:
// - packets hold columns_per_packet consecutive measurement ids, starting at a
//   multiple of it, and come in measurement-id order (a revolution starts at
//   measurement id 0, also when the column window wraps);
// - a packet is sent when at least one of its columns is valid (status != 0):
//   packets of columns outside the column window, or lost ones, are not sent;
// - a valid column gets the profile's valid status (validColumnStatus), the
//   scan's timestamp, pixels and (LEGACY) encoder count; an invalid column of a
//   sent packet gets status 0, zero pixels, its measurement id, and the scan's
//   timestamp (the sensor stamps every column it fires);
// - the frame id is the scan's, modulo 2^16 (the sensor's counter wraps);
// - non-LEGACY packet headers carry packet type 1, the frame id, the
//   metadata's initialization_id (24 bits) and serial number (40 bits); alert
//   flags and countdowns are 0; the footer is zero but for its last 8 bytes,
//   the CRC-64 of firmware 3.x (older firmware leaves that filler unchecked).
// Per-pixel flag bits (LEGACY bits 20-31 of the range word, RNG19 bits 19-31
// and the window byte, RNG15 bit 15) are 0: LidarScan does not hold them.
// decode(encode(scan)) == scan field for field when the scan was made for this
// profile (LidarScan(rows, columns, profile)), its values fit the profile
// (quantizeForProfile), its statuses are 0 or validColumnStatus, measurement_id
// holds the column index in valid columns, and invalid columns are all zero.
class OusterPacketEncoder {
 public:
  // Throws std::invalid_argument for metadata PacketFormat rejects, or whose
  // columns_per_frame is not a multiple of columns_per_packet, or whose
  // serial number is not a number below 2^40.
  explicit OusterPacketEncoder(const OusterMetadata& metadata);

  const PacketFormat& format() const { return format_; }

  // timestamp_ns: the latest column timestamp in the packet, i.e. when the
  // sensor sends it (for pcap records and bag message times).
  using PacketCallback =
      std::function<void(const uint8_t* packet, std::size_t size, uint64_t timestamp_ns)>;

  // Calls on_packet for every packet of the revolution, with a buffer that is
  // valid during the call only. Returns the number of packets. Throws
  // PacketEncodingError (before any packet is handed out) for a scan of the
  // wrong size or profile, or with a value the profile cannot carry.
  std::size_t encode(const LidarScan& scan, const PacketCallback& on_packet) const;
  std::vector<std::vector<uint8_t>> encode(const LidarScan& scan) const;

 private:
  void checkScan(const LidarScan& scan) const;
  template <typename PixelLayout>
  void encodePacket(const LidarScan& scan, int first_column, uint8_t* packet) const;

  PacketFormat format_;
  uint32_t initialization_id_;
  uint64_t serial_number_;
  std::size_t header_size_;
  std::size_t column_size_;
};

}  // namespace range_image_mapping
