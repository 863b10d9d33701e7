// Reading real captures in tests: every complete scan, and the raw lidar payloads.
#pragma once

#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/ouster_packet.h"

#include <cstdint>
#include <string>
#include <vector>

namespace range_image_mapping::test {

using Packet = std::vector<uint8_t>;

inline std::vector<LidarScan> decodeCapture(const std::string& pcap_path, const OusterMetadata& metadata,
                                            io::OusterPcapStatistics* statistics = nullptr) {
  std::vector<LidarScan> scans;
  const io::OusterPcapStatistics result =
      io::readOusterScans(pcap_path, metadata, [&](const LidarScan& scan) { scans.push_back(scan); });
  if (statistics != nullptr) *statistics = result;
  return scans;
}

// The lidar payloads of a capture, in order.
inline std::vector<Packet> lidarPackets(const std::string& pcap_path, const OusterMetadata& metadata) {
  const std::size_t size = PacketFormat(metadata).packetSize();
  std::vector<Packet> packets;
  io::PcapReader reader(pcap_path);
  io::UdpDatagram datagram;
  while (reader.next(datagram))
    if (datagram.size == size) packets.emplace_back(datagram.payload, datagram.payload + datagram.size);
  return packets;
}

}  // namespace range_image_mapping::test
