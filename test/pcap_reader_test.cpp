// pcap reading: errors, link layers, VLAN tags, IPv4 options and fragments on
// captures written here byte by byte, and the real Ouster captures.
#include "range_image_mapping/io/pcap_reader.h"

#include "md5.h"
#include "test_data.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <string>
#include <vector>

namespace range_image_mapping::io {
namespace {

using Bytes = std::vector<uint8_t>;
namespace fs = std::filesystem;

constexpr int kLinkTypeEthernet = 1;
constexpr int kLinkTypeLinuxCooked = 113;
constexpr int kLinkTypeIeee80211 = 105;

// A fresh directory per test, removed afterwards.
class TemporaryDirectory {
 public:
  TemporaryDirectory() {
    const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = fs::temp_directory_path() /
            ("rim_pcap_" + std::to_string(::getpid()) + "_" + test->name());
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TemporaryDirectory() { fs::remove_all(path_); }
  std::string file(const std::string& name) const { return (path_ / name).string(); }

 private:
  fs::path path_;
};

void appendLittle32(Bytes& bytes, uint32_t value) {
  for (int i = 0; i < 4; ++i) bytes.push_back(static_cast<uint8_t>(value >> (8 * i)));
}
void appendBig16(Bytes& bytes, uint16_t value) {
  bytes.push_back(static_cast<uint8_t>(value >> 8));
  bytes.push_back(static_cast<uint8_t>(value));
}
void appendBig32(Bytes& bytes, uint32_t value) {
  appendBig16(bytes, static_cast<uint16_t>(value >> 16));
  appendBig16(bytes, static_cast<uint16_t>(value));
}

// Classic pcap, little-endian, microsecond or nanosecond timestamps.
class PcapFile {
 public:
  PcapFile(std::string path, int link_type, bool nanoseconds = false)
      : path_(std::move(path)), nanoseconds_(nanoseconds) {
    appendLittle32(bytes_, nanoseconds ? 0xA1B23C4Du : 0xA1B2C3D4u);
    bytes_.insert(bytes_.end(), {2, 0, 4, 0});  // version 2.4
    appendLittle32(bytes_, 0);                  // time zone
    appendLittle32(bytes_, 0);                  // accuracy
    appendLittle32(bytes_, 262144);             // snap length
    appendLittle32(bytes_, static_cast<uint32_t>(link_type));
  }
  // captured < frame.size() writes a record cut short, as with a small snap length.
  void add(const Bytes& frame, uint64_t timestamp_ns, std::size_t captured = SIZE_MAX) {
    captured = std::min(captured, frame.size());
    appendLittle32(bytes_, static_cast<uint32_t>(timestamp_ns / 1000000000u));
    const uint64_t fraction = timestamp_ns % 1000000000u;
    appendLittle32(bytes_, static_cast<uint32_t>(nanoseconds_ ? fraction : fraction / 1000u));
    appendLittle32(bytes_, static_cast<uint32_t>(captured));
    appendLittle32(bytes_, static_cast<uint32_t>(frame.size()));
    bytes_.insert(bytes_.end(), frame.begin(), frame.begin() + static_cast<std::ptrdiff_t>(captured));
  }
  void write() const {
    std::ofstream file(path_, std::ios::binary);
    file.write(reinterpret_cast<const char*>(bytes_.data()), static_cast<std::streamsize>(bytes_.size()));
  }

 private:
  std::string path_;
  bool nanoseconds_;
  Bytes bytes_;
};

Bytes udp(uint16_t source_port, uint16_t destination_port, const Bytes& payload) {
  Bytes bytes;
  appendBig16(bytes, source_port);
  appendBig16(bytes, destination_port);
  appendBig16(bytes, static_cast<uint16_t>(payload.size() + 8));
  appendBig16(bytes, 0);  // no checksum
  bytes.insert(bytes.end(), payload.begin(), payload.end());
  return bytes;
}

constexpr uint32_t kSource = 0xC0A80001;       // 192.168.0.1
constexpr uint32_t kDestination = 0xC0A80002;  // 192.168.0.2

struct Ipv4Options {
  uint8_t protocol = 17;
  uint16_t identification = 0;
  bool more_fragments = false;
  std::size_t fragment_offset = 0;  // bytes, a multiple of 8
  int option_words = 0;             // 32-bit words of IP options
};

Bytes ipv4(const Bytes& payload, const Ipv4Options& options = {}) {
  Bytes bytes;
  const std::size_t header_size = 20 + 4 * options.option_words;
  bytes.push_back(static_cast<uint8_t>(0x40 | header_size / 4));
  bytes.push_back(0);
  appendBig16(bytes, static_cast<uint16_t>(header_size + payload.size()));
  appendBig16(bytes, options.identification);
  appendBig16(bytes, static_cast<uint16_t>((options.more_fragments ? 0x2000 : 0) |
                                           options.fragment_offset / 8));
  bytes.push_back(64);  // TTL
  bytes.push_back(options.protocol);
  appendBig16(bytes, 0);  // checksum, not checked
  appendBig32(bytes, kSource);
  appendBig32(bytes, kDestination);
  for (int word = 0; word < options.option_words; ++word) appendBig32(bytes, 0x01010101);  // NOPs
  bytes.insert(bytes.end(), payload.begin(), payload.end());
  return bytes;
}

Bytes ethernet(const Bytes& payload, uint16_t ether_type = 0x0800, std::vector<uint16_t> vlan_tags = {}) {
  Bytes bytes(12, 0xAA);  // addresses
  for (const uint16_t tag_type : vlan_tags) {
    appendBig16(bytes, tag_type);
    appendBig16(bytes, 42);  // VLAN id
  }
  appendBig16(bytes, ether_type);
  bytes.insert(bytes.end(), payload.begin(), payload.end());
  while (bytes.size() < 60) bytes.push_back(0);  // Ethernet minimum frame, padded
  return bytes;
}

Bytes linuxCooked(const Bytes& payload) {
  Bytes bytes(14, 0);
  appendBig16(bytes, 0x0800);
  bytes.insert(bytes.end(), payload.begin(), payload.end());
  return bytes;
}

// IPv4 fragments of a UDP datagram, each carrying at most `fragment_size` bytes.
std::vector<Bytes> fragments(const Bytes& udp_datagram, uint16_t identification, std::size_t fragment_size) {
  std::vector<Bytes> result;
  for (std::size_t offset = 0; offset < udp_datagram.size(); offset += fragment_size) {
    const std::size_t end = std::min(udp_datagram.size(), offset + fragment_size);
    Ipv4Options options;
    options.identification = identification;
    options.fragment_offset = offset;
    options.more_fragments = end < udp_datagram.size();
    result.push_back(ethernet(ipv4(Bytes(udp_datagram.begin() + offset, udp_datagram.begin() + end), options)));
  }
  return result;
}

Bytes pattern(std::size_t size, uint8_t seed) {
  Bytes bytes(size);
  for (std::size_t i = 0; i < size; ++i) bytes[i] = static_cast<uint8_t>(seed + i * 7 + (i >> 8));
  return bytes;
}

struct Received {
  Bytes payload;
  UdpDatagram datagram;
};

std::vector<Received> readAll(const std::string& path, PcapStatistics* statistics = nullptr) {
  PcapReader reader(path);
  std::vector<Received> received;
  UdpDatagram datagram;
  while (reader.next(datagram))
    received.push_back({Bytes(datagram.payload, datagram.payload + datagram.size), datagram});
  EXPECT_FALSE(reader.next(datagram));  // stays at the end
  if (statistics != nullptr) *statistics = reader.statistics();
  return received;
}

template <typename Call>
std::string errorOf(Call call) {
  try {
    call();
  } catch (const PcapError& error) {
    return error.what();
  }
  return "";
}

// ------------------------------------------------------------ errors

TEST(PcapReader, MissingFileNamesPathAndReason) {
  const std::string path = "/nonexistent/capture.pcap";
  const std::string message = errorOf([&] { PcapReader reader(path); });
  EXPECT_NE(message.find(path), std::string::npos) << message;
  EXPECT_NE(message.find("No such file"), std::string::npos) << message;
}

TEST(PcapReader, NonPcapFileNamesPathAndReason) {
  const TemporaryDirectory directory;
  const std::string text = directory.file("notes.pcap");
  std::ofstream(text) << "this is not a capture, just some text long enough to be read\n";
  const std::string message = errorOf([&] { PcapReader reader(text); });
  EXPECT_NE(message.find(text), std::string::npos) << message;
  EXPECT_NE(message.find("unknown file format"), std::string::npos) << message;

  const std::string empty = directory.file("empty.pcap");
  std::ofstream{empty};
  const std::string empty_message = errorOf([&] { PcapReader reader(empty); });
  EXPECT_NE(empty_message.find(empty), std::string::npos) << empty_message;

  OusterMetadata metadata;
  metadata.pixels_per_column = 16;
  metadata.columns_per_frame = 512;
  EXPECT_THROW(readOusterScans(text, metadata, {}), PcapError);
}

TEST(PcapReader, UnsupportedLinkTypeIsNamed) {
  const TemporaryDirectory directory;
  PcapFile file(directory.file("wifi.pcap"), kLinkTypeIeee80211);
  file.add(Bytes(64, 0), 1);
  file.write();
  const std::string message = errorOf([&] { PcapReader reader(directory.file("wifi.pcap")); });
  EXPECT_NE(message.find("link type 105"), std::string::npos) << message;
}

// ------------------------------------------------------------ link and network layers

TEST(PcapReader, EthernetVlanOptionsPaddingAndSkippedFrames) {
  const TemporaryDirectory directory;
  const std::string path = directory.file("frames.pcap");
  PcapFile file(path, kLinkTypeEthernet);
  const Bytes small = pattern(5, 1);  // padded to the Ethernet minimum on the wire
  const Bytes large = pattern(1400, 2);
  Ipv4Options with_options;
  with_options.option_words = 3;
  file.add(ethernet(ipv4(udp(1000, 7502, small))), 1000000001000);
  file.add(ethernet(ipv4(udp(1000, 7503, large)), 0x0800, {0x8100}), 1000000002000);  // 802.1Q
  file.add(ethernet(ipv4(udp(1001, 7504, large)), 0x0800, {0x88A8, 0x8100}), 1000000003000);  // QinQ
  file.add(ethernet(ipv4(udp(1002, 7505, small), with_options)), 1000000004000);  // IHL 8
  // Skipped: ARP, TCP, IPv6, a record cut short, a UDP length past the datagram,
  // an IP header length past the total length.
  file.add(ethernet(Bytes(28, 0), 0x0806), 1000000005000);
  Ipv4Options tcp;
  tcp.protocol = 6;
  file.add(ethernet(ipv4(Bytes(40, 0), tcp)), 1000000006000);
  file.add(ethernet(Bytes(60, 0x60), 0x86DD), 1000000007000);
  file.add(ethernet(ipv4(udp(1003, 7502, large))), 1000000008000, 200);
  Bytes lying_udp = udp(1004, 7502, small);
  lying_udp[5] = 200;  // UDP length 200 > 13 bytes
  file.add(ethernet(ipv4(lying_udp)), 1000000009000);
  Bytes lying_ip = ipv4(udp(1005, 7502, small));
  lying_ip[3] = 10;  // total length 10 < 20
  file.add(ethernet(lying_ip), 1000000010000);
  file.write();

  PcapStatistics statistics;
  const std::vector<Received> received = readAll(path, &statistics);
  ASSERT_EQ(received.size(), 4u);
  EXPECT_EQ(received[0].payload, small);  // the padding is not payload
  EXPECT_EQ(received[1].payload, large);
  EXPECT_EQ(received[2].payload, large);
  EXPECT_EQ(received[3].payload, small);
  const uint16_t ports[] = {7502, 7503, 7504, 7505};
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(received[i].datagram.destination_port, ports[i]);
    EXPECT_EQ(received[i].datagram.source_port, 1000 + std::max(0, i - 1));
    EXPECT_EQ(received[i].datagram.source_address, kSource);
    EXPECT_EQ(received[i].datagram.destination_address, kDestination);
    EXPECT_EQ(received[i].datagram.timestamp_ns, 1000000001000u + 1000u * i);
  }
  EXPECT_EQ(statistics.records, 10u);
  EXPECT_EQ(statistics.udp_datagrams, 4u);
  EXPECT_EQ(statistics.skipped_not_udp, 3u);
  EXPECT_EQ(statistics.skipped_truncated, 1u);
  EXPECT_EQ(statistics.skipped_malformed, 2u);
  EXPECT_TRUE(statistics.stopped_early.empty());
}

TEST(PcapReader, LinuxCookedWithNanosecondTimestamps) {
  const TemporaryDirectory directory;
  const std::string path = directory.file("cooked.pcap");
  PcapFile file(path, kLinkTypeLinuxCooked, /*nanoseconds=*/true);
  const Bytes payload = pattern(300, 3);
  file.add(linuxCooked(ipv4(udp(7502, 7502, payload))), 1234567890123456789u);
  file.write();
  const std::vector<Received> received = readAll(path);
  ASSERT_EQ(received.size(), 1u);
  EXPECT_EQ(received[0].payload, payload);
  EXPECT_EQ(received[0].datagram.timestamp_ns, 1234567890123456789u);
}

TEST(PcapReader, Ipv4FragmentsAreReassembled) {
  const TemporaryDirectory directory;
  const std::string path = directory.file("fragments.pcap");
  PcapFile file(path, kLinkTypeEthernet);
  const Bytes big = pattern(4000, 4);
  const Bytes other = pattern(2000, 5);
  const std::vector<Bytes> big_parts = fragments(udp(50000, 7502, big), 7, 1480);  // 3 fragments
  const std::vector<Bytes> other_parts = fragments(udp(50000, 7502, other), 8, 1480);  // 2 fragments
  const std::vector<Bytes> lost_parts = fragments(udp(50000, 7502, big), 9, 1480);
  ASSERT_EQ(big_parts.size(), 3u);
  ASSERT_EQ(other_parts.size(), 2u);
  // Out of order, interleaved, with a duplicate and an unfragmented datagram in between.
  file.add(big_parts[2], 1000);
  file.add(other_parts[0], 2000);
  file.add(big_parts[0], 3000);
  file.add(ethernet(ipv4(udp(1, 7503, pattern(48, 6)))), 4000);
  file.add(big_parts[0], 5000);
  file.add(big_parts[1], 6000);  // completes `big`
  file.add(other_parts[1], 7000);  // completes `other`
  file.add(lost_parts[0], 8000);   // its other fragments never come
  file.add(lost_parts[2], 9000);
  file.write();

  PcapStatistics statistics;
  const std::vector<Received> received = readAll(path, &statistics);
  ASSERT_EQ(received.size(), 3u);
  EXPECT_EQ(received[0].payload.size(), 48u);
  EXPECT_EQ(received[1].payload, big);
  EXPECT_EQ(received[1].datagram.timestamp_ns, 6000u);  // when the last piece arrived
  EXPECT_EQ(received[1].datagram.destination_port, 7502);
  EXPECT_EQ(received[2].payload, other);
  EXPECT_EQ(statistics.fragments, 8u);
  EXPECT_EQ(statistics.reassembled, 2u);
  EXPECT_EQ(statistics.fragments_dropped, 2u);  // the two of datagram 9
  EXPECT_EQ(statistics.udp_datagrams, 3u);
}

TEST(PcapReader, InconsistentFragmentsAreDropped) {
  const TemporaryDirectory directory;
  const std::string path = directory.file("bad_fragments.pcap");
  PcapFile file(path, kLinkTypeEthernet);
  Ipv4Options odd;  // a middle fragment whose size is not a multiple of 8
  odd.identification = 1;
  odd.more_fragments = true;
  file.add(ethernet(ipv4(pattern(100, 1), odd)), 1);
  Ipv4Options past_end;  // 65528 + 100 bytes is beyond any IPv4 datagram
  past_end.identification = 2;
  past_end.fragment_offset = 65528;
  file.add(ethernet(ipv4(pattern(100, 1), past_end)), 2);
  // Two different "last" fragments of one datagram.
  Ipv4Options last_a, last_b;
  last_a.identification = last_b.identification = 3;
  last_a.fragment_offset = 800;
  last_b.fragment_offset = 1600;
  file.add(ethernet(ipv4(pattern(100, 1), last_a)), 3);
  file.add(ethernet(ipv4(pattern(100, 1), last_b)), 4);
  file.write();
  PcapStatistics statistics;
  EXPECT_TRUE(readAll(path, &statistics).empty());
  EXPECT_EQ(statistics.fragments, 4u);
  EXPECT_EQ(statistics.fragments_dropped, 4u);
  EXPECT_EQ(statistics.reassembled, 0u);
}

// ------------------------------------------------------------ real captures

TEST(PcapReader, RealCaptureDatagrams) {
  RIM_REQUIRE_DATA(path, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  PcapStatistics statistics;
  const std::vector<Received> received = readAll(path, &statistics);
  // SOURCE.md: 192 lidar packets of 8448 bytes to 7502, 30 IMU packets of 48 to 7503.
  ASSERT_EQ(received.size(), 222u);
  std::size_t lidar = 0, imu = 0;
  uint64_t previous = 0;
  for (const Received& datagram : received) {
    lidar += datagram.datagram.destination_port == 7502 && datagram.payload.size() == 8448;
    imu += datagram.datagram.destination_port == 7503 && datagram.payload.size() == 48;
    EXPECT_EQ(datagram.datagram.source_address, 0x7F000001u);  // written from 127.0.0.1
    EXPECT_GE(datagram.datagram.timestamp_ns, previous);
    previous = datagram.datagram.timestamp_ns;
  }
  EXPECT_EQ(lidar, 192u);
  EXPECT_EQ(imu, 30u);
  EXPECT_EQ(statistics.records, 222u);
  EXPECT_EQ(statistics.skipped_not_udp + statistics.skipped_truncated + statistics.skipped_malformed, 0u);
}

TEST(PcapReader, OusterScansOverFragmentedIpv4) {
  RIM_REQUIRE_DATA(path, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(metadata_path, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  // The same datagrams as a 1500-byte MTU network would carry them.
  const TemporaryDirectory directory;
  const std::string fragmented = directory.file("fragmented.pcap");
  PcapFile file(fragmented, kLinkTypeEthernet);
  uint16_t identification = 0;
  for (const Received& datagram : readAll(path))
    for (const Bytes& fragment : fragments(udp(7502, datagram.datagram.destination_port, datagram.payload),
                                           ++identification, 1480))
      file.add(fragment, datagram.datagram.timestamp_ns);
  file.write();

  std::vector<std::string> range_digests;
  const OusterPcapStatistics statistics =
      readOusterScans(fragmented, loadOusterMetadata(metadata_path),
                      [&](const LidarScan& scan) { range_digests.push_back(test::md5Hex(scan.range)); });
  EXPECT_EQ(statistics.pcap.reassembled, 192u);
  EXPECT_EQ(statistics.lidar_datagrams, 192u);
  EXPECT_EQ(statistics.other_datagrams, 30u);
  // SOURCE.md digests of frames 1795..1797.
  EXPECT_EQ(range_digests, (std::vector<std::string>{"17b04f169a54850cff3c97fce782d360",
                                                     "97af312c2c7f77cb219cbf399bde3455",
                                                     "058bdcf1ac1094866d13bee966f09a66"}));
}

TEST(PcapReader, OusterScansFallBackToPacketSize) {
  RIM_REQUIRE_DATA(path, "ouster-pcaps/windowed_frame2.pcap");
  RIM_REQUIRE_DATA(metadata_path, "ouster-pcaps/windowed_frame2_0.json");
  OusterMetadata metadata = loadOusterMetadata(metadata_path);
  std::size_t columns = 0;
  const auto count = [&](const LidarScan& scan) { columns += scan.receivedColumns(); };
  const OusterPcapStatistics by_port = readOusterScans(path, metadata, count);
  EXPECT_FALSE(by_port.classified_by_size);
  EXPECT_EQ(by_port.lidar_datagrams, 15u);
  EXPECT_EQ(by_port.batcher.scans, 1u);
  EXPECT_EQ(columns, 228u);

  metadata.udp_port_lidar = 1234;  // as if the capture had been re-routed
  columns = 0;
  const OusterPcapStatistics by_size = readOusterScans(path, metadata, count);
  EXPECT_TRUE(by_size.classified_by_size);
  EXPECT_EQ(by_size.lidar_datagrams, 15u);
  EXPECT_EQ(by_size.other_datagrams, 10u);
  EXPECT_EQ(by_size.batcher.scans, 1u);
  EXPECT_EQ(columns, 228u);
}

TEST(PcapReader, CaptureCutMidRecordKeepsWhatCameBefore) {
  RIM_REQUIRE_DATA(path, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(metadata_path, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  const TemporaryDirectory directory;
  const std::string cut = directory.file("cut.pcap");
  {
    std::ifstream source(path, std::ios::binary);
    std::vector<char> head(900000);  // into the second frame, mid-record
    source.read(head.data(), static_cast<std::streamsize>(head.size()));
    std::ofstream(cut, std::ios::binary).write(head.data(), static_cast<std::streamsize>(head.size()));
  }
  std::vector<LidarScan> scans;
  const OusterPcapStatistics statistics = readOusterScans(
      cut, loadOusterMetadata(metadata_path), [&](const LidarScan& scan) { scans.push_back(scan); });
  EXPECT_FALSE(statistics.pcap.stopped_early.empty());
  ASSERT_EQ(scans.size(), 2u);
  EXPECT_EQ(test::md5Hex(scans[0].range), "17b04f169a54850cff3c97fce782d360");
  EXPECT_EQ(scans[1].frame_id, 1796u);
  EXPECT_LT(scans[1].receivedColumns(), 1024u);
  EXPECT_EQ(statistics.batcher.incomplete_scans, 1u);
}

}  // namespace
}  // namespace range_image_mapping::io
