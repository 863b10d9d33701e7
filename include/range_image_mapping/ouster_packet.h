// Ouster lidar packet layouts and the decoded scan in raw sensor units.
#pragma once

#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/range_image.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace range_image_mapping {

// Facts of a profile's pixel layout.
std::size_t pixelBytes(UdpProfile profile);
bool hasSignal(UdpProfile profile);        // all but RNG15_RFL8_NIR8
bool hasSecondReturn(UdpProfile profile);  // the dual-return profile

// One revolution in the sensor's own units, staggered (column = measurement id),
// row-major H x W. Missing columns stay zero with status 0.
struct LidarScan {
  int rows = 0;
  int columns = 0;
  uint32_t frame_id = 0;
  std::vector<uint32_t> range;         // mm, 0 = no return
  std::vector<uint32_t> range2;        // second return (dual profile only), mm
  std::vector<uint8_t> reflectivity;
  std::vector<uint8_t> reflectivity2;  // dual profile only
  std::vector<uint16_t> signal;        // empty for RNG15_RFL8_NIR8
  std::vector<uint16_t> signal2;       // dual profile only
  std::vector<uint16_t> near_ir;
  std::vector<uint64_t> timestamp_ns;  // W
  std::vector<uint16_t> measurement_id;  // W
  std::vector<uint32_t> status;        // W, 0 = column not received / invalid
  std::vector<uint32_t> encoder_count;  // W (LEGACY only, else 0)

  LidarScan() = default;
  LidarScan(int rows, int columns, UdpProfile profile);
  std::size_t receivedColumns() const;  // status != 0
  // Back to "nothing received", keeping the allocation.
  void reset();
};

// Layout of one lidar packet for a given metadata.
//
// LEGACY: 16 (or columns_per_packet) columns of
//   [u64 timestamp, u16 measurement id, u16 frame id, u32 encoder] H x 12 B [u32 status].
// Other profiles: 32 B header (u16 packet type, u16 frame id, ...), columns of
//   [u64 timestamp, u16 measurement id, u16 status] H x pixel bytes, 32 B footer
//   (firmware 3.x: its last 8 bytes are a CRC64 of the packet before them).
// Everything little-endian.
class PacketFormat {
 public:
  // Throws std::invalid_argument for sizes no sensor has (non-positive rows or columns).
  explicit PacketFormat(const OusterMetadata& metadata);
  std::size_t packetSize() const { return packet_size_; }
  int columnsPerPacket() const { return columns_per_packet_; }
  UdpProfile profile() const { return profile_; }
  int rows() const { return rows_; }
  int columns() const { return columns_; }
  int columnWindowWidth() const { return column_window_width_; }
  bool columnInWindow(int column) const { return in_window_[column] != 0; }

  // Frame id of a packet of the right size (LEGACY: first column's frame id).
  uint32_t frameId(const uint8_t* packet) const;
  // Whether a packet of the right size ends in the CRC64 of everything before
  // it (CRC-64/XZ: ECMA-182, reflected, initial value and final XOR all ones).
  // Firmware 3.x writes it in the last 8 bytes of the footer; 2.x does not,
  // and LEGACY packets have no footer (always false).
  bool checksumMatches(const uint8_t* packet) const;

  enum class Result { kOk, kWrongSize, kBadColumn, kNotLidar };
  // Checks a packet without decoding it: size, packet type, every measurement id
  // inside [0, W) and (LEGACY) one frame id for all columns.
  Result validate(const uint8_t* packet, std::size_t size) const;
  // Validates, then writes every valid column of the packet into scan (sized
  // for this format). A packet that fails validation writes nothing.
  // new_window_columns (optional) receives how many window columns were not
  // valid in scan before and are now.
  Result decode(const uint8_t* packet, std::size_t size, LidarScan& scan,
                int* new_window_columns = nullptr) const;

 private:
  template <typename PixelLayout>
  int decodeColumns(const uint8_t* packet, LidarScan& scan) const;
  uint16_t measurementId(const uint8_t* packet, int column_in_packet) const;

  UdpProfile profile_;
  int rows_;
  int columns_;
  int columns_per_packet_;
  std::size_t header_size_;  // packet header (0 for LEGACY)
  std::size_t column_size_;
  std::size_t packet_size_;
  int column_window_width_;
  std::vector<uint8_t> in_window_;  // per column, 1 inside column_window
};

// Which return to convert, and which field becomes intensity.
enum class ReturnIndex { kFirst, kSecond };

// Raw scan -> range image in metres (NaN where range is 0), staggered, with
// reflectivity as intensity and column timestamps (0 for missing columns).
// stamp_ns = timestamp of the lowest valid column (a frame starts at measurement
// id 0, also when the column window wraps). Throws
// std::invalid_argument when the scan and model sizes differ, or kSecond is
// asked of a single-return scan.
RangeImage toRangeImage(const LidarScan& scan, const LidarModelConstPtr& model,
                        ReturnIndex which = ReturnIndex::kFirst);
// The same into an existing image, whose buffers are reused when it already has
// this model (no allocation per frame in steady state).
void toRangeImage(const LidarScan& scan, const LidarModelConstPtr& model, ReturnIndex which,
                  RangeImage& image);

}  // namespace range_image_mapping
