#include "range_image_mapping/io/pcap_writer.h"

#include <pcap/pcap.h>

#include <algorithm>
#include <cstdio>
#include <vector>

namespace range_image_mapping::io {
namespace {

constexpr std::size_t kEthernetHeaderSize = 14;
constexpr std::size_t kIpv4HeaderSize = 20;  // no options
constexpr std::size_t kUdpHeaderSize = 8;
constexpr std::size_t kMaxIpv4Size = 65535;
constexpr std::size_t kMaxUdpPayload = kMaxIpv4Size - kIpv4HeaderSize - kUdpHeaderSize;
constexpr std::size_t kMinimumMtu = 68;    // RFC 791: every host must pass 68-byte packets
constexpr std::size_t kFragmentBlock = 8;  // fragment offsets count 8-byte blocks
constexpr int kSnapshotLength = 65535;
constexpr uint16_t kEtherTypeIpv4 = 0x0800;
constexpr uint8_t kProtocolUdp = 17;
constexpr uint8_t kTimeToLive = 64;
constexpr uint16_t kMoreFragments = 0x2000;
constexpr uint32_t kLoopbackAddress = 0x7F000001;  // 127.0.0.1

// Network headers are big-endian: written byte by byte.
void writeBigEndian16(uint8_t* bytes, uint16_t value) {
  bytes[0] = static_cast<uint8_t>(value >> 8);
  bytes[1] = static_cast<uint8_t>(value);
}
void writeBigEndian32(uint8_t* bytes, uint32_t value) {
  writeBigEndian16(bytes, static_cast<uint16_t>(value >> 16));
  writeBigEndian16(bytes + 2, static_cast<uint16_t>(value));
}

// RFC 1071 ones' complement sum, not yet folded or inverted.
uint32_t onesComplementSum(const uint8_t* bytes, std::size_t size, uint32_t sum = 0) {
  for (std::size_t i = 0; i + 1 < size; i += 2) sum += static_cast<uint32_t>(bytes[i] << 8 | bytes[i + 1]);
  if (size % 2 != 0) sum += static_cast<uint32_t>(bytes[size - 1] << 8);
  return sum;
}
uint16_t finishChecksum(uint32_t sum) {
  while (sum >> 16) sum = (sum & 0xFFFF) + (sum >> 16);
  return static_cast<uint16_t>(~sum);
}

uint16_t udpPort(int port) {
  if (port <= 0 || port > 65535)
    throw std::invalid_argument("OusterPcapWriter: udp_port_lidar " + std::to_string(port) +
                                " is not a UDP port");
  return static_cast<uint16_t>(port);
}

}  // namespace

struct PcapWriter::State {
  std::string path;
  PcapWriterOptions options;
  pcap_t* handle = nullptr;
  pcap_dumper_t* dumper = nullptr;
  uint16_t identification = 0;
  std::size_t datagrams = 0;
  std::size_t records = 0;
  std::vector<uint8_t> udp;    // UDP header + payload of the datagram being written
  std::vector<uint8_t> frame;  // one record

  ~State() {
    if (dumper != nullptr) pcap_dump_close(dumper);
    if (handle != nullptr) pcap_close(handle);
  }

  void writeRecord(const uint8_t* ip_payload, std::size_t size, std::size_t fragment_offset,
                   bool more_fragments, const UdpDatagram& datagram);
};

PcapWriter::PcapWriter(const std::string& path, PcapWriterOptions options)
    : state_(std::make_unique<State>()) {
  if (options.mtu != 0 && options.mtu < kMinimumMtu)
    throw std::invalid_argument("PcapWriter: MTU " + std::to_string(options.mtu) +
                                " is below the IPv4 minimum of 68 bytes (0: no fragmentation)");
  state_->path = path;
  state_->options = options;
  state_->handle = pcap_open_dead_with_tstamp_precision(DLT_EN10MB, kSnapshotLength,
                                                        PCAP_TSTAMP_PRECISION_MICRO);
  if (state_->handle == nullptr) throw PcapError("pcap " + path + ": libpcap could not start a capture");
  state_->dumper = pcap_dump_open(state_->handle, path.c_str());
  if (state_->dumper == nullptr)
    throw PcapError("pcap " + path + ": cannot write: " + pcap_geterr(state_->handle));
}

PcapWriter::~PcapWriter() = default;

void PcapWriter::State::writeRecord(const uint8_t* ip_payload, std::size_t size,
                                    std::size_t fragment_offset, bool more_fragments,
                                    const UdpDatagram& datagram) {
  frame.assign(kEthernetHeaderSize + kIpv4HeaderSize + size, 0);
  writeBigEndian16(frame.data() + 12, kEtherTypeIpv4);  // MAC addresses stay zero
  uint8_t* ip = frame.data() + kEthernetHeaderSize;
  ip[0] = 0x45;  // version 4, 5 words of header
  writeBigEndian16(ip + 2, static_cast<uint16_t>(kIpv4HeaderSize + size));
  writeBigEndian16(ip + 4, identification);
  writeBigEndian16(ip + 6, static_cast<uint16_t>((more_fragments ? kMoreFragments : 0) |
                                                 fragment_offset / kFragmentBlock));
  ip[8] = kTimeToLive;
  ip[9] = kProtocolUdp;
  writeBigEndian32(ip + 12, datagram.source_address);
  writeBigEndian32(ip + 16, datagram.destination_address);
  writeBigEndian16(ip + 10, finishChecksum(onesComplementSum(ip, kIpv4HeaderSize)));
  std::copy(ip_payload, ip_payload + size, ip + kIpv4HeaderSize);

  pcap_pkthdr header{};
  header.ts.tv_sec = static_cast<time_t>(datagram.timestamp_ns / 1000000000u);
  header.ts.tv_usec = static_cast<suseconds_t>(datagram.timestamp_ns % 1000000000u / 1000u);
  header.caplen = header.len = static_cast<bpf_u_int32>(frame.size());
  pcap_dump(reinterpret_cast<u_char*>(dumper), &header, frame.data());
  ++records;
}

void PcapWriter::write(const UdpDatagram& datagram) {
  State& state = *state_;
  if (state.dumper == nullptr) throw PcapError("pcap " + state.path + ": written after close()");
  if (datagram.size > kMaxUdpPayload)
    throw PcapError("pcap " + state.path + ": a UDP payload of " + std::to_string(datagram.size) +
                    " bytes exceeds the IPv4 limit of " + std::to_string(kMaxUdpPayload));
  if (datagram.size > 0 && datagram.payload == nullptr)
    throw std::invalid_argument("PcapWriter::write: payload is null");

  const std::size_t udp_size = kUdpHeaderSize + datagram.size;
  state.udp.assign(udp_size, 0);
  uint8_t* udp = state.udp.data();
  writeBigEndian16(udp, datagram.source_port);
  writeBigEndian16(udp + 2, datagram.destination_port);
  writeBigEndian16(udp + 4, static_cast<uint16_t>(udp_size));
  if (datagram.size > 0) std::copy(datagram.payload, datagram.payload + datagram.size, udp + kUdpHeaderSize);
  // Checksum over the pseudo header (addresses, protocol, length) and the datagram.
  uint8_t pseudo_header[12] = {};
  writeBigEndian32(pseudo_header, datagram.source_address);
  writeBigEndian32(pseudo_header + 4, datagram.destination_address);
  pseudo_header[9] = kProtocolUdp;
  writeBigEndian16(pseudo_header + 10, static_cast<uint16_t>(udp_size));
  const uint16_t checksum =
      finishChecksum(onesComplementSum(udp, udp_size, onesComplementSum(pseudo_header, 12)));
  writeBigEndian16(udp + 6, checksum == 0 ? 0xFFFF : checksum);  // 0 would mean "no checksum"

  const std::size_t mtu = state.options.mtu;
  if (mtu == 0 || kIpv4HeaderSize + udp_size <= mtu) {
    state.writeRecord(udp, udp_size, 0, false, datagram);
  } else {
    // Every fragment but the last carries a multiple of 8 bytes.
    const std::size_t fragment_size = (mtu - kIpv4HeaderSize) / kFragmentBlock * kFragmentBlock;
    for (std::size_t offset = 0; offset < udp_size; offset += fragment_size) {
      const std::size_t size = std::min(fragment_size, udp_size - offset);
      state.writeRecord(udp + offset, size, offset, offset + size < udp_size, datagram);
    }
  }
  ++state.identification;
  ++state.datagrams;
}

void PcapWriter::close() {
  State& state = *state_;
  if (state.dumper == nullptr) return;
  const bool failed = pcap_dump_flush(state.dumper) != 0 || std::ferror(pcap_dump_file(state.dumper));
  pcap_dump_close(state.dumper);
  state.dumper = nullptr;
  if (failed) throw PcapError("pcap " + state.path + ": writing failed (disk full?)");
}

std::size_t PcapWriter::datagramsWritten() const { return state_->datagrams; }
std::size_t PcapWriter::recordsWritten() const { return state_->records; }
const std::string& PcapWriter::path() const { return state_->path; }

OusterPcapWriter::OusterPcapWriter(const std::string& path, const OusterMetadata& metadata,
                                   PcapWriterOptions options, int64_t record_time_offset_ns)
    : encoder_(metadata),
      lidar_port_(udpPort(metadata.udp_port_lidar)),
      writer_(path, options),
      record_time_offset_ns_(record_time_offset_ns) {}

std::size_t OusterPcapWriter::writeScan(const LidarScan& scan) {
  UdpDatagram datagram;
  datagram.source_address = datagram.destination_address = kLoopbackAddress;
  datagram.source_port = datagram.destination_port = lidar_port_;
  return encoder_.encode(scan, [&](const uint8_t* packet, std::size_t size, uint64_t timestamp_ns) {
    const int64_t record_time_ns = static_cast<int64_t>(timestamp_ns) + record_time_offset_ns_;
    if (record_time_ns < 0)
      throw std::invalid_argument("OusterPcapWriter: packet time " + std::to_string(timestamp_ns) +
                                  " ns plus the record time offset is negative");
    datagram.payload = packet;
    datagram.size = size;
    datagram.timestamp_ns = static_cast<uint64_t>(record_time_ns);
    writer_.write(datagram);
  });
}

}  // namespace range_image_mapping::io
