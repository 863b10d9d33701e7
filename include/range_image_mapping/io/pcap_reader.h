// Offline pcap / pcapng captures: UDP datagrams out of Ethernet (with 802.1Q
// VLAN tags), Linux cooked (SLL, SLL2), BSD loopback or raw IPv4 frames, with
// IPv4 fragments reassembled. And the Ouster shortcut: a capture straight into
// scans.
#pragma once

#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/scan_batcher.h"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping::io {

// The file is missing, not a capture, of an unsupported link type, or broken;
// what() names the file and gives libpcap's message.
class PcapError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct UdpDatagram {
  const uint8_t* payload = nullptr;  // valid until the next call of PcapReader::next
  std::size_t size = 0;
  uint32_t source_address = 0;       // IPv4, host byte order
  uint32_t destination_address = 0;
  uint16_t source_port = 0;
  uint16_t destination_port = 0;
  uint64_t timestamp_ns = 0;         // capture time (of the last fragment if fragmented)
};

// Every record read lands in exactly one of the "skipped" counters, becomes a
// datagram, or is a fragment (counted in fragments).
struct PcapStatistics {
  std::size_t records = 0;            // frames read from the file
  std::size_t udp_datagrams = 0;      // returned by next()
  std::size_t skipped_not_udp = 0;    // not IPv4/UDP: ARP, IPv6, TCP, ...
  std::size_t skipped_truncated = 0;  // captured bytes shorter than the headers announce
  std::size_t skipped_malformed = 0;  // IPv4/UDP headers that cannot be right
  std::size_t fragments = 0;          // IPv4 fragments read
  std::size_t reassembled = 0;        // datagrams rebuilt from fragments (also in udp_datagrams)
  std::size_t fragments_dropped = 0;  // fragments of datagrams that never completed or were inconsistent
  // Empty unless reading stopped early at a damaged record (e.g. a capture cut
  // off mid-record): then libpcap's message. The datagrams before it are kept.
  std::string stopped_early;
};

class PcapReader {
 public:
  // Throws PcapError naming the path and libpcap's message.
  explicit PcapReader(const std::string& path);
  ~PcapReader();
  PcapReader(const PcapReader&) = delete;
  PcapReader& operator=(const PcapReader&) = delete;

  // The next UDP datagram, or false at the end of the capture.
  bool next(UdpDatagram& datagram);
  const PcapStatistics& statistics() const;
  const std::string& path() const;

 private:
  struct State;  // libpcap handle and reassembly buffers, kept out of this header
  std::unique_ptr<State> state_;
};

struct OusterPcapStatistics {
  PcapStatistics pcap;
  BatcherStatistics batcher;
  std::size_t lidar_datagrams = 0;  // given to the batcher
  std::size_t other_datagrams = 0;  // IMU and anything else
  // No datagram went to metadata.udp_port_lidar (re-routed or rewritten
  // capture), so lidar packets were recognised by their size instead.
  bool classified_by_size = false;
};

// Reads a capture into scans: datagrams to metadata.udp_port_lidar (or of the
// lidar packet size, see classified_by_size) go through a ScanBatcher, which is
// flushed at the end. Throws PcapError for files that cannot be read.
// stop, when given, is looked at after each packet: once true, reading ends
// there (no flush) with the statistics so far.
OusterPcapStatistics readOusterScans(const std::string& pcap_path, const OusterMetadata& metadata,
                                     const ScanBatcher::ScanCallback& on_scan, const bool* stop = nullptr);

// Every scan of a capture that has any column, as range images sharing one
// model of the metadata. Throws like readOusterScans.
std::vector<RangeImage> readOusterRangeImages(const std::string& pcap_path, const OusterMetadata& metadata,
                                              ReturnIndex which = ReturnIndex::kFirst);

}  // namespace range_image_mapping::io
