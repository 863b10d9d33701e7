// Packets into complete revolutions, by frame id.
#pragma once

#include "range_image_mapping/ouster_packet.h"

#include <cstddef>
#include <cstdint>
#include <functional>

namespace range_image_mapping {

struct BatcherStatistics {
  std::size_t packets = 0;              // offered
  std::size_t wrong_size = 0;           // dropped: size differs from the profile's
  std::size_t malformed = 0;            // dropped: not a lidar packet / bad columns
  std::size_t bad_checksum = 0;         // dropped: CRC64 does not match (streams that carry one)
  std::size_t stale = 0;                // dropped: of an emitted frame, or a few frames late
  std::size_t scans = 0;                // emitted
  std::size_t incomplete_scans = 0;     // emitted with columns missing in the window
  std::size_t missing_columns = 0;      // total over emitted scans
};

// Feed it packet payloads in arrival order; it calls on_scan with each finished
// revolution: as soon as every column of the column window arrived (later
// packets of that frame are then stale), when the frame id changes, or on
// flush(). Columns that never arrived are invalid: no data ever leaks from the
// previous revolution. Frame ids are 16-bit and wrap; a packet up to
// kLateFrames frames behind the current one is stale, anything else starts a
// new revolution (e.g. after a sensor restart). One scan buffer is reused:
// no heap allocation per packet or per scan, so the scan handed to on_scan is
// valid during the callback only (convert or copy it there).
// Checksums: firmware 3.x ends every packet in a CRC64, 2.x does not. The
// first packets tell which: once one matches, the stream carries them, and a
// packet whose checksum does not match is damaged and dropped; after
// kChecksumProbePackets valid packets in a row without a match, the stream
// carries none and checksums are no longer computed.
class ScanBatcher {
 public:
  using ScanCallback = std::function<void(const LidarScan&)>;
  ScanBatcher(const OusterMetadata& metadata, ScanCallback on_scan);

  static constexpr uint32_t kLateFrames = 4;
  static constexpr int kChecksumProbePackets = 64;

  // Never throws for bad packets: they are dropped and counted.
  void addPacket(const uint8_t* data, std::size_t size);
  void flush();  // emit the revolution in progress, if any
  const BatcherStatistics& statistics() const { return statistics_; }
  const PacketFormat& format() const { return format_; }

 private:
  bool checksumAccepts(const uint8_t* data);
  bool isStale(uint32_t frame_id) const;
  void startScan(uint32_t frame_id);
  void emitScan();

  PacketFormat format_;
  ScanCallback on_scan_;
  LidarScan scan_;
  bool scan_used_ = false;  // a fresh scan is already zero
  BatcherStatistics statistics_;
  bool in_progress_ = false;
  int window_columns_received_ = 0;  // in the scan in progress
  bool emitted_any_ = false;
  uint32_t last_emitted_frame_id_ = 0;
  enum class Checksums { kUnknown, kPresent, kAbsent };
  Checksums checksums_;
  int packets_probed_ = 0;  // without a matching checksum, while kUnknown
};

}  // namespace range_image_mapping
