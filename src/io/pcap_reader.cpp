#include "range_image_mapping/io/pcap_reader.h"

#include <pcap/pcap.h>

#include <algorithm>
#include <array>
#include <vector>

namespace range_image_mapping::io {
namespace {

// Network headers are big-endian; bytes are read one at a time, so alignment
// never matters.
uint16_t readBigEndian16(const uint8_t* bytes) {
  return static_cast<uint16_t>(bytes[0] << 8 | bytes[1]);
}
uint32_t readBigEndian32(const uint8_t* bytes) {
  return static_cast<uint32_t>(bytes[0]) << 24 | static_cast<uint32_t>(bytes[1]) << 16 |
         static_cast<uint32_t>(bytes[2]) << 8 | bytes[3];
}

constexpr uint16_t kEtherTypeIpv4 = 0x0800;
constexpr uint16_t kEtherTypeVlan = 0x8100;      // 802.1Q
constexpr uint16_t kEtherTypeQinQ = 0x88A8;      // 802.1ad outer tag
constexpr uint16_t kEtherTypeVlanOld = 0x9100;   // pre-standard QinQ
constexpr std::size_t kEthernetHeaderSize = 14;
constexpr std::size_t kVlanTagSize = 4;
constexpr std::size_t kLinuxCookedHeaderSize = 16;   // SLL, protocol at 14
constexpr std::size_t kLinuxCooked2HeaderSize = 20;  // SLL2, protocol at 0
constexpr std::size_t kLoopbackHeaderSize = 4;       // address family
constexpr uint32_t kAddressFamilyIpv4 = 2;           // AF_INET on every BSD and Linux
constexpr std::size_t kIpv4MinimumHeaderSize = 20;
constexpr uint8_t kProtocolUdp = 17;
constexpr uint16_t kMoreFragments = 0x2000;
constexpr uint16_t kFragmentOffsetMask = 0x1FFF;
constexpr std::size_t kUdpHeaderSize = 8;
constexpr std::size_t kMaxIpv4Payload = 65535;
constexpr std::size_t kFragmentBlock = 8;  // fragment offsets count 8-byte blocks
constexpr std::size_t kReassemblySlots = 8;  // datagrams being rebuilt at once

#ifndef DLT_LINUX_SLL2
#define DLT_LINUX_SLL2 276
#endif

bool supportedLinkType(int link_type) {
  return link_type == DLT_EN10MB || link_type == DLT_LINUX_SLL || link_type == DLT_LINUX_SLL2 ||
         link_type == DLT_RAW || link_type == DLT_NULL || link_type == DLT_LOOP;
}

// One IPv4 datagram being rebuilt from its fragments.
struct Reassembly {
  bool in_use = false;
  uint32_t source = 0, destination = 0;
  uint16_t identification = 0;
  uint64_t age = 0;                // order of creation, to evict the oldest
  std::size_t fragments = 0;
  std::size_t total_size = 0;      // known once the last fragment arrived, else 0
  std::size_t end_seen = 0;        // largest offset + length so far
  std::size_t blocks_received = 0;
  std::vector<uint8_t> data;       // IPv4 payload, kMaxIpv4Payload bytes once used
  std::vector<uint8_t> block_received;
};

}  // namespace

struct PcapReader::State {
  std::string path;
  pcap_t* handle = nullptr;
  int link_type = 0;
  PcapStatistics statistics;
  std::array<Reassembly, kReassemblySlots> reassemblies;
  uint64_t reassembly_counter = 0;
  bool finished = false;

  ~State() {
    if (handle != nullptr) pcap_close(handle);
  }

  bool parseRecord(const uint8_t* bytes, std::size_t size, uint64_t timestamp_ns, UdpDatagram& out);
  bool parseIpv4(const uint8_t* bytes, std::size_t size, uint64_t timestamp_ns, UdpDatagram& out);
  bool parseUdp(const uint8_t* bytes, std::size_t size, uint32_t source, uint32_t destination,
                uint64_t timestamp_ns, UdpDatagram& out);
  bool addFragment(const uint8_t* payload, std::size_t size, std::size_t offset, bool more,
                   uint32_t source, uint32_t destination, uint16_t identification,
                   uint64_t timestamp_ns, UdpDatagram& out);
  void dropReassembly(Reassembly& reassembly);
  void finish();
};

bool PcapReader::State::parseRecord(const uint8_t* bytes, std::size_t size, uint64_t timestamp_ns,
                                    UdpDatagram& out) {
  uint16_t ether_type = 0;
  std::size_t offset = 0;
  switch (link_type) {
    case DLT_EN10MB:
      offset = kEthernetHeaderSize;
      if (size < offset) break;
      ether_type = readBigEndian16(bytes + offset - 2);
      while (ether_type == kEtherTypeVlan || ether_type == kEtherTypeQinQ ||
             ether_type == kEtherTypeVlanOld) {
        offset += kVlanTagSize;
        if (size < offset) break;
        ether_type = readBigEndian16(bytes + offset - 2);
      }
      break;
    case DLT_LINUX_SLL:
      offset = kLinuxCookedHeaderSize;
      if (size >= offset) ether_type = readBigEndian16(bytes + 14);
      break;
    case DLT_LINUX_SLL2:
      offset = kLinuxCooked2HeaderSize;
      if (size >= offset) ether_type = readBigEndian16(bytes);
      break;
    case DLT_NULL:
    case DLT_LOOP: {
      offset = kLoopbackHeaderSize;
      if (size < offset) break;
      // The family is in the capturing host's byte order (DLT_NULL): accept both.
      const uint32_t big = readBigEndian32(bytes);
      const uint32_t little = static_cast<uint32_t>(bytes[3]) << 24 |
                              static_cast<uint32_t>(bytes[2]) << 16 |
                              static_cast<uint32_t>(bytes[1]) << 8 | bytes[0];
      ether_type = big == kAddressFamilyIpv4 || little == kAddressFamilyIpv4 ? kEtherTypeIpv4 : 1;
      break;
    }
    default:  // DLT_RAW: the record starts with the IP header, IPv4 or IPv6
      offset = 0;
      if (size > 0) ether_type = (bytes[0] >> 4) == 4 ? kEtherTypeIpv4 : 1;
      break;
  }
  if (size < offset) {
    ++statistics.skipped_truncated;
    return false;
  }
  if (ether_type != kEtherTypeIpv4) {
    ++statistics.skipped_not_udp;
    return false;
  }
  return parseIpv4(bytes + offset, size - offset, timestamp_ns, out);
}

bool PcapReader::State::parseIpv4(const uint8_t* bytes, std::size_t size, uint64_t timestamp_ns,
                                  UdpDatagram& out) {
  if (size < kIpv4MinimumHeaderSize) {
    ++statistics.skipped_truncated;
    return false;
  }
  const std::size_t header_size = (bytes[0] & 0x0F) * 4u;
  const std::size_t total_size = readBigEndian16(bytes + 2);
  if ((bytes[0] >> 4) != 4 || header_size < kIpv4MinimumHeaderSize || total_size < header_size) {
    ++statistics.skipped_malformed;
    return false;
  }
  // Ethernet pads short frames, so the IP total length, not the record, ends the datagram.
  if (total_size > size) {
    ++statistics.skipped_truncated;
    return false;
  }
  if (bytes[9] != kProtocolUdp) {
    ++statistics.skipped_not_udp;
    return false;
  }
  const uint32_t source = readBigEndian32(bytes + 12);
  const uint32_t destination = readBigEndian32(bytes + 16);
  const uint16_t flags_and_offset = readBigEndian16(bytes + 6);
  const bool more_fragments = (flags_and_offset & kMoreFragments) != 0;
  const std::size_t fragment_offset = (flags_and_offset & kFragmentOffsetMask) * kFragmentBlock;
  const uint8_t* payload = bytes + header_size;
  const std::size_t payload_size = total_size - header_size;
  if (more_fragments || fragment_offset != 0) {
    ++statistics.fragments;
    return addFragment(payload, payload_size, fragment_offset, more_fragments, source, destination,
                       readBigEndian16(bytes + 4), timestamp_ns, out);
  }
  return parseUdp(payload, payload_size, source, destination, timestamp_ns, out);
}

bool PcapReader::State::parseUdp(const uint8_t* bytes, std::size_t size, uint32_t source,
                                 uint32_t destination, uint64_t timestamp_ns, UdpDatagram& out) {
  // The IP datagram is complete here, so a UDP length that does not fit is wrong, not cut.
  const std::size_t udp_size = size >= kUdpHeaderSize ? readBigEndian16(bytes + 4) : 0;
  if (udp_size < kUdpHeaderSize || udp_size > size) {
    ++statistics.skipped_malformed;
    return false;
  }
  out.payload = bytes + kUdpHeaderSize;
  out.size = udp_size - kUdpHeaderSize;
  out.source_address = source;
  out.destination_address = destination;
  out.source_port = readBigEndian16(bytes);
  out.destination_port = readBigEndian16(bytes + 2);
  out.timestamp_ns = timestamp_ns;
  ++statistics.udp_datagrams;
  return true;
}

void PcapReader::State::dropReassembly(Reassembly& reassembly) {
  statistics.fragments_dropped += reassembly.fragments;
  reassembly.in_use = false;
}

bool PcapReader::State::addFragment(const uint8_t* payload, std::size_t size, std::size_t offset,
                                    bool more, uint32_t source, uint32_t destination,
                                    uint16_t identification, uint64_t timestamp_ns,
                                    UdpDatagram& out) {
  // Only the last fragment may end off an 8-byte boundary; nothing may pass 64 KiB.
  if ((more && size % kFragmentBlock != 0) || offset + size > kMaxIpv4Payload) {
    ++statistics.fragments_dropped;
    return false;
  }
  Reassembly* slot = nullptr;
  for (Reassembly& candidate : reassemblies)
    if (candidate.in_use && candidate.source == source && candidate.destination == destination &&
        candidate.identification == identification)
      slot = &candidate;
  if (slot == nullptr) {
    // A free slot, or else the oldest unfinished datagram gives way.
    slot = &*std::min_element(reassemblies.begin(), reassemblies.end(),
                              [](const Reassembly& a, const Reassembly& b) {
                                if (a.in_use != b.in_use) return !a.in_use;
                                return a.age < b.age;
                              });
    if (slot->in_use) dropReassembly(*slot);
    slot->in_use = true;
    slot->source = source;
    slot->destination = destination;
    slot->identification = identification;
    slot->age = ++reassembly_counter;
    slot->fragments = 0;
    slot->total_size = 0;
    slot->end_seen = 0;
    slot->blocks_received = 0;
    slot->data.resize(kMaxIpv4Payload);
    slot->block_received.assign((kMaxIpv4Payload + kFragmentBlock - 1) / kFragmentBlock, 0);
  }
  Reassembly& reassembly = *slot;
  ++reassembly.fragments;
  std::copy(payload, payload + size, reassembly.data.begin() + static_cast<std::ptrdiff_t>(offset));
  for (std::size_t block = offset / kFragmentBlock;
       block < (offset + size + kFragmentBlock - 1) / kFragmentBlock; ++block) {
    reassembly.blocks_received += reassembly.block_received[block] == 0;
    reassembly.block_received[block] = 1;
  }
  reassembly.end_seen = std::max(reassembly.end_seen, offset + size);
  if (!more) {
    if (reassembly.total_size != 0 && reassembly.total_size != offset + size) {
      dropReassembly(reassembly);  // two different "last" fragments
      return false;
    }
    reassembly.total_size = offset + size;
  }
  if (reassembly.total_size == 0) return false;
  if (reassembly.end_seen > reassembly.total_size) {
    dropReassembly(reassembly);  // data past the announced end
    return false;
  }
  if (reassembly.blocks_received * kFragmentBlock < reassembly.total_size) return false;
  // Complete: the buffer stays valid until the slot is reused, after this call.
  reassembly.in_use = false;
  ++statistics.reassembled;
  return parseUdp(reassembly.data.data(), reassembly.total_size, source, destination, timestamp_ns,
                  out);
}

void PcapReader::State::finish() {
  if (finished) return;
  finished = true;
  for (Reassembly& reassembly : reassemblies)
    if (reassembly.in_use) dropReassembly(reassembly);
}

PcapReader::PcapReader(const std::string& path) : state_(std::make_unique<State>()) {
  state_->path = path;
  char error[PCAP_ERRBUF_SIZE] = "";
  // Nanosecond precision: libpcap scales microsecond files up, so one code path.
  state_->handle =
      pcap_open_offline_with_tstamp_precision(path.c_str(), PCAP_TSTAMP_PRECISION_NANO, error);
  if (state_->handle == nullptr)
    throw PcapError("pcap: cannot open '" + path + "': " + std::string(error));
  state_->link_type = pcap_datalink(state_->handle);
  if (!supportedLinkType(state_->link_type)) {
    const char* name = pcap_datalink_val_to_name(state_->link_type);
    throw PcapError("pcap: '" + path + "' has link type " + std::to_string(state_->link_type) +
                    " (" + (name != nullptr ? name : "unknown") +
                    "); supported: EN10MB, LINUX_SLL, LINUX_SLL2, RAW, NULL, LOOP");
  }
}

PcapReader::~PcapReader() = default;

bool PcapReader::next(UdpDatagram& datagram) {
  State& state = *state_;
  while (!state.finished) {
    pcap_pkthdr* header = nullptr;
    const u_char* bytes = nullptr;
    const int result = pcap_next_ex(state.handle, &header, &bytes);
    if (result == PCAP_ERROR_BREAK) break;  // end of file
    if (result == PCAP_ERROR) {
      state.statistics.stopped_early = pcap_geterr(state.handle);
      break;
    }
    if (result != 1) continue;  // 0 is a live-capture timeout, not seen offline
    ++state.statistics.records;
    const uint64_t timestamp_ns = static_cast<uint64_t>(header->ts.tv_sec) * 1000000000ull +
                                  static_cast<uint64_t>(header->ts.tv_usec);
    if (state.parseRecord(bytes, header->caplen, timestamp_ns, datagram)) return true;
  }
  state.finish();
  return false;
}

const PcapStatistics& PcapReader::statistics() const { return state_->statistics; }
const std::string& PcapReader::path() const { return state_->path; }

namespace {

bool anyDatagramToPort(const std::string& pcap_path, int port) {
  PcapReader reader(pcap_path);
  UdpDatagram datagram;
  while (reader.next(datagram))
    if (datagram.destination_port == port) return true;
  return false;
}

}  // namespace

OusterPcapStatistics readOusterScans(const std::string& pcap_path, const OusterMetadata& metadata,
                                     const ScanBatcher::ScanCallback& on_scan, const bool* stop) {
  OusterPcapStatistics statistics;
  ScanBatcher batcher(metadata, on_scan);
  const std::size_t lidar_size = batcher.format().packetSize();
  // With lidar and IMU on one port only the size tells them apart.
  statistics.classified_by_size = metadata.udp_port_lidar == metadata.udp_port_imu ||
                                  !anyDatagramToPort(pcap_path, metadata.udp_port_lidar);
  PcapReader reader(pcap_path);
  UdpDatagram datagram;
  while (reader.next(datagram)) {
    const bool lidar = statistics.classified_by_size
                           ? datagram.size == lidar_size
                           : datagram.destination_port == metadata.udp_port_lidar;
    if (lidar) {
      ++statistics.lidar_datagrams;
      batcher.addPacket(datagram.payload, datagram.size);
      if (stop && *stop) break;
    } else {
      ++statistics.other_datagrams;
    }
  }
  if (!(stop && *stop)) batcher.flush();
  statistics.pcap = reader.statistics();
  statistics.batcher = batcher.statistics();
  return statistics;
}

std::vector<RangeImage> readOusterRangeImages(const std::string& pcap_path, const OusterMetadata& metadata,
                                              ReturnIndex which) {
  const auto model = std::make_shared<const LidarModel>(metadata.intrinsics);
  std::vector<RangeImage> images;
  readOusterScans(pcap_path, metadata, [&](const LidarScan& scan) {
    if (scan.receivedColumns() > 0) images.push_back(toRangeImage(scan, model, which));
  });
  return images;
}

}  // namespace range_image_mapping::io
