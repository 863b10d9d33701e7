// Ouster packets into scans: decoded fields against the golden digests of the
// real captures, column windows, lost and bad packets, and the conversion into
// a range image.
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/ouster_packet.h"
#include "range_image_mapping/scan_batcher.h"

#include "md5.h"
#include "capture_packets.h"
#include "test_data.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iostream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

using test::md5Hex;
using test::Packet;

std::string readText(const std::string& path) {
  std::ifstream file(path);
  std::ostringstream text;
  text << file.rdbuf();
  return text.str();
}

// The value of `"key": "value"` in the first scan of a *_digest.json ("" if absent).
std::string scanDigest(const std::string& digest_json, const std::string& key) {
  const std::size_t scans = digest_json.find("\"scans\"");
  if (scans == std::string::npos) return "";
  const std::size_t at = digest_json.find("\"" + key + "\"", scans);
  if (at == std::string::npos) return "";
  const std::size_t open = digest_json.find('"', digest_json.find(':', at));
  const std::size_t close = digest_json.find('"', open + 1);
  return digest_json.substr(open + 1, close - open - 1);
}


using test::decodeCapture;
using test::lidarPackets;

std::size_t nonZero(const std::vector<uint32_t>& values) {
  return static_cast<std::size_t>(std::count_if(values.begin(), values.end(), [](uint32_t v) { return v; }));
}

// Columns never received must hold nothing at all.
void expectColumnEmpty(const LidarScan& scan, int column) {
  EXPECT_EQ(scan.status[column], 0u) << column;
  EXPECT_EQ(scan.timestamp_ns[column], 0u) << column;
  EXPECT_EQ(scan.measurement_id[column], 0u) << column;
  for (int row = 0; row < scan.rows; ++row) {
    const std::size_t i = static_cast<std::size_t>(row) * scan.columns + column;
    ASSERT_EQ(scan.range[i], 0u) << row << "," << column;
    ASSERT_EQ(scan.reflectivity[i], 0u) << row << "," << column;
    ASSERT_EQ(scan.near_ir[i], 0u) << row << "," << column;
  }
}

// ------------------------------------------------------------ golden digests

struct Capture {
  const char* pcap;
  const char* metadata;
  const char* digest;
};

class GoldenDigestTest : public ::testing::TestWithParam<Capture> {};

TEST_P(GoldenDigestTest, DecodedFieldsMatchTheSdk) {
  const Capture& capture = GetParam();
  RIM_REQUIRE_DATA(pcap_path, std::string("ouster-pcaps/") + capture.pcap);
  RIM_REQUIRE_DATA(metadata_path, std::string("ouster-pcaps/") + capture.metadata);
  RIM_REQUIRE_DATA(digest_path, std::string("ouster-pcaps/") + capture.digest);
  const std::string digest = readText(digest_path);
  const OusterMetadata metadata = loadOusterMetadata(metadata_path);
  io::OusterPcapStatistics statistics;
  const std::vector<LidarScan> scans = decodeCapture(pcap_path, metadata, &statistics);
  ASSERT_EQ(scans.size(), 1u);
  EXPECT_EQ(statistics.batcher.incomplete_scans, 0u);
  EXPECT_EQ(statistics.batcher.packets, 64u);
  EXPECT_FALSE(statistics.classified_by_size);
  const LidarScan& scan = scans.front();
  EXPECT_EQ(std::to_string(scan.frame_id), scanDigest(digest, "FRAME_ID"));
  EXPECT_EQ(scan.receivedColumns(), 1024u);

  // Every field the digest holds and this profile carries, as the SDK stores it.
  const std::vector<std::pair<std::string, std::string>> fields = {
      {"RANGE", md5Hex(scan.range)},
      {"REFLECTIVITY", md5Hex(scan.reflectivity)},
      {"TIMESTAMP", md5Hex(scan.timestamp_ns)},
      {"MEASUREMENT_ID", md5Hex(scan.measurement_id)},
      {"NEAR_IR", md5Hex(scan.near_ir)},
      {"SIGNAL", md5Hex(scan.signal)},
      {"RANGE2", md5Hex(scan.range2)},
      {"REFLECTIVITY2", md5Hex(scan.reflectivity2)},
      {"SIGNAL2", md5Hex(scan.signal2)}};
  int compared = 0;
  for (const auto& [key, decoded] : fields) {
    const std::string golden = scanDigest(digest, key);
    const bool required = key == "RANGE" || key == "REFLECTIVITY" || key == "TIMESTAMP" ||
                          key == "MEASUREMENT_ID" || key == "NEAR_IR";
    if (golden.empty()) {
      EXPECT_FALSE(required) << key << " missing from " << digest_path;
      continue;
    }
    EXPECT_EQ(decoded, golden) << key;
    ++compared;
  }
  EXPECT_GE(compared, 5);
}

INSTANTIATE_TEST_SUITE_P(
    Captures, GoldenDigestTest,
    ::testing::Values(
        Capture{"OS-0-128-U1_v2.3.0_1024x10.pcap", "OS-0-128-U1_v2.3.0_1024x10.json",
                "OS-0-128-U1_v2.3.0_1024x10_digest.json"},
        Capture{"OS-2-128-U1_v2.3.0_1024x10.pcap", "OS-2-128-U1_v2.3.0_1024x10.json",
                "OS-2-128-U1_v2.3.0_1024x10_digest.json"},
        Capture{"OS-0-32-U1_v2.2.0_1024x10.pcap", "OS-0-32-U1_v2.2.0_1024x10.json",
                "OS-0-32-U1_v2.2.0_1024x10_digest.json"},
        Capture{"OS-1-32-G_v2.1.1_1024x10.pcap", "OS-1-32-G_v2.1.1_1024x10.json",
                "OS-1-32-G_v2.1.1_1024x10_digest.json"},
        Capture{"OS-2-32-U0_v2.0.0_1024x10.pcap", "OS-2-32-U0_v2.0.0_1024x10.json",
                "OS-2-32-U0_v2.0.0_1024x10_digest.json"}),
    [](const ::testing::TestParamInfo<Capture>& info) {
      std::string name = std::string(info.param.pcap).substr(0, 10);
      std::replace(name.begin(), name.end(), '-', '_');
      return name;
    });

// Digests computed by the data's curator (SOURCE.md), no official ones exist.
TEST(OusterPacket, LowBandwidthThreeFrames) {
  RIM_REQUIRE_DATA(pcap_path, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(metadata_path, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  const std::vector<LidarScan> scans = decodeCapture(pcap_path, loadOusterMetadata(metadata_path));
  ASSERT_EQ(scans.size(), 3u);
  const struct {
    uint32_t frame_id;
    const char* range;
    const char* reflectivity;
    std::size_t returns;
  } kExpected[] = {
      {1795, "17b04f169a54850cff3c97fce782d360", "3e1f0d8cf87a42013864a854492d9412", 107647},
      {1796, "97af312c2c7f77cb219cbf399bde3455", "6bdd4629244960e211ad0638c293017f", 107357},
      {1797, "058bdcf1ac1094866d13bee966f09a66", "4e5cfcd416dcb88c5a5b6b53c30e0e87", 107532}};
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(scans[i].frame_id, kExpected[i].frame_id);
    EXPECT_EQ(md5Hex(scans[i].range), kExpected[i].range) << i;
    EXPECT_EQ(md5Hex(scans[i].reflectivity), kExpected[i].reflectivity) << i;
    EXPECT_EQ(nonZero(scans[i].range), kExpected[i].returns) << i;
    EXPECT_TRUE(scans[i].signal.empty());  // RNG15_RFL8_NIR8 has no signal field
    // The low-bandwidth profile has 8 mm steps.
    for (const uint32_t millimetres : scans[i].range) ASSERT_EQ(millimetres % 8, 0u);
  }
  // SOURCE.md: frame 1795 spans 991587364520 .. 991687215910 ns.
  EXPECT_EQ(scans[0].timestamp_ns.front(), 991587364520u);
  EXPECT_EQ(scans[0].timestamp_ns.back(), 991687215910u);
}

TEST(OusterPacket, LegacyWithReducedMetadata) {
  RIM_REQUIRE_DATA(pcap_path, "ouster-pcaps/OS-1-64_1024x10_fw20.pcap");
  RIM_REQUIRE_DATA(metadata_path, "ouster-pcaps/OS-1-64_sensor_config_reduced.json");
  const std::vector<LidarScan> scans = decodeCapture(pcap_path, loadOusterMetadata(metadata_path));
  ASSERT_EQ(scans.size(), 1u);
  EXPECT_EQ(scans[0].frame_id, 189u);
  EXPECT_EQ(md5Hex(scans[0].range), "db8638834f08216c2de5f19b1a0f352b");
  EXPECT_EQ(nonZero(scans[0].range), 16749u);
  // LEGACY columns carry encoder counts; they grow with the measurement id.
  EXPECT_LT(scans[0].encoder_count[0], scans[0].encoder_count[1023]);
}

TEST(OusterPacket, NestedMetadataCompleteAndPartialFrame) {
  RIM_REQUIRE_DATA(pcap_path, "ouster-pcaps/crc_test.pcap");
  RIM_REQUIRE_DATA(metadata_path, "ouster-pcaps/crc_test.json");
  io::OusterPcapStatistics statistics;
  const std::vector<LidarScan> scans =
      decodeCapture(pcap_path, loadOusterMetadata(metadata_path), &statistics);
  ASSERT_EQ(scans.size(), 2u);
  EXPECT_EQ(scans[0].frame_id, 254u);
  EXPECT_EQ(scans[0].columns, 512);
  EXPECT_EQ(md5Hex(scans[0].range), "a0119763b309d842c3d164d3a5e218d4");
  // Frame 255 has 32 of 512 columns; flush() emits it, incomplete.
  EXPECT_EQ(scans[1].frame_id, 255u);
  EXPECT_EQ(scans[1].receivedColumns(), 32u);
  EXPECT_EQ(statistics.batcher.scans, 2u);
  EXPECT_EQ(statistics.batcher.incomplete_scans, 1u);
  EXPECT_EQ(statistics.batcher.missing_columns, 480u);
}

// Firmware 3.x packets end in a CRC64 of the packet (crc_test.pcap); 2.x
// packets of the same profile do not (lb_n3), LEGACY ones have no footer.
TEST(OusterPacket, ChecksumsMatchOnFirmware3PacketsOnly) {
  RIM_REQUIRE_DATA(crc_pcap, "ouster-pcaps/crc_test.pcap");
  RIM_REQUIRE_DATA(crc_metadata_path, "ouster-pcaps/crc_test.json");
  RIM_REQUIRE_DATA(v2_pcap, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(v2_metadata_path, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  RIM_REQUIRE_DATA(legacy_pcap, "ouster-pcaps/OS-1-32-G_v2.1.1_1024x10.pcap");
  RIM_REQUIRE_DATA(legacy_metadata_path, "ouster-pcaps/OS-1-32-G_v2.1.1_1024x10.json");
  const OusterMetadata crc_metadata = loadOusterMetadata(crc_metadata_path);
  const PacketFormat crc_format(crc_metadata);
  const std::vector<Packet> packets = lidarPackets(crc_pcap, crc_metadata);
  ASSERT_EQ(packets.size(), 34u);
  for (std::size_t i = 0; i < packets.size(); ++i) EXPECT_TRUE(crc_format.checksumMatches(packets[i].data())) << i;
  // Any one bit changed anywhere (header, pixels, footer, the checksum itself) is caught.
  for (const std::size_t byte : {std::size_t(2), std::size_t(1000), packets[0].size() - 9, packets[0].size() - 1}) {
    Packet damaged = packets[5];
    damaged[byte] ^= 0x10;
    EXPECT_FALSE(crc_format.checksumMatches(damaged.data())) << "byte " << byte;
  }
  const OusterMetadata v2_metadata = loadOusterMetadata(v2_metadata_path);
  for (const Packet& packet : lidarPackets(v2_pcap, v2_metadata))
    EXPECT_FALSE(PacketFormat(v2_metadata).checksumMatches(packet.data()));
  const OusterMetadata legacy_metadata = loadOusterMetadata(legacy_metadata_path);
  for (const Packet& packet : lidarPackets(legacy_pcap, legacy_metadata))
    EXPECT_FALSE(PacketFormat(legacy_metadata).checksumMatches(packet.data()));
}

// In a stream that carries checksums a damaged packet is dropped and counted
// (its columns stay invalid, the rest of the frame is exact); in one that
// does not (firmware 2.x), nothing is dropped for its checksum.
TEST(OusterPacket, DamagedPacketOfAChecksummedStreamIsDropped) {
  RIM_REQUIRE_DATA(crc_pcap, "ouster-pcaps/crc_test.pcap");
  RIM_REQUIRE_DATA(crc_metadata_path, "ouster-pcaps/crc_test.json");
  RIM_REQUIRE_DATA(v2_pcap, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(v2_metadata_path, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  const auto batch = [](const OusterMetadata& metadata, const std::vector<Packet>& packets,
                        BatcherStatistics& statistics) {
    std::vector<LidarScan> scans;
    ScanBatcher batcher(metadata, [&](const LidarScan& scan) { scans.push_back(scan); });
    for (const Packet& packet : packets) batcher.addPacket(packet.data(), packet.size());
    batcher.flush();
    statistics = batcher.statistics();
    return scans;
  };
  const OusterMetadata crc_metadata = loadOusterMetadata(crc_metadata_path);
  std::vector<Packet> packets = lidarPackets(crc_pcap, crc_metadata);
  BatcherStatistics intact_statistics, damaged_statistics;
  const std::vector<LidarScan> intact = batch(crc_metadata, packets, intact_statistics);
  EXPECT_EQ(intact_statistics.bad_checksum, 0u);
  ASSERT_EQ(intact.size(), 2u);
  EXPECT_EQ(md5Hex(intact[0].range), "a0119763b309d842c3d164d3a5e218d4");
  // A range bit flipped in packet 7 (columns 112-127 of frame 254): without
  // the checksum it would decode as a plausible wrong range.
  const std::size_t first_pixel = 32 + 12;
  packets[7][first_pixel] ^= 0x01;
  const std::vector<LidarScan> damaged = batch(crc_metadata, packets, damaged_statistics);
  EXPECT_EQ(damaged_statistics.bad_checksum, 1u);
  ASSERT_EQ(damaged.size(), 2u);
  EXPECT_EQ(damaged[0].receivedColumns(), 512u - 16u);
  EXPECT_EQ(damaged_statistics.missing_columns, intact_statistics.missing_columns + 16);
  const int columns = damaged[0].columns;
  for (int row = 0; row < damaged[0].rows; ++row)
    for (int column = 0; column < columns; ++column) {
      const std::size_t i = std::size_t(row) * columns + column;
      const bool dropped = damaged[0].status[column] == 0;
      ASSERT_EQ(damaged[0].range[i], dropped ? 0u : intact[0].range[i]) << row << ", " << column;
    }
  const OusterMetadata v2_metadata = loadOusterMetadata(v2_metadata_path);
  BatcherStatistics v2_statistics;
  const std::vector<LidarScan> v2_scans = batch(v2_metadata, lidarPackets(v2_pcap, v2_metadata), v2_statistics);
  EXPECT_EQ(v2_statistics.bad_checksum, 0u);
  EXPECT_EQ(v2_scans.size(), 3u);
  EXPECT_EQ(v2_statistics.incomplete_scans, 0u);
}

TEST(OusterPacket, DualReturnSecondRangeIsPlausible) {
  RIM_REQUIRE_DATA(pcap_path, "ouster-pcaps/OS-0-32-U1_v2.2.0_1024x10.pcap");
  RIM_REQUIRE_DATA(metadata_path, "ouster-pcaps/OS-0-32-U1_v2.2.0_1024x10.json");
  const std::vector<LidarScan> scans = decodeCapture(pcap_path, loadOusterMetadata(metadata_path));
  ASSERT_EQ(scans.size(), 1u);
  const LidarScan& scan = scans[0];
  ASSERT_EQ(scan.range2.size(), scan.range.size());
  const std::size_t first_returns = nonZero(scan.range);
  const std::size_t second_returns = nonZero(scan.range2);
  EXPECT_GT(second_returns, 0u);
  EXPECT_LE(second_returns, first_returns);
  // Returns come strongest first: the second never has more signal than the
  // first, and it is another surface, not a copy of the first.
  std::size_t both = 0;
  for (std::size_t i = 0; i < scan.range.size(); ++i) {
    if (scan.range2[i] == 0) continue;
    ASSERT_LE(scan.signal2[i], scan.signal[i]) << i;
    if (scan.range[i] == 0) continue;
    ++both;
    ASSERT_NE(scan.range2[i], scan.range[i]) << i;
  }
  EXPECT_GT(both, 0u);
}

// ------------------------------------------------------------ column windows

struct WindowCase {
  const char* pcap;
  const char* metadata;
  int first, last;
};

TEST(OusterPacket, ColumnWindowsHoldExactlyTheirColumns) {
  for (const WindowCase& window : {WindowCase{"windowed_frame1.pcap", "windowed_frame1_0.json", 1, 256},
                                   WindowCase{"windowed_frame2.pcap", "windowed_frame2_0.json", 370, 85}}) {
    SCOPED_TRACE(window.pcap);
    RIM_REQUIRE_DATA(pcap_path, std::string("ouster-pcaps/") + window.pcap);
    RIM_REQUIRE_DATA(metadata_path, std::string("ouster-pcaps/") + window.metadata);
    const OusterMetadata metadata = loadOusterMetadata(metadata_path);
    ASSERT_EQ(metadata.intrinsics.column_window, (std::array<int, 2>{window.first, window.last}));
    io::OusterPcapStatistics statistics;
    const std::vector<LidarScan> scans = decodeCapture(pcap_path, metadata, &statistics);
    ASSERT_EQ(scans.size(), 1u);
    EXPECT_EQ(statistics.batcher.scans, 1u);
    EXPECT_EQ(statistics.batcher.incomplete_scans, 0u);
    const LidarScan& scan = scans[0];
    const bool wraps = window.first > window.last;
    std::size_t inside = 0;
    for (int column = 0; column < scan.columns; ++column) {
      const bool in_window = wraps ? (column >= window.first || column <= window.last)
                                   : (column >= window.first && column <= window.last);
      inside += in_window;
      if (in_window) {
        EXPECT_NE(scan.status[column], 0u) << column;
        EXPECT_EQ(scan.measurement_id[column], column);
      } else {
        expectColumnEmpty(scan, column);
      }
    }
    EXPECT_EQ(scan.receivedColumns(), inside);
  }
}

TEST(OusterPacket, CompleteWindowIsEmittedAtOnceAndLaterPacketsAreStale) {
  RIM_REQUIRE_DATA(pcap_path, "ouster-pcaps/windowed_frame1.pcap");
  RIM_REQUIRE_DATA(metadata_path, "ouster-pcaps/windowed_frame1_0.json");
  const OusterMetadata metadata = loadOusterMetadata(metadata_path);
  const std::vector<Packet> packets = lidarPackets(pcap_path, metadata);
  ASSERT_EQ(packets.size(), 17u);
  int emitted = 0;
  ScanBatcher batcher(metadata, [&](const LidarScan&) { ++emitted; });
  for (const Packet& packet : packets) batcher.addPacket(packet.data(), packet.size());
  EXPECT_EQ(emitted, 1);  // before any flush: the window [1, 256] was complete
  batcher.addPacket(packets[3].data(), packets[3].size());  // a late duplicate
  batcher.flush();
  EXPECT_EQ(emitted, 1);
  EXPECT_EQ(batcher.statistics().stale, 1u);
  EXPECT_EQ(batcher.statistics().scans, 1u);
}

// ------------------------------------------------------------ lost and bad packets

class LowBandwidthPackets : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string pcap_path = test::dataFile("ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
    const std::string metadata_path = test::dataFile("ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
    if (pcap_path.empty() || metadata_path.empty())
      GTEST_SKIP() << "sensor data not found: ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap (looked in "
                   << test::dataDirectory() << "; set RIM_DATA_DIR to the shared/data folder)";
    metadata_ = loadOusterMetadata(metadata_path);
    packets_ = lidarPackets(pcap_path, metadata_);
    ASSERT_EQ(packets_.size(), 192u);
  }

  // Feeds the packets whose index `keep` accepts, then flushes.
  template <typename Keep>
  std::vector<LidarScan> batch(Keep keep, BatcherStatistics* statistics = nullptr) {
    std::vector<LidarScan> scans;
    ScanBatcher batcher(metadata_, [&](const LidarScan& scan) { scans.push_back(scan); });
    for (std::size_t i = 0; i < packets_.size(); ++i)
      if (keep(i)) batcher.addPacket(packets_[i].data(), packets_[i].size());
    batcher.flush();
    if (statistics != nullptr) *statistics = batcher.statistics();
    return scans;
  }

  OusterMetadata metadata_;
  std::vector<Packet> packets_;
};

TEST_F(LowBandwidthPackets, DroppedPacketLeavesExactlyItsColumnsInvalid) {
  BatcherStatistics statistics;
  const std::vector<LidarScan> scans = batch([](std::size_t i) { return i != 5; }, &statistics);
  ASSERT_EQ(scans.size(), 3u);
  EXPECT_EQ(statistics.incomplete_scans, 1u);
  EXPECT_EQ(statistics.missing_columns, 16u);
  EXPECT_EQ(scans[0].receivedColumns(), 1008u);
  for (int column = 0; column < 1024; ++column) {
    if (column >= 80 && column < 96) expectColumnEmpty(scans[0], column);
    else EXPECT_NE(scans[0].status[column], 0u) << column;
  }
  EXPECT_EQ(scans[1].receivedColumns(), 1024u);
}

TEST_F(LowBandwidthPackets, NextScanNeverHoldsThePreviousScansData) {
  const std::vector<LidarScan> complete = batch([](std::size_t) { return true; });
  // Drop packets 3 and 4 of the second frame (columns 48..79).
  const std::vector<LidarScan> scans = batch([](std::size_t i) { return i != 64 + 3 && i != 64 + 4; });
  ASSERT_EQ(scans.size(), 3u);
  EXPECT_EQ(scans[1].frame_id, 1796u);
  for (int column = 48; column < 80; ++column) {
    // The first frame had returns there, so a leak would show.
    ASSERT_NE(complete[0].status[column], 0u);
    expectColumnEmpty(scans[1], column);
  }
  std::size_t first_frame_returns_there = 0;
  for (int row = 0; row < 128; ++row)
    for (int column = 48; column < 80; ++column)
      first_frame_returns_there += complete[0].range[row * 1024 + column] != 0;
  EXPECT_GT(first_frame_returns_there, 1000u);
  EXPECT_EQ(md5Hex(scans[0].range), md5Hex(complete[0].range));
  EXPECT_EQ(md5Hex(scans[2].range), md5Hex(complete[2].range));
}

TEST_F(LowBandwidthPackets, BadPacketsAreCountedNeverDecoded) {
  std::vector<LidarScan> scans;
  ScanBatcher batcher(metadata_, [&](const LidarScan& scan) { scans.push_back(scan); });
  const std::size_t size = packets_[0].size();
  std::size_t offered = 0;
  const auto offer = [&](const uint8_t* data, std::size_t bytes) {
    batcher.addPacket(data, bytes);
    ++offered;
  };
  // Wrong sizes: truncated, one byte long, empty, null.
  offer(packets_[0].data(), size - 1);
  offer(packets_[0].data(), 100);
  Packet longer = packets_[0];
  longer.push_back(0);
  offer(longer.data(), longer.size());
  offer(packets_[0].data(), 0);
  offer(nullptr, 0);
  EXPECT_EQ(batcher.statistics().wrong_size, 5u);
  // Right size, but not a lidar packet (packet type 2), or a measurement id past W.
  Packet not_lidar = packets_[0];
  not_lidar[0] = 2;
  offer(not_lidar.data(), size);
  Packet bad_column = packets_[1];
  bad_column[32 + 8] = 0xFF;  // first column's measurement id := 0x..FF >= 1024
  bad_column[32 + 9] = 0xFF;
  offer(bad_column.data(), size);
  EXPECT_EQ(batcher.statistics().malformed, 2u);
  // Random bytes of random and of the right size.
  std::mt19937 random(12345);
  Packet noise(size * 2);
  for (int trial = 0; trial < 200; ++trial) {
    for (uint8_t& byte : noise) byte = static_cast<uint8_t>(random());
    offer(noise.data(), trial % 2 ? size : random() % noise.size());
  }
  EXPECT_TRUE(scans.empty());  // nothing garbage-made was emitted
  // Then the real frame still decodes exactly.
  for (std::size_t i = 0; i < 64; ++i) offer(packets_[i].data(), size);
  batcher.flush();
  const BatcherStatistics& statistics = batcher.statistics();
  EXPECT_EQ(statistics.packets, offered);
  EXPECT_EQ(statistics.wrong_size + statistics.malformed + statistics.stale + 64, offered);
  ASSERT_EQ(scans.size(), 1u);
  EXPECT_EQ(md5Hex(scans[0].range), "17b04f169a54850cff3c97fce782d360");
}

TEST_F(LowBandwidthPackets, OtherProfilesAreRejected) {
  // The same bytes decoded as another profile do not fit its packet size.
  for (const UdpProfile profile : {UdpProfile::kLegacy, UdpProfile::kRng19Rfl8Sig16Nir16,
                                   UdpProfile::kRng19Rfl8Sig16Nir16Dual}) {
    OusterMetadata other = metadata_;
    other.profile = profile;
    ScanBatcher batcher(other, [](const LidarScan&) { ADD_FAILURE() << "emitted"; });
    for (const Packet& packet : packets_) batcher.addPacket(packet.data(), packet.size());
    batcher.flush();
    EXPECT_EQ(batcher.statistics().wrong_size, packets_.size()) << toString(profile);
  }
}

TEST_F(LowBandwidthPackets, FrameIdWrapsAround) {
  // Relabel the three frames 65535, 0, 1 and insert a late packet of 65535.
  auto relabel = [](Packet packet, uint16_t frame_id) {
    packet[2] = static_cast<uint8_t>(frame_id);
    packet[3] = static_cast<uint8_t>(frame_id >> 8);
    return packet;
  };
  std::vector<LidarScan> scans;
  ScanBatcher batcher(metadata_, [&](const LidarScan& scan) { scans.push_back(scan); });
  const uint16_t labels[] = {65535, 0, 1};
  for (std::size_t i = 0; i < packets_.size(); ++i) {
    if (i == 64 + 10) {
      const Packet late = relabel(packets_[7], 65535);
      batcher.addPacket(late.data(), late.size());
    }
    const Packet packet = relabel(packets_[i], labels[i / 64]);
    batcher.addPacket(packet.data(), packet.size());
  }
  batcher.flush();
  ASSERT_EQ(scans.size(), 3u);
  EXPECT_EQ(scans[0].frame_id, 65535u);
  EXPECT_EQ(scans[1].frame_id, 0u);
  EXPECT_EQ(scans[2].frame_id, 1u);
  EXPECT_EQ(batcher.statistics().incomplete_scans, 0u);
  EXPECT_EQ(batcher.statistics().stale, 1u);
  EXPECT_EQ(md5Hex(scans[1].range), "97af312c2c7f77cb219cbf399bde3455");
}

TEST_F(LowBandwidthPackets, SensorRestartStartsANewScan) {
  // Frame ids far behind the current one are a restart, not late packets.
  std::vector<LidarScan> scans;
  ScanBatcher batcher(metadata_, [&](const LidarScan& scan) { scans.push_back(scan); });
  for (std::size_t i = 0; i < 64; ++i) batcher.addPacket(packets_[i].data(), packets_[i].size());
  for (std::size_t i = 64; i < 128; ++i) {
    Packet packet = packets_[i];
    packet[2] = 7;  // frame id 7, far behind 1795
    packet[3] = 0;
    batcher.addPacket(packet.data(), packet.size());
  }
  batcher.flush();
  ASSERT_EQ(scans.size(), 2u);
  EXPECT_EQ(scans[1].frame_id, 7u);
  EXPECT_EQ(scans[1].receivedColumns(), 1024u);
}

TEST_F(LowBandwidthPackets, ReusedRangeImageHoldsOnlyTheNewScan) {
  // The second frame misses packet 3 (columns 48..63): converted into the image
  // of the first frame, nothing of the first may remain.
  const std::vector<LidarScan> scans = batch([](std::size_t i) { return i != 64 + 3; });
  ASSERT_EQ(scans.size(), 3u);
  const auto model = std::make_shared<const LidarModel>(metadata_.intrinsics);
  RangeImage image;
  toRangeImage(scans[0], model, ReturnIndex::kFirst, image);
  const float* buffer = image.range.data();
  toRangeImage(scans[1], model, ReturnIndex::kFirst, image);
  EXPECT_EQ(image.range.data(), buffer);  // no new allocation
  const RangeImage fresh = toRangeImage(scans[1], model);
  ASSERT_EQ(image.range.size(), fresh.range.size());
  EXPECT_EQ(std::memcmp(image.range.data(), fresh.range.data(), fresh.range.size() * sizeof(float)), 0);
  EXPECT_EQ(image.intensity, fresh.intensity);
  EXPECT_EQ(image.column_timestamp_ns, fresh.column_timestamp_ns);
  EXPECT_EQ(image.stamp_ns, fresh.stamp_ns);
  EXPECT_EQ(image.frame_id, 1796u);
  for (int row = 0; row < 128; ++row)
    for (int column = 48; column < 64; ++column) ASSERT_FALSE(image.valid(row, column));
  EXPECT_EQ(image.column_timestamp_ns[50], 0u);
}

// A reused scan, reset, holds only what the new packets brought: decoding into
// it after another frame gives what decoding into a fresh scan gives.
TEST_F(LowBandwidthPackets, ResetScanDecodesLikeAFreshOne) {
  const PacketFormat format(metadata_);
  // Frame 0 without packet 3 (columns 48..63), which frame 1 into the reused scan did fill.
  const auto decodeFrame0 = [&](LidarScan& scan) {
    for (std::size_t i = 0; i < 64; ++i)
      if (i != 3) format.decode(packets_[i].data(), packets_[i].size(), scan);
  };
  LidarScan fresh(128, 1024, metadata_.profile);
  decodeFrame0(fresh);

  LidarScan reused(128, 1024, metadata_.profile);
  for (std::size_t i = 64; i < 128; ++i) format.decode(packets_[i].data(), packets_[i].size(), reused);
  ASSERT_EQ(reused.receivedColumns(), 1024u);
  const uint32_t* buffer = reused.range.data();
  reused.reset();
  EXPECT_EQ(reused.receivedColumns(), 0u);
  decodeFrame0(reused);
  EXPECT_EQ(reused.range.data(), buffer);  // reset keeps the allocation

  EXPECT_EQ(reused.receivedColumns(), 1024u - 16u);
  EXPECT_EQ(reused.frame_id, fresh.frame_id);
  EXPECT_EQ(reused.range, fresh.range);
  EXPECT_EQ(reused.reflectivity, fresh.reflectivity);
  EXPECT_EQ(reused.signal, fresh.signal);
  EXPECT_EQ(reused.near_ir, fresh.near_ir);
  EXPECT_EQ(reused.timestamp_ns, fresh.timestamp_ns);
  EXPECT_EQ(reused.measurement_id, fresh.measurement_id);
  EXPECT_EQ(reused.status, fresh.status);
  for (int column = 48; column < 64; ++column) {
    EXPECT_EQ(reused.status[column], 0u);
    EXPECT_EQ(reused.timestamp_ns[column], 0u);
    for (int row = 0; row < 128; ++row) ASSERT_EQ(reused.range[std::size_t(row) * 1024 + column], 0u);
  }
}

// ------------------------------------------------------------ range images

TEST(OusterPacket, ToRangeImageKeepsMillimetresAndTimestamps) {
  RIM_REQUIRE_DATA(pcap_path, "ouster-pcaps/OS-0-32-U1_v2.2.0_1024x10.pcap");
  RIM_REQUIRE_DATA(metadata_path, "ouster-pcaps/OS-0-32-U1_v2.2.0_1024x10.json");
  const OusterMetadata metadata = loadOusterMetadata(metadata_path);
  const auto model = std::make_shared<const LidarModel>(metadata.intrinsics);
  const std::vector<Packet> packets = lidarPackets(pcap_path, metadata);
  std::vector<LidarScan> scans;
  ScanBatcher batcher(metadata, [&](const LidarScan& scan) { scans.push_back(scan); });
  // Without packet 0 (columns 0..15) the scan starts at column 16.
  for (std::size_t i = 1; i < packets.size(); ++i) batcher.addPacket(packets[i].data(), packets[i].size());
  batcher.flush();
  ASSERT_EQ(scans.size(), 1u);
  const LidarScan& scan = scans[0];

  for (const ReturnIndex which : {ReturnIndex::kFirst, ReturnIndex::kSecond}) {
    const bool first = which == ReturnIndex::kFirst;
    const RangeImage image = toRangeImage(scan, model, which);
    const std::vector<uint32_t>& millimetres = first ? scan.range : scan.range2;
    const std::vector<uint8_t>& reflectivity = first ? scan.reflectivity : scan.reflectivity2;
    ASSERT_EQ(image.rows(), 32);
    ASSERT_EQ(image.columns(), 1024);
    EXPECT_EQ(image.frame_id, scan.frame_id);
    EXPECT_EQ(image.column_order, ColumnOrder::kStaggered);
    EXPECT_EQ(image.intensity_field, "reflectivity");
    ASSERT_EQ(image.intensity.size(), millimetres.size());
    std::size_t valid = 0;
    for (std::size_t i = 0; i < millimetres.size(); ++i) {
      if (millimetres[i] == 0) {
        ASSERT_TRUE(std::isnan(image.range[i])) << i;
      } else {
        ASSERT_EQ(std::lround(image.range[i] * 1000.0), static_cast<long>(millimetres[i])) << i;
        ++valid;
      }
      ASSERT_EQ(image.intensity[i], reflectivity[i]);
    }
    EXPECT_EQ(image.validCount(), valid);
    for (int column = 0; column < 1024; ++column)
      EXPECT_EQ(image.column_timestamp_ns[column], column < 16 ? 0u : scan.timestamp_ns[column]);
    EXPECT_EQ(image.stamp_ns, scan.timestamp_ns[16]);
    EXPECT_GT(image.stamp_ns, 0u);
  }

  // A model of another size, or a second return that is not there, is refused.
  const auto other_model = std::make_shared<const LidarModel>(LidarIntrinsics::synthetic(32, 512, 0.3, -0.3));
  EXPECT_THROW(toRangeImage(scan, other_model), std::invalid_argument);
  LidarScan single = scan;
  single.range2.clear();
  EXPECT_THROW(toRangeImage(single, model, ReturnIndex::kSecond), std::invalid_argument);
  EXPECT_THROW(toRangeImage(scan, nullptr), std::invalid_argument);
}

TEST(OusterPacket, ToRangeImageStampFollowsAWrappingWindow) {
  RIM_REQUIRE_DATA(pcap_path, "ouster-pcaps/windowed_frame2.pcap");
  RIM_REQUIRE_DATA(metadata_path, "ouster-pcaps/windowed_frame2_0.json");
  const OusterMetadata metadata = loadOusterMetadata(metadata_path);
  const std::vector<LidarScan> scans = decodeCapture(pcap_path, metadata);
  ASSERT_EQ(scans.size(), 1u);
  const RangeImage image = toRangeImage(scans[0], std::make_shared<const LidarModel>(metadata.intrinsics));
  // The window [370, 85] wraps, but the frame starts at measurement id 0: columns
  // 0..85 come first, 370..511 after them.
  EXPECT_EQ(image.stamp_ns, scans[0].timestamp_ns[0]);
  uint64_t earliest = UINT64_MAX;
  for (int column = 0; column < 512; ++column)
    if (scans[0].status[column] != 0) earliest = std::min(earliest, scans[0].timestamp_ns[column]);
  EXPECT_EQ(image.stamp_ns, earliest);
  EXPECT_LT(scans[0].timestamp_ns[85], scans[0].timestamp_ns[370]);
  EXPECT_EQ(image.column_timestamp_ns[200], 0u);
  EXPECT_TRUE(std::isnan(image.range[200]));
}

}  // namespace
}  // namespace range_image_mapping
