// Writing pcap captures with libpcap: UDP datagrams in Ethernet + IPv4 frames
// (the link type and framing the ouster-sdk records sensors with), and the
// Ouster shortcut: scans straight into a capture. io::PcapReader reads them back.
#pragma once

#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/ouster_packet_encoder.h"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

namespace range_image_mapping::io {

struct PcapWriterOptions {
  // 0 (default): a datagram is one record however large, with an IPv4 total
  // length beyond any Ethernet MTU and a snaplen of 65535, as the ouster-sdk
  // writes its captures (8 to 25 KB lidar packets). Otherwise: the largest IPv4
  // packet on the wire, at least 68; larger datagrams become IPv4 fragments of
  // that size (one record each), as tcpdump shows them on a real network.
  std::size_t mtu = 0;
};

// Classic pcap, microsecond timestamps, link type Ethernet. Ethernet addresses
// are zero, IPv4 headers carry a checksum, an identification counting up per
// datagram and a TTL of 64; UDP headers carry a checksum.
class PcapWriter {
 public:
  // Throws PcapError naming the path and libpcap's message, and
  // std::invalid_argument for an MTU below 68.
  explicit PcapWriter(const std::string& path, PcapWriterOptions options = {});
  ~PcapWriter();  // closes; call close() first to learn about write errors
  PcapWriter(const PcapWriter&) = delete;
  PcapWriter& operator=(const PcapWriter&) = delete;

  // One datagram: its payload, addresses, ports and timestamp (the record
  // time). Throws PcapError for a payload above 65507 bytes (the IPv4 limit),
  // or after close().
  void write(const UdpDatagram& datagram);
  // Flushes and closes; throws PcapError when the file could not be written.
  void close();

  std::size_t datagramsWritten() const;
  std::size_t recordsWritten() const;  // more than datagrams when fragmenting
  const std::string& path() const;

 private:
  struct State;  // libpcap handles, kept out of this header
  std::unique_ptr<State> state_;
};

// Ouster scans into a capture: every packet goes from 127.0.0.1 to 127.0.0.1,
// source and destination port metadata.udp_port_lidar, recorded at the packet's
// timestamp (its latest column) plus record_time_offset_ns. readOusterScans
// with the same metadata gives the scans back.
class OusterPcapWriter {
 public:
  OusterPcapWriter(const std::string& path, const OusterMetadata& metadata,
                   PcapWriterOptions options = {}, int64_t record_time_offset_ns = 0);

  // Returns the number of packets written. Throws like OusterPacketEncoder::encode
  // (nothing written then) and PcapWriter::write.
  std::size_t writeScan(const LidarScan& scan);
  void close() { writer_.close(); }

  const OusterPacketEncoder& encoder() const { return encoder_; }
  PcapWriter& pcap() { return writer_; }

 private:
  OusterPacketEncoder encoder_;
  uint16_t lidar_port_;  // checked before the file is created
  PcapWriter writer_;
  int64_t record_time_offset_ns_;
};

}  // namespace range_image_mapping::io
