#include "range_image_mapping/scan_batcher.h"

#include <utility>

namespace range_image_mapping {
namespace {

constexpr uint32_t kFrameIdModulo = 1u << 16;  // frame ids are u16 on the wire

// How many frames `frame_id` lies behind `reference`, modulo the 16-bit wrap.
uint32_t framesBehind(uint32_t frame_id, uint32_t reference) {
  return (reference - frame_id) % kFrameIdModulo;
}

}  // namespace

ScanBatcher::ScanBatcher(const OusterMetadata& metadata, ScanCallback on_scan)
    : format_(metadata),
      on_scan_(std::move(on_scan)),
      scan_(format_.rows(), format_.columns(), format_.profile()),
      checksums_(format_.profile() == UdpProfile::kLegacy ? Checksums::kAbsent : Checksums::kUnknown) {}

bool ScanBatcher::checksumAccepts(const uint8_t* data) {
  if (checksums_ == Checksums::kAbsent) return true;
  const bool matches = format_.checksumMatches(data);
  if (checksums_ == Checksums::kPresent) return matches;
  if (matches)
    checksums_ = Checksums::kPresent;
  else if (++packets_probed_ >= kChecksumProbePackets)
    checksums_ = Checksums::kAbsent;
  return true;
}

bool ScanBatcher::isStale(uint32_t frame_id) const {
  if (in_progress_) {
    const uint32_t behind = framesBehind(frame_id, scan_.frame_id);
    return behind > 0 && behind <= kLateFrames;
  }
  // The last emitted frame itself is stale too: it was complete.
  return emitted_any_ && framesBehind(frame_id, last_emitted_frame_id_) <= kLateFrames;
}

void ScanBatcher::addPacket(const uint8_t* data, std::size_t size) {
  ++statistics_.packets;
  switch (format_.validate(data, size)) {
    case PacketFormat::Result::kOk: break;
    case PacketFormat::Result::kWrongSize: ++statistics_.wrong_size; return;
    case PacketFormat::Result::kBadColumn:
    case PacketFormat::Result::kNotLidar: ++statistics_.malformed; return;
  }
  if (!checksumAccepts(data)) {
    ++statistics_.bad_checksum;
    return;
  }
  const uint32_t frame_id = format_.frameId(data);
  if (!in_progress_ || frame_id != scan_.frame_id) {
    if (isStale(frame_id)) {
      ++statistics_.stale;
      return;
    }
    if (in_progress_) emitScan();
    startScan(frame_id);
  }
  int new_columns = 0;
  format_.decode(data, size, scan_, &new_columns);
  window_columns_received_ += new_columns;
  if (window_columns_received_ == format_.columnWindowWidth()) emitScan();
}

void ScanBatcher::flush() {
  if (in_progress_) emitScan();
}

void ScanBatcher::startScan(uint32_t frame_id) {
  // Reset here rather than after emitting, so a throwing callback can never
  // leave the previous revolution's pixels in the next scan.
  if (scan_used_) scan_.reset();
  scan_used_ = true;
  scan_.frame_id = frame_id;
  window_columns_received_ = 0;
  in_progress_ = true;
}

void ScanBatcher::emitScan() {
  in_progress_ = false;
  emitted_any_ = true;
  last_emitted_frame_id_ = scan_.frame_id;
  const int missing = format_.columnWindowWidth() - window_columns_received_;
  ++statistics_.scans;
  if (missing > 0) {
    ++statistics_.incomplete_scans;
    statistics_.missing_columns += static_cast<std::size_t>(missing);
  }
  if (on_scan_) on_scan_(scan_);
}

}  // namespace range_image_mapping
